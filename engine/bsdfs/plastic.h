// plastic: a coated diffuse surface, a Lambertian base under a smooth or rough dielectric coat.
//
// Model: Mitsuba's "plastic" / "roughplastic" with nonlinear internal scattering, after
// Weidlich & Wilkie 2007 ("Arbitrarily Layered Micro-Facet Surfaces"). Two lobes:
//   specular: the coat's reflection, tint * F(cos_o) for a smooth coat (a delta lobe), or for
//             alpha >= kSmoothAlpha the GGX microfacet BRDF of rough_conductor.h with the
//             dielectric Fresnel term min(F(wo.wm), F(cos_o), F(cos_i)) (see Energy);
//   diffuse:  f_d = R / (1 - R F_dr,int) * (1 - F(cos_o)) (1 - F(cos_i)) / (pi eta^2).
// Light refracts into the coat (1 - F(cos_i)), reaches the base, and bounces between the base
// and the coat's underside; the geometric series of those bounces (internal diffuse reflectance
// F_dr,int of the coat, total internal reflection included) gives R / (1 - R F_dr,int), and
// 1 / eta^2 is the radiance compression of leaving the coat. The smooth-interface Fresnel F is
// used for the diffuse weights also under a rough coat (Mitsuba's roughplastic uses precomputed
// rough-transmittance tables there instead).
// Energy: the diffuse albedo is (1 - F(cos_o)) R (1 - F_dr,int) / (1 - R F_dr,int), because
// T_int = T_ext / eta^2 (engine/fresnel.h); it is at most 1 - F(cos_o), and equal for R = 1.
// So the total is at most 1 if the specular albedo is at most F(cos_o). It is exactly that for
// a smooth coat, hence albedo 1 for a white base. For a rough coat, F(wo.wm) averaged over the
// microfacets exceeds F(cos_o) slightly because F is convex (Jensen): measured up to +0.08% of
// gain at alpha ~0.1, eta 1.2 without a cap. Capping the microfacet Fresnel at min(F(cos_o),
// F(cos_i)) (symmetric, so reciprocity holds) bounds the specular albedo by F(cos_o) times the
// GGX single-scattering albedo <= 1, so the rough coat cannot gain energy; it loses GGX's
// single-scattering share of the specular energy (tests/bsdf_test.cpp, BsdfEnergy). Measured
// albedo of a white base under an eta 1.5 coat, at cos_o = 1 / 0.7 / 0.3 / 0.05: smooth
// 1 / 1 / 1 / 1; alpha 0.05: 1.000 / 0.998 / 0.963 / 0.643; alpha 0.3: 0.995 / 0.988 / 0.866 /
// 0.354; alpha 1: 0.972 / 0.966 / 0.824 / 0.305.
// The model is symmetric in (wo, wi), so radiance and importance modes agree.
// Sampling: the specular lobe with probability p = F(cos_o) s / (F(cos_o) s + (1 - F(cos_o)) d),
// s = luminance(tint), d = luminance(R (1 - F_dr,int) / (1 - R F_dr,int)): each lobe's estimated
// albedo; the returned pdf is the mixture's (rough coat) or (1 - p) times the cosine pdf for a
// diffuse sample under a smooth coat, where the delta lobe is returned with probability p.
// Parameters: reflectance R (base albedo, RGB in [0, 1]), eta (coat IOR, > 1), alpha (coat GGX
// roughness), tint (RGB multiplier of the coat's reflection; 1 for clear varnish).
// References: Weidlich & Wilkie 2007; Mitsuba 0.6 plugins plastic and roughplastic (Jakob).
// Limits: two-sided, reflection only; no absorption in the coat; the coat is infinitely thin.
// Cost: make() integrates F_dr by 16-point Gauss-Legendre (16 Fresnel evaluations).
#pragma once

#include "engine/bsdfs/common.h"
#include "engine/fresnel.h"
#include "engine/microfacet.h"
#include "engine/sampling.h"

namespace rf {

struct PlasticBxdf {
  static constexpr bool kTwoSided = true;
  static constexpr bool kDelta = false;
  // Which of sample()'s random numbers it reads (the sampler skips the others' work).
  static constexpr bool kUsesChoice = true;     // uc
  static constexpr bool kUsesDirection = true;  // u

