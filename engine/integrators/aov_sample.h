// The AOVs of one camera ray (engine/aov.h, docs/outputs.md), traced for them by the render
// drivers (drivers.h) when a render asks for AOVs; a render without AOVs never calls it.
//
// The ray is followed through smooth (delta) surfaces along one deterministic direction each, so
// an AOV sample draws no random numbers and the main image's samples are untouched: a mirror
// reflects, a thin dielectric passes straight through, a dielectric refracts (reflects under total
// internal reflection), each multiplying the albedo by its tint (a conductor by its normal-
// incidence Fresnel reflectance), for at most kMaxSpecularBounces surfaces (then the sample is
// black with a zero normal). At the first non-delta surface:
//   albedo  diffuse and plastic: the diffuse reflectance; rough conductor: its normal-incidence
//           Fresnel reflectance (F0, or the tint in tint mode); rough dielectric: its tint;
//   normal  the shading normal turned to face the ray.
// Depth is the distance to the first surface along the camera ray, whatever it is.
#pragma once

#include "engine/aov.h"
#include "engine/integrators/common.h"

namespace rf {

inline constexpr int kMaxSpecularBounces = 8;

AovSample aov_sample(const RenderContext& ctx, const Ray& camera_ray, TraceCounters& counters);

// The albedo the AOV reports for a (non-delta) material's parameters.
RGB aov_albedo(const BsdfParams& p);

}  // namespace rf
