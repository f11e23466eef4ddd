// Whitted ray tracing (`whitted`).
//
// Estimator: from the camera, follow only delta BSDFs (mirror reflection, glass refraction and
// reflection chosen by Fresnel); at the first surface that is not purely specular, add direct
// lighting: every point, spot and directional light exactly (one shadow ray each) and the area
// lights and environment by one light sample (chosen by power, delta picks discarded, so the
// estimate is unbiased for the non-delta lights). Emitters and the environment seen through the
// specular chain are added as they are.
// Parameters: max_depth bounds the specular chain (pbrt-v4's meaning, as every integrator).
// Strengths: fast, noise-free for delta lights, sharp reflections and refractions.
// Cannot do: it is NOT a global-illumination method. No light reaches a diffuse or glossy surface
// by way of another surface (no indirect light, no colour bleeding, no caustics), and glossy
// surfaces get only their direct lighting. Its image converges to the path tracer restricted to
// camera -> specular* -> one non-specular vertex -> light.
#pragma once

#include <string>

#include "engine/integrators/module.h"

namespace rf {

struct WhittedIntegrator : IntegratorDefaults {
  static constexpr const char* kName = "whitted";
  static constexpr bool kSplats = false;
  static constexpr const char* kKeys[] = {"type", "max_depth"};

  SampleBuffer render(const RenderContext& ctx, const TaskKey& task, bool parallel) const;
  bool operator==(const WhittedIntegrator&) const = default;
};

}  // namespace rf
