// What every integrator sees: the scene, its acceleration structure and its lights, read-only
// and shared by all threads. Integrators are free functions dispatched on the settings' type.
#pragma once

#include <cstdint>

#include "engine/accel.h"
#include "engine/lights.h"
#include "engine/sampler.h"
#include "engine/scene.h"
#include "engine/texture.h"

namespace rf {

struct RenderContext {
  const Scene& scene;
  const Accel& accel;
  const LightSet& lights;
  const TextureEvaluator& textures;
  float pixel_spread = 0;  // angle one pixel subtends at the camera (for texture footprints)
};

// Per-thread counters an integrator updates; summed into the task's buffer.
struct TraceCounters {
  uint64_t rays = 0;
};

// Radiance arriving along a camera ray (integrators/path.cpp).
RGB path_radiance(const RenderContext& ctx, Ray ray, Sampler& sampler,
                  TraceCounters& counters);

}  // namespace rf
