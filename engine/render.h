// Rendering work units (DESIGN.md "Work units"): a task is (frame, rect, pass). The Renderer
// owns what a scene needs to render (Embree BVH, lights) and renders one task into a sample
// buffer; tasks are pure functions of (scene, settings, rect, pass), so they can run anywhere.
#pragma once

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <vector>

#include "engine/accel.h"
#include "engine/film.h"
#include "engine/integrator.h"
#include "engine/lights.h"
#include "engine/scene.h"
#include "engine/texture.h"

namespace rf {

class Renderer {
 public:
  explicit Renderer(const Scene& scene);

  const Scene& scene() const { return scene_; }
  const Accel& accel() const { return *accel_; }
  const LightSet& lights() const { return *lights_; }
  const TextureEvaluator& textures() const { return *textures_; }
  // What integrators see (for tests and tools that call an integrator directly).
  RenderContext context() const;

  // True for integrators whose tasks cover the whole frame and splat (light tracing, BDPT).
  bool splats() const { return integrator_splats(kind_); }
  // Header of every buffer this scene and its settings produce, for the given passes.
  BufferHeader header(const PassSet& passes) const;
  // The tiles of the frame (whole frame for splatting integrators), row-major.
  std::vector<Rect> tiles(int tile_size) const;

  // Renders one pass of one rect. With parallel = true the rows are spread over TBB's threads
  // (a worker rendering one task on all cores); the pixels are the same either way.
  SampleBuffer render_task(const Rect& rect, uint32_t pass, bool parallel) const;

  // Renders another frame of the same scene from now on (the frame only selects the seed stream,
  // so the BVH, lights and textures are kept: a worker renders a sequence without rebuilding).
  // Not concurrent with render_task.
  void set_frame(uint32_t frame);
  uint32_t frame() const { return frame_; }

 private:
  SampleBuffer render_camera_paths(const Rect& rect, uint32_t pass, bool parallel) const;
  SampleBuffer render_light_paths(uint32_t pass, bool parallel) const;
  SampleBuffer render_bdpt(uint32_t pass, bool parallel) const;
  std::shared_ptr<const VplSet> pass_vpls(uint32_t pass, std::atomic<uint64_t>& rays) const;
  std::shared_ptr<const PhotonMap> pass_photons(uint32_t pass, std::atomic<uint64_t>& rays) const;

  const Scene& scene_;
  IntegratorKind kind_;
  uint32_t frame_;
  std::unique_ptr<Accel> accel_;
  std::unique_ptr<LightSet> lights_;
  std::unique_ptr<TextureEvaluator> textures_;
  // Per-pass state of IR / PPM (see integrator.h), shared by a pass's tiles.
  mutable std::mutex cache_mutex_;
  // Keyed by (frame, pass): VPLs and photons belong to one frame's seed stream.
  mutable std::map<uint64_t, std::shared_ptr<const void>> pass_cache_;
  uint64_t pass_key(uint32_t pass) const { return (uint64_t(frame_) << 32) | pass; }
};

// Canonical text of the settings that change pixels, beside the scene digest (BufferHeader).
std::string settings_text(const Scene& scene);

// Throws SceneError when the scene's integrator cannot render it (the Renderer's own check, without
// building one; the coordinator runs it at submit).
void check_renderable(const Scene& scene);

// What Renderer::header and Renderer::tiles return, without building a renderer (the
// coordinator splits and checks frames from a parsed scene alone).
BufferHeader frame_header(const Scene& scene, const PassSet& passes);
std::vector<Rect> frame_tiles(const Scene& scene, int tile_size);

}  // namespace rf
