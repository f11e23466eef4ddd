// thin_dielectric: an infinitely thin slab of dielectric, a window pane.
//
// Model: pbrt-v4's ThinDielectricBxDF. Light bounces inside the slab between its two parallel
// smooth faces; summing the geometric series of internal reflections gives the total
// reflectance R' = R + T^2 R / (1 - R^2) and transmittance T' = 1 - R', with R = F(cos_o, eta) and
// T = 1 - R the single-interface Fresnel terms. Transmission leaves straight through (wi = -wo:
// the two refractions cancel and the slab has no thickness). A sample picks reflection with
// probability R', transmission with T', so f cos / pdf = tint for both.
// Parameters: eta (slab IOR over the surrounding IOR), tint (RGB multiplier of both lobes).
// Orientation: two-sided (the slab is symmetric); eta_rel of a transmission is 1, so radiance
// and importance modes agree.
// References: pbrt-v4 section 9.5.3 (ThinDielectricBxDF).
// Limits: delta lobes only; no absorption in the slab; no lateral offset of the ray.
#pragma once

#include "engine/bsdfs/common.h"
#include "engine/fresnel.h"

namespace rf {

struct ThinDielectricBxdf {
  static constexpr bool kTwoSided = true;
  static constexpr bool kDelta = true;
  // Which of sample()'s random numbers it reads (the sampler skips the others' work).
  static constexpr bool kUsesChoice = true;      // uc
  static constexpr bool kUsesDirection = false;  // u

  float eta = 1.5f;
  RGB tint{1.0f};

  // Total reflectance of the slab at incidence cos_theta (>= 0).
  float reflectance(float cos_theta) const {
    float r = fresnel_dielectric(cos_theta, eta), t = 1 - r;
    if (r < 1) r += t * t * r / (1 - r * r);
    return r;
  }
  RGB eval(Vec3, Vec3, TransportMode) const { return RGB(0.0f); }
  float pdf(Vec3, Vec3, TransportMode) const { return 0.0f; }
  bool sample(Vec3 wo, float uc, Vec2 /*u*/, TransportMode, BsdfSample& s) const {
    if (wo.z <= 0) return false;
    float r = reflectance(wo.z), t = 1 - r;
    s.is_delta = true;
    s.eta = 1;
    if (uc < r) {
      s.wi = Vec3(-wo.x, -wo.y, wo.z);
      s.f = tint * (r / wo.z);
      s.pdf_solid_angle = r;
      s.is_transmission = false;
    } else {
      s.wi = -wo;
      s.f = tint * (t / wo.z);
      s.pdf_solid_angle = t;
      s.is_transmission = true;
    }
    return true;
  }
};

}  // namespace rf
