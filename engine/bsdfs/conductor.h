// conductor: a smooth metal (perfect mirror).
//
// Model: specular reflection f = F(cos_o) delta(wi - mirror(wo)) / |cos_i|, so a sample's
// f cos / pdf = F. The Fresnel term is either the exact conductor reflectance of the complex IOR
// eta + i k, per RGB channel (light arriving from a medium of IOR 1), or, in tint mode, Schlick's
// approximation with F0 = tint (an artist's colour at normal incidence).
// Parameters: eta, k (RGB; measured spectral data averaged per band, e.g. the presets in
// engine/scene_json.cpp), or tint (RGB F0 in [0, 1]) when use_tint is set.
// References: pbrt-v4 sections 9.3-9.5 (ConductorBxDF, FrComplex); Schlick 1994.
// Limits: two-sided, reflection only, delta lobe only (eval and pdf are 0).
#pragma once

#include "engine/bsdfs/common.h"
#include "engine/fresnel.h"

namespace rf {

// The Fresnel term of a conductor, shared with the rough conductor.
struct ConductorFresnel {
  RGB eta{1.0f}, k{0.0f};
  RGB tint{1.0f};
  bool use_tint = false;

  RGB operator()(float cos_theta_i) const {
    return vselect(use_tint, fresnel_schlick(tint, cos_theta_i),
                   fresnel_complex(cos_theta_i, eta, k));
  }
};

struct ConductorBxdf {
  static constexpr bool kTwoSided = true;
  static constexpr bool kDelta = true;
  // Which of sample()'s random numbers it reads (the sampler skips the others' work).
  static constexpr bool kUsesChoice = false;     // uc
  static constexpr bool kUsesDirection = false;  // u

  ConductorFresnel fresnel;

  RGB eval(Vec3, Vec3, TransportMode) const { return RGB(0.0f); }
  float pdf(Vec3, Vec3, TransportMode) const { return 0.0f; }
  bool sample(Vec3 wo, float /*uc*/, Vec2 /*u*/, TransportMode, BsdfSample& s) const {
    if (wo.z <= 0) return false;
    s.wi = Vec3(-wo.x, -wo.y, wo.z);
    s.f = fresnel(wo.z) / wo.z;
    s.pdf_solid_angle = 1;
    s.is_delta = true;
    s.is_transmission = false;
    s.eta = 1;
    return true;
  }
};

}  // namespace rf
