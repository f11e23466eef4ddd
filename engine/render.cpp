#include "engine/render.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include <spdlog/spdlog.h>

#include "engine/check.h"

namespace rf {

Renderer::Renderer(const Scene& scene)
    : scene_(scene),
      per_frame_(geometry_moves(scene)),
      lights_(std::make_unique<LightSet>(scene)),
      textures_(std::make_unique<TextureEvaluator>(scene)),
      camera_(
          std::make_unique<PerspectiveCamera>(scene.camera, scene.film.width, scene.film.height)) {
  check_renderable(scene);
  float t = std::tan(0.5f * scene.camera.fov_deg * kPi / 180.0f);
  pixel_spread_ = 2 * t / float(std::min(scene.film.width, scene.film.height));
  geometry_ = std::make_shared<const AccelGeometry>(scene);  // what no frame changes
  if (!per_frame_) still_ = build_frame(0);
}

std::unique_ptr<Renderer::FrameState> Renderer::build_frame(FrameNumber frame) const {
  auto f = std::make_unique<FrameState>();
  const auto t0 = std::chrono::steady_clock::now();
  f->accel = std::make_unique<Accel>(geometry_, frame);
  if (per_frame_) {
    size_t moving = 0, deforming = 0;
    for (const Instance& i : scene_.instances) moving += i.moves();
    for (const Mesh& m : scene_.meshes) deforming += m.deforms();
    spdlog::info(
        "frame {}: BVH built in {:.4f} s ({} instances, {} moving; {} deforming shapes; up to {} "
        "time steps)",
        frame, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(),
        scene_.instances.size(), moving, deforming, f->accel->time_steps());
  }
  f->context = std::make_unique<RenderContext>(scene_, *f->accel, *lights_, *textures_, *camera_,
                                               pass_cache_, pixel_spread_, stop_);
  return f;
}

std::shared_ptr<const Renderer::FrameState> Renderer::frame_state(FrameNumber frame) const {
  if (!per_frame_) return still_;
  std::shared_ptr<Entry> entry;
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto [it, inserted] = frames_.try_emplace(frame);
    if (inserted) it->second = std::make_shared<Entry>();
    entry = it->second;
    recent_.erase(std::remove(recent_.begin(), recent_.end(), frame), recent_.end());
    recent_.push_back(frame);
    while (recent_.size() > kKeepFrames) {  // tasks in flight hold their state
      frames_.erase(recent_.front());
      recent_.erase(recent_.begin());
    }
  }
  tbb::collaborative_call_once(entry->once, [&] { entry->state = build_frame(frame); });
  return entry->state;
}

const Renderer::FrameState& Renderer::first_frame() const {
  std::call_once(first_once_, [&] { first_ = frame_state(0); });
  return *first_;
}

bool Renderer::has_lights() const { return !lights_->empty(); }

bool Renderer::splats() const { return integrator_splats(scene_.render.integrator.method); }

BufferHeader Renderer::header(FrameNumber frame, const PassSet& passes) const {
  return frame_header(scene_, frame, passes);
}

SampleBuffer Renderer::render(const TaskKey& task, bool parallel) const {
  const Rect film{0, 0, scene_.film.width, scene_.film.height};
  RF_CHECK(task.rect.w > 0 && task.rect.h > 0 && film.contains(task.rect),
           "task rect " + to_string(task.rect) + " in a " + to_string(film) + " film");
  const std::shared_ptr<const FrameState> state = frame_state(task.frame);
  return render_task(*state->context, task, parallel);
}

}  // namespace rf
