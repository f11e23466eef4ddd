// Progressive photon mapping, probabilistic form (`ppm`; Knaus & Zwicker 2011).
//
// Estimator. Pass i (i = pass + 1) is an independent photon-mapping image with its own photons
// and its own radius r_i, which depends only on i:
//   r_i^2 = r_1^2 prod_{k=1}^{i-1} (k + alpha) / (k + 1)     (KZ 2011, eq. 15; ~ i^(alpha - 1)),
// so the image, the average of passes, is consistent: the kernel's bias falls with r_i^2 and the
// variance of pass i grows only as 1 / r_i^2 ~ i^(1 - alpha), so the average's error -> 0.
// Per pass, M photon paths leave the lights (light by power, importance-mode BSDFs, shading
// normals corrected as in light.cpp, Russian roulette) and store a photon (position, incoming
// direction, throughput / M, depth k = scattering events including its own vertex) at every
// non-delta surface hit except the first (k >= 2): direct light is not taken from photons.
// The camera path follows delta BSDFs to the first non-delta vertex x (d scattering events before
// it) and there estimates
//   L(x) = Le(x) + direct(x) [next-event estimation, MIS with the BSDF sample, as path/path.cpp]
//        + sum over photons within r_i with k + d <= max_depth of
//          f_x(wo, wi_j) Phi_j |wi_j.ns| / |wi_j.ng| / (pi r_i^2)      (constant kernel).
// A photon of depth k stands for a path of k + d scattering events (the photon's vertex is x), so
// the max-depth rule is path's. The BSDF sample of x is traced only to find emission for MIS, and,
// when x's BSDF sampled a delta lobe (a plastic's smooth coat), to continue the camera path,
// which then gathers again at its next non-delta vertex.
// Bias (consistent, not unbiased): the density estimate blurs indirect light over r_i (corners
// and contact shadows are filled in, edges of indirect light softened, light on a thin wall's one
// side can reach the other side's points within r_i where the BSDF allows). The bias of pass i is
// O(r_i^2); it vanishes as passes grow, but any finite number of passes keeps some.
// Parameters: max_depth, rr_min_depth, photons (M per pass; default 100000), radius (r_1; 0 picks
// 0.02 x the scene's bounding radius, LightSet::scene_radius()), alpha (default 2/3, in (0, 1)).
// Per-pass state: the photons of pass p in a hash grid of cell 2 r_p (photon_grid.h), a pure
// function of (scene, settings, p): photon path i is keyed by (seed, frame, p, i) and paths are
// traced in fixed chunks concatenated in order. Shared read-only by the pass's tiles.
// Strengths: caustics (light -> specular -> diffuse -> camera) and caustics seen through
// specular surfaces (specular -> diffuse -> specular), which neither path nor light tracing
// nor BDPT samples well.
// Environment and directional lights emit photons from a disk outside the scene facing the light
// (LightSet::sample_emission); a camera path that leaves the scene takes the environment's
// radiance (MIS-weighted after a non-delta scattering, as the path tracer: camera_path.h).
// Limits: biased for any finite pass count; memory per pass grows with M; glossy receivers blur.
#pragma once

#include <string>

#include "engine/integrators/module.h"

namespace rf {

struct PpmIntegrator : IntegratorDefaults {
  static constexpr const char* kName = "ppm";
  static constexpr bool kMovingGeometry = false;  // see IntegratorDefaults
  static constexpr bool kSplats = false;
  static constexpr const char* kKeys[] = {"type",    "max_depth", "rr_min_depth",
                                          "photons", "radius",    "alpha"};
  static constexpr const char* kPbrtTypes = "sppm";

  int photons = 100000;       // photon paths traced per pass
  float radius = 0;           // r_1, the first pass's radius; 0: 0.02 x scene_radius()
  float alpha = 2.0f / 3.0f;  // Knaus-Zwicker alpha in (0, 1)

  void parse(const JsonReader& r, const Json& j, const std::string& path);
  std::string settings_text() const;
  void from_pbrt(const ForeignParams& p);  // photonsperiteration, radius

  SampleBuffer render(const RenderContext& ctx, const TaskKey& task, bool parallel) const;
  bool operator==(const PpmIntegrator&) const = default;
};

}  // namespace rf
