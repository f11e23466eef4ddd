// What every integrator sees: the scene, its acceleration structure, lights and textures,
// read-only and shared by all threads. Integrators are free functions, one file each under
// engine/integrators/, dispatched on IntegratorKind (a closed set: a switch, no virtual calls).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "engine/accel.h"
#include "engine/bsdf.h"
#include "engine/camera.h"
#include "engine/lights.h"
#include "engine/sampler.h"
#include "engine/scene.h"
#include "engine/texture.h"

namespace rf {

enum class IntegratorKind : uint8_t {
  Whitted,
  AmbientOcclusion,
  Direct,
  Path,
  LightTracing,
  Bdpt,
  InstantRadiosity,
  PhotonMapping
};

// Throws std::invalid_argument for a name known_integrators() does not list.
IntegratorKind integrator_kind(const std::string& name);
// Splatting integrators render whole-frame tasks and fill the splat plane (DESIGN.md).
inline bool integrator_splats(IntegratorKind k) {
  return k == IntegratorKind::LightTracing || k == IntegratorKind::Bdpt;
}

struct RenderContext {
  const Scene& scene;
  const Accel& accel;
  const LightSet& lights;
  const TextureEvaluator& textures;
  float pixel_spread = 0;  // angle one pixel subtends at the camera (for texture footprints)
  uint32_t frame = 0;      // the frame rendered: its seed stream (DESIGN.md determinism contract)
};

// Per-thread counters an integrator updates; summed into the task's buffer.
struct TraceCounters {
  uint64_t rays = 0;
};

// The BSDF at a hit, its textures resolved with a ray-cone footprint of the given width.
Bsdf bsdf_at(const RenderContext& ctx, const SurfaceHit& hit, float cone_width);
// Whether a light sample is visible from a hit (a ray to infinity for infinite lights).
bool light_visible(const RenderContext& ctx, const SurfaceHit& hit, const LightSample& ls);
// Next-event estimation at a non-delta vertex: one light sample, weighted by the power heuristic
// against BSDF sampling (1 for delta lights); f * Le * |cos| * w / pdf, or 0 when occluded.
RGB light_sample_mis(const RenderContext& ctx, const SurfaceHit& hit, const Bsdf& bsdf, Vec3 wo,
                     float u_light, Vec2 u_point, TraceCounters& counters);

// Radiance arriving along a camera ray, one function per camera-path integrator.
RGB whitted_radiance(const RenderContext& ctx, Ray ray, Sampler& sampler, TraceCounters& counters);
RGB ao_radiance(const RenderContext& ctx, Ray ray, Sampler& sampler, TraceCounters& counters);
RGB direct_radiance(const RenderContext& ctx, Ray ray, Sampler& sampler, TraceCounters& counters);
RGB path_radiance(const RenderContext& ctx, Ray ray, Sampler& sampler, TraceCounters& counters);

// Light tracing: where a light path's camera connections land. Splats are recorded per chunk
// of light paths and added to the task's splat plane in chunk order, so the sum, and the image,
// does not depend on which thread traced which chunk.
struct Splat {
  uint32_t pixel;  // y * width + x
  RGB value;       // already weighted by the filter and the pixel count
};
struct SplatTarget {
  std::vector<Splat>* out;
  int width, height;
  const FilterSettings* filter;
};
// Traces one light path (its random numbers from `sampler`, already started for this path) and
// splats every vertex's connection to the camera.
void trace_light_path(const RenderContext& ctx, const PerspectiveCamera& camera, Sampler& sampler,
                      SplatTarget& target, TraceCounters& counters);

// Bidirectional path tracing (integrators/bdpt.cpp): one camera sample through `ray` (its
// subpath and a light subpath keyed by the same sample); returns what lands in the sample's own
// pixel (strategies t >= 2) and records t = 1 strategies as splats.
RGB bdpt_sample(const RenderContext& ctx, const PerspectiveCamera& camera, Ray ray,
                Sampler& sampler, SplatTarget& splats, TraceCounters& counters);

// Per-pass state of integrators that precompute something for a whole pass, built once per pass
// by the Renderer (a pure function of the scene, settings and pass) and shared read-only by the
// pass's tiles: instant radiosity's virtual point lights, photon mapping's photons.
struct VplSet;
struct PhotonMap;
std::shared_ptr<const VplSet> build_vpls(const RenderContext& ctx, uint32_t pass,
                                         TraceCounters& counters);
RGB ir_radiance(const RenderContext& ctx, const VplSet& vpls, Ray ray, Sampler& sampler,
                TraceCounters& counters);
std::shared_ptr<const PhotonMap> build_photon_map(const RenderContext& ctx, uint32_t pass,
                                                  TraceCounters& counters);
RGB ppm_radiance(const RenderContext& ctx, const PhotonMap& photons, Ray ray, Sampler& sampler,
                 TraceCounters& counters);

}  // namespace rf
