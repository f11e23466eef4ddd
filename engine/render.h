// The Renderer: what one scene needs to render any of its tasks (DESIGN.md "Work units"): the
// Embree BVH, the light set, the texture cache, the camera, and the per-pass state of the
// integrators that precompute (VPLs, photons). Immutable after construction apart from that
// cache; any thread renders any task (frame, rect, pass) of any frame of the scene, so a worker
// renders a whole sequence of one scene on one BVH.
#pragma once

#include <memory>
#include <vector>

#include "engine/accel.h"
#include "engine/camera.h"
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
  const Accel& accel() const { return *accel_; }
  const LightSet& lights() const { return *lights_; }
  const TextureEvaluator& textures() const { return *textures_; }
  // What integrators see (for tests and tools that call an estimator directly).
  const RenderContext& context() const { return *context_; }

  // True for integrators whose tasks cover the whole frame and splat (light tracing, BDPT).
  bool splats() const;
  // Whether anything emits light (area, punctual or environment lights).
  bool has_lights() const;
  // Header of every buffer this scene's frame produces, for the given passes.
  BufferHeader header(uint32_t frame, const PassSet& passes) const;
  // The task rects of a frame (work_units).
  std::vector<Rect> tiles(int tile_size) const { return work_units(scene_, tile_size); }

  // Renders one task into a one-pass sample buffer. With parallel = true its rows (or light
  // paths) are spread over TBB's threads (a worker rendering one task on all cores); the pixels
  // are the same either way.
  SampleBuffer render(const TaskKey& task, bool parallel) const;

  // Stops the tasks rendering now: each throws RenderStopped at its next sample (a pass of 10^12
  // samples per pixel is stopped too, not only the next one), and so does every render() until
  // resume(). Any thread may call it.
  void request_stop() const { context_->stop.store(true, std::memory_order_relaxed); }
  void resume() const { context_->stop.store(false, std::memory_order_relaxed); }

 private:
  const Scene& scene_;
  std::unique_ptr<Accel> accel_;
  std::unique_ptr<LightSet> lights_;
  std::unique_ptr<TextureEvaluator> textures_;
  std::unique_ptr<PerspectiveCamera> camera_;
  PassCache pass_cache_;
  std::unique_ptr<RenderContext> context_;
};

}  // namespace rf
