// Ambient occlusion (`ao`).
//
// Estimator: at the first surface a camera ray hits, AO(x) = (1/pi) * integral over the
// hemisphere about the shading normal (turned towards the camera) of V(x, w) cos(theta) dw, where
// V = 1 unless the ray x + t w hits something with t < max_distance. With cosine-weighted sampling
// each occlusion ray contributes exactly V (variance V(1-V)); with uniform hemisphere sampling it
// contributes 2 V cos(theta), unbiased but noisier. The pixel value is AO in all three channels.
// Parameters: max_distance (infinity by default), sampling ("cosine" or "uniform"), samples (rays
// per camera sample).
// Strengths: cheap, noise-friendly shape cue, needs no lights or materials.
// Cannot do: it is not light transport: no lights, no materials, no interreflection; a closed
// room is black without a max distance. A camera ray that misses everything gives 0.
#pragma once

#include <string>

#include "engine/math.h"
#include "engine/integrators/module.h"

namespace rf {

struct AoIntegrator : IntegratorDefaults {
  static constexpr const char* kName = "ao";
  static constexpr bool kSplats = false;
  static constexpr const char* kKeys[] = {"type", "max_distance", "sampling", "samples"};
  static constexpr bool kNeedsLights = false;
  static constexpr const char* kPbrtTypes = "ambientocclusion";

  float max_distance = kInf;  // occluders farther than this do not count
  bool cosine = true;         // cosine-weighted (true) or uniform hemisphere sampling
  int samples = 1;            // occlusion rays per camera sample

  void parse(const JsonReader& r, const Json& j, const std::string& path);
  std::string settings_text() const;
  void from_pbrt(const ForeignParams& p);  // cossample, maxdistance

  SampleBuffer render(const RenderContext& ctx, const TaskKey& task, bool parallel) const;
  // The estimator: the occlusion seen along one camera ray (for tests at a chosen point).
  RGB radiance(const RenderContext& ctx, Ray ray, Sampler& sampler, TraceCounters& counters) const;
  bool operator==(const AoIntegrator&) const = default;
};

}  // namespace rf
