// The Renderer: what one scene needs to render any of its tasks (DESIGN.md "Work units"): the
// Embree BVH, the light set, the texture cache, the camera, and the per-pass state of the
// integrators that precompute (VPLs, photons). Immutable after construction apart from that
// cache; any thread renders any task (frame, rect, pass) of any frame of the scene, so a worker
// renders a whole sequence of one scene on one BVH. A scene whose geometry moves has one BVH per
// frame (Accel: the placements over that frame's shutter), built by the first task of the frame
// and kept for the kKeepFrames frames used last; the geometry no frame changes (AccelGeometry:
// the meshes' and objects' BVHs) is built once, with the renderer.
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include <tbb/collaborative_call_once.h>

#include "engine/accel.h"
#include "engine/camera.h"
#include "engine/frame.h"
#include "engine/integrators/common.h"
#include "engine/lights/light_set.h"
#include "engine/sample_buffer.h"
#include "engine/scene.h"
#include "engine/texture.h"
#include "engine/work_units.h"

namespace rf {

class Renderer {
 public:
  // Builds the scene's acceleration structure and lights; throws SceneError when its integrator
  // cannot render it (check_renderable). The scene must outlive the renderer.
  explicit Renderer(const Scene& scene);

  const Scene& scene() const { return scene_; }
  // Frame 0's BVH and what integrators see then (for tests and tools that call an estimator
  // directly; a scene without moving geometry has only this one).
  const Accel& accel() const { return *first_frame().accel; }
  const LightSet& lights() const { return *lights_; }
  const TextureEvaluator& textures() const { return *textures_; }
  const RenderContext& context() const { return *first_frame().context; }

  // True for integrators whose tasks cover the whole frame and splat (light tracing, BDPT).
  bool splats() const;
  // Whether anything emits light (area, punctual or environment lights).
  bool has_lights() const;
  // Header of every buffer this scene's frame produces, for the given passes.
  BufferHeader header(FrameNumber frame, const PassSet& passes) const;
  // The task rects of a frame (work_units).
  TileGrid tiles(int tile_size) const { return work_units(scene_, tile_size); }

  // Renders one task into a one-pass sample buffer. With parallel = true its rows (or light
  // paths) are spread over TBB's threads (a worker rendering one task on all cores); the pixels
  // are the same either way.
  SampleBuffer render(const TaskKey& task, bool parallel) const;

  // Stops the tasks rendering now: each throws RenderStopped at its next sample (a pass of 10^12
  // samples per pixel is stopped too, not only the next one), and so does every render() until
  // resume(). Any thread may call it.
  void request_stop() const { stop_.store(true, std::memory_order_relaxed); }
  void resume() const { stop_.store(false, std::memory_order_relaxed); }

  // The frames whose BVH a scene with moving geometry keeps (a worker's tasks come a frame at a
  // time; a local frame range renders frame by frame).
  static constexpr size_t kKeepFrames = 2;

 private:
  // A frame's BVH and the context that sees it.
  struct FrameState {
    std::unique_ptr<Accel> accel;
    std::unique_ptr<RenderContext> context;
  };
  std::unique_ptr<FrameState> build_frame(FrameNumber frame) const;
  // The state of `frame` (the only one when nothing moves), built by its first caller while the
  // others that ask meanwhile wait and lend it their threads.
  std::shared_ptr<const FrameState> frame_state(FrameNumber frame) const;
  const FrameState& first_frame() const;

  const Scene& scene_;
  const bool per_frame_;  // geometry_moves(scene)
  std::unique_ptr<LightSet> lights_;
  std::unique_ptr<TextureEvaluator> textures_;
  std::unique_ptr<PerspectiveCamera> camera_;
  PassCache pass_cache_;
  float pixel_spread_ = 0;
  mutable std::atomic<bool> stop_{false};
  std::shared_ptr<const FrameState> still_;  // a scene without moving geometry: its one state
  std::shared_ptr<const AccelGeometry> geometry_;  // the part of the BVH frames share
  struct Entry {
    tbb::collaborative_once_flag once;
    std::shared_ptr<const FrameState> state;
  };
  mutable std::mutex mu_;
  mutable std::map<FrameNumber, std::shared_ptr<Entry>> frames_;  // by frame
  mutable std::vector<uint32_t> recent_;                       // least recently used first
  mutable std::once_flag first_once_;
  mutable std::shared_ptr<const FrameState> first_;  // frame 0's, for accel() and context()
};

}  // namespace rf
