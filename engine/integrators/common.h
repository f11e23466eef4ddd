// What every integrator sees and shares: the scene with its acceleration structure, lights,
// textures and camera (read-only, shared by all threads), per-pass state, per-thread counters, and
// the few pieces several estimators use (the BSDF at a hit, shadow tests, next-event estimation).
#pragma once

#include <atomic>
#include <stdexcept>

#include <tbb/collaborative_call_once.h>

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include "engine/accel.h"
#include "engine/bsdf.h"
#include "engine/camera.h"
#include "engine/frame.h"
#include "engine/lights/light_set.h"
#include "engine/sampler.h"
#include "engine/scene.h"
#include "engine/texture.h"

namespace rf {

// Per-pass state of integrators that precompute something for a whole pass (instant radiosity's
// virtual point lights, photon mapping's photons): a pure function of (scene, settings, frame,
// pass), built once by the first task of a pass that needs it and shared read-only by the pass's
// tiles. Tasks of the same pass that arrive meanwhile wait for that build and lend it their
// threads (tbb::collaborative_call_once), so a pass's state is built exactly once. The few passes
// in flight are kept (a local render works on a window of passes, a worker on one task at a time).
class PassCache {
 public:
  template <class T, class Build>
  std::shared_ptr<const T> get(FrameNumber frame, uint32_t pass, Build&& build) const {
    std::shared_ptr<Entry> entry = entry_for((uint64_t(frame_bits(frame)) << 32) | pass);
    tbb::collaborative_call_once(entry->once, [&] { entry->state = build(); });
    return std::static_pointer_cast<const T>(entry->state);
  }

 private:
  struct Entry {
    tbb::collaborative_once_flag once;
    std::shared_ptr<const void> state;
  };
  std::shared_ptr<Entry> entry_for(uint64_t key) const {
    std::lock_guard<std::mutex> lock(mu_);
    auto [it, inserted] = entries_.try_emplace(key);
    if (inserted) {
      it->second = std::make_shared<Entry>();
      while (entries_.size() > kKeep)  // the oldest pass that is not this one
        entries_.erase(entries_.begin() == it ? std::next(entries_.begin()) : entries_.begin());
    }
    return it->second;
  }

  static constexpr size_t kKeep = 8;
  mutable std::mutex mu_;
  mutable std::map<uint64_t, std::shared_ptr<Entry>> entries_;
};

// How the path tracer's packets shade the vertices of a material
// (engine/integrators/path/surface_lanes.h): in the vectorised lanes, as a constant Lambertian lobe
// or as a constant rough conductor (not smooth enough to be a mirror), else one by one.
enum class LaneKind : uint8_t { OneByOne, Diffuse, RoughConductor };
LaneKind lane_kind(const Material& m);

// Thrown by a task that Renderer::request_stop() stopped; its buffer is discarded.
struct RenderStopped : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct RenderContext {
  RenderContext(const Scene& scene_, const Accel& accel_, const LightSet& lights_,
                const TextureEvaluator& textures_, const PerspectiveCamera& camera_,
                const PassCache& pass_cache_, float pixel_spread_, const std::atomic<bool>& stop_)
      : scene(scene_),
        accel(accel_),
        lights(lights_),
        textures(textures_),
        camera(camera_),
        pass_cache(pass_cache_),
        pixel_spread(pixel_spread_),
        stop(stop_),
        moves(scene_moves(scene_)) {
    for (const Material& m : scene.materials) lane_kinds.push_back(lane_kind(m));
    for (LaneKind k : lane_kinds) all_in_lanes &= k != LaneKind::OneByOne;
  }
  const Scene& scene;
  const Accel& accel;
  const LightSet& lights;
  const TextureEvaluator& textures;
  const PerspectiveCamera& camera;
  const PassCache& pass_cache;
  float pixel_spread = 0;  // angle one pixel subtends at the camera (for texture footprints)
  // lane_kind of each of the scene's materials, and whether none is OneByOne.
  std::vector<LaneKind> lane_kinds;
  bool all_in_lanes = true;
  // Renderer::request_stop(): the drivers check it at every camera sample and light path.
  const std::atomic<bool>& stop;
  // scene_moves(scene): camera samples and light paths draw a time (Ray::time).
  bool moves = false;
  // When a path at shutter position `time` samples a light (moving emitters read it).
  LightTime at(float time) const { return {&accel, time}; }
  void throw_if_stopped() const {
    if (stop.load(std::memory_order_relaxed)) throw RenderStopped("the render was stopped");
  }
};

// Per-thread counters an integrator updates; summed into the task's buffer.
struct TraceCounters {
  uint64_t rays = 0;
  // Path vertices shaded in the vectorised lanes (SurfaceLanes), and the rough-conductor ones
  // among them; not summed into the buffer, the packet test reads them.
  uint64_t lane_vertices = 0, conductor_lane_vertices = 0;
};

// The material's parameters at a hit, textures resolved with a ray-cone footprint of the given
// width, and the BSDF they make.
BsdfParams material_params_at(const RenderContext& ctx, const SurfaceHit& hit, float cone_width);
Bsdf bsdf_at(const RenderContext& ctx, const SurfaceHit& hit, float cone_width);
// The shadow ray from a hit to a light sample (a ray to infinity for infinite lights).
Ray light_shadow_ray(const RenderContext& ctx, const SurfaceHit& hit, const LightSample& ls);
// Whether a light sample is visible from a hit: nothing blocks light_shadow_ray.
bool light_visible(const RenderContext& ctx, const SurfaceHit& hit, const LightSample& ls);

// The receiver normal light selection may use at a surface with this BSDF and outgoing direction
// wo (LightSet::sample): the geometric normal on wo's side when the BSDF only reflects (light
// from the other side contributes nothing), zero when it transmits.
inline Vec3 receiver_normal(const Bsdf& bsdf, Vec3 wo) {
  if (bsdf.transmits()) return Vec3(0.0f);
  Vec3 ng = bsdf.geometric_normal();
  return dot(wo, ng) >= 0 ? ng : -ng;
}
// Next-event estimation at a non-delta vertex: one light sample, weighted by the power heuristic
// against BSDF sampling (1 for delta lights); f * Le * |cos| * w / pdf, or 0 when occluded.
RGB light_sample_mis(const RenderContext& ctx, const SurfaceHit& hit, const Bsdf& bsdf, Vec3 wo,
                     float u_light, Vec2 u_point, TraceCounters& counters);
// light_sample_mis without its shadow test, for callers that cast shadow rays in packets: the
// contribution if unoccluded and the shadow ray that decides it. False (contribution 0, no ray to
// cast) when no light was sampled or the BSDF is black towards it. With mis false the sample
// takes the full weight (1): for a vertex whose BSDF sample is not traced on, so that light
// sampling is its only strategy.
bool light_sample_mis_unshadowed(const RenderContext& ctx, const SurfaceHit& hit, const Bsdf& bsdf,
                                 Vec3 wo, float u_light, Vec2 u_point, RGB& contribution,
                                 Ray& shadow, bool mis = true);
// A camera path with throughput beta left the scene in direction dir: adds the environment's
// radiance to `radiance`, weighted by the power heuristic against light sampling when the last
// scattering was not a delta one (prev_bsdf_pdf: that BSDF sample's solid-angle density).
// Nothing without an environment.
void add_escaped(const RenderContext& ctx, Vec3 dir, bool prev_delta, float prev_bsdf_pdf, RGB beta,
                 RGB& radiance);

}  // namespace rf
