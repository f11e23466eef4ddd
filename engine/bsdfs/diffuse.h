// diffuse: the Lambertian BRDF.
//
// Model: f = R / pi on the hemisphere of wo, 0 below. Sampled cosine-weighted (Malley), so
// f cos / pdf = R exactly.
// Parameters: reflectance R (RGB albedo in [0, 1]).
// References: Lambert 1760; pbrt-v4 section 9.2 (DiffuseBxDF).
// Limits: two-sided, reflection only; no retro-reflection or roughness (no Oren-Nayar).
#pragma once

#include "engine/bsdfs/common.h"
#include "engine/sampling.h"

namespace rf {

struct DiffuseBxdf {
  static constexpr bool kTwoSided = true;
  static constexpr bool kDelta = false;
  // Which of sample()'s random numbers it reads (the sampler skips the others' work).
  static constexpr bool kUsesChoice = false;    // uc
  static constexpr bool kUsesDirection = true;  // u

  RGB reflectance;

  RGB eval(Vec3 wo, Vec3 wi, TransportMode) const {
    if (wo.z <= 0 || wi.z <= 0) return RGB(0.0f);
    return reflectance * kInvPi;
  }
  float pdf(Vec3 wo, Vec3 wi, TransportMode) const {
    if (wo.z <= 0 || wi.z <= 0) return 0.0f;
    return cosine_hemisphere_pdf(wi.z);
  }
  bool sample(Vec3 wo, float /*uc*/, Vec2 u, TransportMode, BsdfSample& s) const {
    if (wo.z <= 0) return false;
    return sample_from_disk(sample_concentric_disk(u), s);
  }
  // sample()'s direction from its point d on the concentric disk (the path tracer's lanes compute
  // d in one loop and the direction in another), for wo above the surface.
  bool sample_from_disk(Vec2 d, BsdfSample& s) const {
    s.wi = cosine_hemisphere_from_disk(d);
    s.pdf_solid_angle = cosine_hemisphere_pdf(s.wi.z);
    if (!(s.pdf_solid_angle > 0)) return false;
    s.f = reflectance * kInvPi;
    s.is_delta = false;
    s.is_transmission = false;
    s.eta = 1;
    return true;
  }
};

}  // namespace rf
