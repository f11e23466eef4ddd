// Path tracing with next-event estimation (`path`).
//
// Estimator: unidirectional paths from the camera. At every vertex with a non-delta BSDF, one
// light sample (light chosen by power) and one BSDF sample, combined by multiple importance
// sampling with the power heuristic (Veach 1997, ch. 9); emission found by the BSDF sample (area
// lights, the environment) is weighted against the light-sampling pdf of the same point. Delta
// lights (point, spot, directional) are reached by light sampling only, delta BSDFs (mirror,
// glass) by BSDF sampling only, each with weight 1.
// Parameters: max_depth D (scattering events, pbrt-v4's meaning: D = 0 sees emitters only, D = 1
// is direct lighting), rr_min_depth (Russian roulette after that many bounces, survival
// probability min(1, max component of throughput x eta scale), pbrt-v4's rule).
// Strengths: unbiased, simple, robust for diffuse and glossy scenes with visible light sources.
// Cannot do well: caustics from small lights seen through specular surfaces (found only by
// chance; from point lights never), light arriving through narrow openings; see bdpt and ppm.
//
// The module's files (engine/integrators/path/): this header (the parameters: the scene layer);
// path_tracer.h (the estimator: a pixel's samples traced alone or in packets, and the one-lane
// loop); packets.h (the packet orchestration, one function per phase of a depth); surface_lanes.h
// (the vectorised kernels that shade a packet's plain vertices); lane_lights.h (the light tables
// those kernels read, built from a LightSet). The sample-dimension layout is
// integrators/sample_layout.h.
#pragma once

#include "engine/integrators/module.h"

namespace rf {

struct PathIntegrator : IntegratorDefaults {
  static constexpr const char* kName = "path";
  static constexpr bool kSplats = false;
  static constexpr const char* kKeys[] = {"type", "max_depth", "rr_min_depth"};
  static constexpr const char* kPbrtTypes = "path volpath simplepath simplevolpath randomwalk mlt";
  static constexpr const char* kMitsubaTypes = "path volpath volpathmis prb";

  SampleBuffer render(const RenderContext& ctx, const TaskKey& task, bool parallel) const;
  bool operator==(const PathIntegrator&) const = default;
};

}  // namespace rf
