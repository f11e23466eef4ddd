// rough_conductor: a rough metal, the GGX microfacet BRDF.
//
// Model: Cook-Torrance / Walter et al. 2007 reflection
//   f(wo, wi) = D(wm) F(wo.wm) G2(wo, wi) / (4 cos_o cos_i),  wm = normalize(wo + wi),
// with the GGX (Trowbridge-Reitz) distribution and height-correlated Smith masking-shadowing
// from engine/microfacet.h, and the conductor Fresnel term of engine/bsdfs/conductor.h (complex
// IOR per RGB channel, or Schlick with F0 = tint). Sampled by visible normals (Heitz 2018):
//   pdf(wi) = D_wo(wm) / (4 wo.wm).
// Parameters: alpha (GGX roughness, alpha = r^2 in Disney's "perceptual roughness" r),
// eta, k or tint (see conductor.h). Alpha below kSmoothAlpha is the smooth conductor instead
// (engine/bsdf.h decides).
// References: Walter et al. 2007; Heitz 2014 and 2018; pbrt-v4 section 9.6 (ConductorBxDF).
// Limits: two-sided, reflection only. Single scattering: energy reflected by more than one
// microfacet is lost, so even a white conductor (F = 1) reflects less than 1. Measured loss
// (tests/bsdf_test.cpp, RoughConductor.EnergyLoss), cosine-weighted average over incidence:
// 2.8% at alpha 0.1, 15% at 0.3, 37% at 0.6, 59% at 1.0 (at normal incidence: 1.2%, 12%, 41%,
// 69%). No multiple-scattering compensation (Kulla & Conty 2017 would add it).
#pragma once

#include "engine/bsdfs/common.h"
#include "engine/bsdfs/conductor.h"
#include "engine/fresnel.h"
#include "engine/microfacet.h"

namespace rf {

struct RoughConductorBxdf {
  static constexpr bool kTwoSided = true;
  static constexpr bool kDelta = false;
  // Which of sample()'s random numbers it reads (the sampler skips the others' work).
  static constexpr bool kUsesChoice = false;    // uc
  static constexpr bool kUsesDirection = true;  // u

  TrowbridgeReitz distrib;
  ConductorFresnel fresnel;

  // Selects rather than early returns (the path tracer's lanes vectorise them): 0 where wo or wi
  // is not above the surface or wm is undefined.
  RGB eval(Vec3 wo, Vec3 wi, TransportMode) const {
    Vec3 wm = wo + wi;
    const bool ok = !(wo.z <= 0) & !(wi.z <= 0) & !(length_sq(wm) == 0);
    wm = normalize(wm);
    float d = distrib.D(wm) * distrib.G2(wo, wi) / (4 * wo.z * wi.z);
    return vselect(ok, fresnel(dot(wo, wm)) * d, RGB(0.0f));
  }
  float pdf(Vec3 wo, Vec3 wi, TransportMode) const {
    Vec3 wm = wo + wi;
    const bool ok = !(wo.z <= 0) & !(wi.z <= 0) & !(length_sq(wm) == 0);
    wm = normalize(wm);
    float c = dot(wo, wm);
    return ok & !(c <= 0) ? distrib.D_visible(wo, wm) / (4 * c) : 0.0f;
  }
  bool sample(Vec3 wo, float /*uc*/, Vec2 u, TransportMode mode, BsdfSample& s) const {
    float cos_phi, sin_phi;
    TrowbridgeReitz::visible_normal_phi(u, cos_phi, sin_phi);
    return sample_from_phi(wo, u.x, cos_phi, sin_phi, mode, s) && s.pdf_solid_angle > 0;
  }
  // sample() given u.x and the cosine and sine of phi (TrowbridgeReitz::visible_normal_phi), with
  // selects (the path tracer's lanes run it in a loop): whether wo and the sampled wi are above the
  // surface. sample() also requires pdf > 0; the lanes test that after their loop (GCC 12 does
  // not vectorise the select of flags it becomes here).
  bool sample_from_phi(Vec3 wo, float ux, float cos_phi, float sin_phi, TransportMode mode,
                       BsdfSample& s) const {
    Vec3 wm = distrib.sample_visible_normal(wo, ux, cos_phi, sin_phi);
    s.wi = reflect(wo, wm);
    // f and pdf from the returned direction, so they agree with eval() and pdf() exactly.
    s.f = eval(wo, s.wi, mode);
    s.pdf_solid_angle = pdf(wo, s.wi, mode);
    s.is_delta = false;
    s.is_transmission = false;
    s.eta = 1;
    return !(wo.z <= 0) & !(s.wi.z <= 0);
  }
};

}  // namespace rf
