// Light tracing, or particle tracing (`light`).
//
// Estimator: paths start on the lights (a light chosen by power, a point on it, a direction by
// its emission distribution) and scatter through the scene with importance-mode BSDFs; every
// vertex, the one on the light included, connects to the camera through the camera's importance
// W_e and splats its contribution beta * f * |cos| * W_e / pdf_lens at the raster point it reaches,
// weighted by the pixel filter (DESIGN.md "Pixels, filters and splats"). With W_e normalised over
// the whole film, a pixel's importance is W_e times the pixel count, so every splat carries that
// factor; the image is the splat plane divided by the number of light paths. A light path's
// random numbers are keyed by (seed, frame, pass, light-path index): any pass range renders
// anywhere. Non-symmetric shading normals are corrected (Veach 1997, 5.3).
// Parameters: max_depth (a vertex after k scatterings connects through one more: paths with up
// to max_depth scattering events), rr_min_depth (roulette on throughput relative to its start).
// Strengths: caustics seen on diffuse surfaces (light -> specular -> diffuse -> camera), which the
// path tracer finds only by chance.
// Environment and directional lights start their paths on a disk outside the scene, facing the
// light (LightSet::sample_emission, as pbrt-v4). The environment seen directly cannot be reached
// by a light path (it never hits the lens): each pixel gets spp-per-pass camera samples for it
// (the environment's radiance where the camera ray leaves the scene, drivers.h).
// Cannot do: anything seen through a specular surface (a connection through a delta BSDF is
// impossible; the environment seen in a mirror included), and it is noisy wherever the camera
// sees little of what lights reach.
#pragma once

#include <string>

#include "engine/integrators/module.h"

namespace rf {

struct LightIntegrator : IntegratorDefaults {
  static constexpr const char* kName = "light";
  static constexpr bool kSplats = true;
  static constexpr const char* kKeys[] = {"type", "max_depth", "rr_min_depth"};
  static constexpr const char* kPbrtTypes = "lightpath";
  static constexpr const char* kMitsubaTypes = "ptracer";

  SampleBuffer render(const RenderContext& ctx, const TaskKey& task, bool parallel) const;
  bool operator==(const LightIntegrator&) const = default;
};

}  // namespace rf
