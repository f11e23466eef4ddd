// dielectric: a smooth interface between the outside (IOR 1) and a dielectric (IOR eta), glass.
//
// Model: specular reflection with the exact dielectric Fresnel reflectance R = F(cos_o, eta)
// and specular refraction (Snell's law) with T = 1 - R. A sample picks reflection with
// probability R, refraction with probability T, so f cos / pdf = tint for reflection, and for
// refraction tint in importance mode and tint / eta_rel^2 in radiance mode (eta_rel =
// eta_t / eta_i): radiance is compressed entering a denser medium, importance is not.
// Beyond the critical angle (from inside) R = 1: total internal reflection.
// Parameters: eta (interior IOR over exterior IOR, > 1 for glass), tint (RGB multiplier of both
// lobes; 1 for physically clear glass).
// Orientation: oriented. Local +z is the outside; wo may arrive from either side.
// References: pbrt-v4 section 9.5 (DielectricBxDF, specular case); Veach 1997 section 5.2.
// Limits: delta lobes only; no absorption inside (no Beer-Lambert medium); no dispersion.
#pragma once

#include "engine/bsdfs/common.h"
#include "engine/fresnel.h"

namespace rf {

struct DielectricBxdf {
  static constexpr bool kTwoSided = false;
  static constexpr bool kDelta = true;
  // Which of sample()'s random numbers it reads (the sampler skips the others' work).
  static constexpr bool kUsesChoice = true;      // uc
  static constexpr bool kUsesDirection = false;  // u

  float eta = 1.5f;
  RGB tint{1.0f};

  RGB eval(Vec3, Vec3, TransportMode) const { return RGB(0.0f); }
  float pdf(Vec3, Vec3, TransportMode) const { return 0.0f; }
  bool sample(Vec3 wo, float uc, Vec2 /*u*/, TransportMode mode, BsdfSample& s) const {
    if (wo.z == 0) return false;
    float r = fresnel_dielectric(wo.z, eta), t = 1 - r;
    s.is_delta = true;
    if (uc < r) {
      s.wi = Vec3(-wo.x, -wo.y, wo.z);
      s.f = tint * (r / abs_cos_theta(s.wi));
      s.pdf_solid_angle = r;
      s.is_transmission = false;
      s.eta = 1;
      return true;
    }
    float etap;
    if (!refract(wo, Vec3(0, 0, 1), eta, &etap, &s.wi) || s.wi.z == 0) return false;
    float ft = t / abs_cos_theta(s.wi);
    if (mode == TransportMode::Radiance) ft /= etap * etap;
    s.f = tint * ft;
    s.pdf_solid_angle = t;
    s.is_transmission = true;
    s.eta = etap;
    return true;
  }
};

}  // namespace rf