  RGB reflectance{0.5f};
  RGB tint{1.0f};
  float eta = 1.5f;
  bool smooth = true;
  TrowbridgeReitz distrib;
  float fdr_int = 0;     // internal diffuse reflectance of the coat, F_dr,int(eta)
  RGB diffuse_scale{0};  // R / (1 - R F_dr,int) / (pi eta^2)

  static PlasticBxdf make(RGB reflectance, RGB tint, float eta, float alpha) {
    PlasticBxdf p;
    p.reflectance = reflectance;
    p.tint = tint;
    p.eta = eta;
    p.smooth = TrowbridgeReitz::effectively_smooth(alpha);
    p.distrib = {alpha, alpha};
    p.fdr_int = fresnel_diffuse_reflectance_interior(eta);
    p.diffuse_scale = reflectance / (RGB(1.0f) - reflectance * p.fdr_int) * (kInvPi / (eta * eta));
    return p;
  }

  float specular_probability(float cos_o) const {
    float f = fresnel_dielectric(cos_o, eta);
    float s = f * luminance(tint);
    float d = (1 - f) * luminance(diffuse_scale * (kPi * eta * eta) * (1 - fdr_int));
    return s + d > 0 ? s / (s + d) : 0.5f;
  }
  // The base's light, given the coat's smooth Fresnel reflectances fo = F(cos_o), fi = F(cos_i).
  RGB diffuse(float fo, float fi) const { return diffuse_scale * ((1 - fo) * (1 - fi)); }
  // The rough coat's reflection (0 for a smooth coat, whose lobe is a delta), with its
  // microfacet Fresnel capped at min(fo, fi).
  RGB glossy(Vec3 wo, Vec3 wi, float fo, float fi) const {
    if (smooth) return RGB(0.0f);
    Vec3 wm = normalize(wo + wi);
    float f = std::min(fresnel_dielectric(dot(wo, wm), eta), std::min(fo, fi));
    return tint * (distrib.D(wm) * distrib.G2(wo, wi) * f / (4 * wo.z * wi.z));
  }
  float glossy_pdf(Vec3 wo, Vec3 wi) const {
    if (smooth) return 0.0f;
    Vec3 wm = normalize(wo + wi);
    float c = dot(wo, wm);
    return c > 0 ? distrib.D_visible(wo, wm) / (4 * c) : 0.0f;
  }

  RGB eval(Vec3 wo, Vec3 wi, TransportMode) const {
    if (wo.z <= 0 || wi.z <= 0) return RGB(0.0f);
    float fo = fresnel_dielectric(wo.z, eta), fi = fresnel_dielectric(wi.z, eta);
    return glossy(wo, wi, fo, fi) + diffuse(fo, fi);
  }
  float pdf(Vec3 wo, Vec3 wi, TransportMode) const {
    if (wo.z <= 0 || wi.z <= 0) return 0.0f;
    float p = specular_probability(wo.z);
    return p * glossy_pdf(wo, wi) + (1 - p) * cosine_hemisphere_pdf(wi.z);
  }
  bool sample(Vec3 wo, float uc, Vec2 u, TransportMode mode, BsdfSample& s) const {
    if (wo.z <= 0) return false;
    float p = specular_probability(wo.z);
    s.is_transmission = false;
    s.eta = 1;
    if (uc < p && smooth) {
      s.wi = Vec3(-wo.x, -wo.y, wo.z);
      s.f = tint * (fresnel_dielectric(wo.z, eta) / wo.z);
      s.pdf_solid_angle = p;
      s.is_delta = true;
      return true;
    }
    s.wi = uc < p ? reflect(wo, distrib.sample_visible_normal(wo, u)) : sample_cosine_hemisphere(u);
    if (s.wi.z <= 0) return false;
    s.f = eval(wo, s.wi, mode);
    s.pdf_solid_angle = pdf(wo, s.wi, mode);
    s.is_delta = false;
    return s.pdf_solid_angle > 0;
  }
};

}  // namespace rf
