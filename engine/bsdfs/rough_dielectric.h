// rough_dielectric: rough glass, the GGX microfacet BSDF of Walter et al. 2007.
//
// Model (local frame, +z = outside, eta = IOR inside / IOR outside): with etap = eta_t / eta_i
// for the pair (etap = eta when wo is outside and wi inside, 1 / eta for the reverse, 1 for a
// reflection) the generalised half vector is wm = normalize(wo + etap wi), turned to +z;
//   reflection:   f = D(wm) F(wo.wm) G2 / |4 cos_o cos_i|
//   transmission: f = D(wm) (1 - F(wo.wm)) G2 |wi.wm| |wo.wm| / (|cos_o cos_i| (wi.wm +
//   wo.wm/etap)^2)
// and in radiance mode the transmission is further divided by etap^2 (importance mode is the
// adjoint and is not). Microfacets facing away from wo or wi contribute nothing.
// Reciprocity: f_radiance(wo, wi) / n(wo)^2 = f_radiance(wi, wo) / n(wi)^2, and
// f_importance(wo, wi) = f_radiance(wi, wo) (tests/bsdf_test.cpp checks both).
// Sampling: a visible normal from D_wo (Heitz 2018), then reflection with probability
// F(wo.wm), else refraction about wm (pbrt-v4): pdf = D_wo(wm) |dwm/dwi| times that probability,
// |dwm/dwi| = 1 / (4 |wo.wm|) for reflection and |wi.wm| / (wi.wm + wo.wm/etap)^2 for refraction.
// Samples that leave the wrong hemisphere (multiple scattering in reality) are discarded.
// Parameters: alpha (GGX roughness), eta (> 1), tint (RGB multiplier of both lobes, 1 for clear).
// Alpha below kSmoothAlpha is the smooth dielectric instead (engine/bsdf.h decides).
// Orientation: oriented; wo may be outside (z > 0) or inside (z < 0).
// References: Walter et al. 2007; Heitz 2018; pbrt-v4 section 9.7 (DielectricBxDF, rough case).
// Limits: single scattering (energy lost at high roughness); no absorption; no dispersion.
#pragma once

#include "engine/bsdfs/common.h"
#include "engine/fresnel.h"
#include "engine/microfacet.h"

namespace rf {

struct RoughDielectricBxdf {
  static constexpr bool kTwoSided = false;
  static constexpr bool kDelta = false;
  // Which of sample()'s random numbers it reads (the sampler skips the others' work).
  static constexpr bool kUsesChoice = true;     // uc
  static constexpr bool kUsesDirection = true;  // u

  TrowbridgeReitz distrib;
  float eta = 1.5f;
  RGB tint{1.0f};

  // The generalised half vector of (wo, wi) turned to +z, and etap; false when the pair cannot
  // scatter (grazing, degenerate, or through a back-facing microfacet).
  bool half_vector(Vec3 wo, Vec3 wi, Vec3& wm, float& etap) const {
    if (wo.z == 0 || wi.z == 0) return false;
    bool reflect = wo.z * wi.z > 0;
    etap = reflect ? 1.0f : (wo.z > 0 ? eta : 1 / eta);
    wm = wi * etap + wo;
    if (length_sq(wm) == 0) return false;
    wm = normalize(wm);
    if (wm.z < 0) wm = -wm;
    return dot(wm, wi) * wi.z > 0 && dot(wm, wo) * wo.z > 0;
  }

  // F(wo.wm) of a valid pair. For a refraction it is evaluated from the outside direction:
  // the same value mathematically, but from inside near the critical angle cos_t is
  // ill-conditioned (float error ~1e-3 relative in 1 - F), which would break reciprocity.
  float fresnel(Vec3 wo, Vec3 wi, Vec3 wm) const {
    Vec3 w = (wo.z * wi.z < 0 && wo.z < 0) ? wi : wo;
    return fresnel_dielectric(dot(w, wm), eta);
  }

  RGB eval(Vec3 wo, Vec3 wi, TransportMode mode) const {
    Vec3 wm;
    float etap;
    if (!half_vector(wo, wi, wm, etap)) return RGB(0.0f);
    float f = fresnel(wo, wi, wm);
    float dg = distrib.D(wm) * distrib.G2(wo, wi);
    if (wo.z * wi.z > 0) return tint * (dg * f / std::fabs(4 * wo.z * wi.z));
    float denom = sqr(dot(wi, wm) + dot(wo, wm) / etap) * wi.z * wo.z;
    float ft = dg * (1 - f) * std::fabs(dot(wi, wm) * dot(wo, wm) / denom);
    if (mode == TransportMode::Radiance) ft /= etap * etap;
    return tint * ft;
  }

  float pdf(Vec3 wo, Vec3 wi, TransportMode) const {
    Vec3 wm;
    float etap;
    if (!half_vector(wo, wi, wm, etap)) return 0.0f;
    float r = fresnel(wo, wi, wm);
    if (wo.z * wi.z > 0) return distrib.D_visible(wo, wm) / (4 * std::fabs(dot(wo, wm))) * r;
    float dwm_dwi = std::fabs(dot(wi, wm)) / sqr(dot(wi, wm) + dot(wo, wm) / etap);
    return distrib.D_visible(wo, wm) * dwm_dwi * (1 - r);
  }

  bool sample(Vec3 wo, float uc, Vec2 u, TransportMode mode, BsdfSample& s) const {
    if (wo.z == 0) return false;
    Vec3 wm = distrib.sample_visible_normal(wo, u);
    float r = fresnel_dielectric(dot(wo, wm), eta);
    if (uc < r) {
      s.wi = reflect(wo, wm);
      if (!same_hemisphere(wo, s.wi)) return false;
      s.is_transmission = false;
      s.eta = 1;
    } else {
      float etap;
      if (!refract(wo, wm, eta, &etap, &s.wi)) return false;
      if (same_hemisphere(wo, s.wi) || s.wi.z == 0) return false;
      s.is_transmission = true;
      s.eta = etap;
    }
    // f and pdf from the returned direction, so they agree with eval() and pdf() exactly.
    s.f = eval(wo, s.wi, mode);
    s.pdf_solid_angle = pdf(wo, s.wi, mode);
    s.is_delta = false;
    return s.pdf_solid_angle > 0;
  }
};

}  // namespace rf
