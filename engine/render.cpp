#include "engine/render.h"

#include <algorithm>
#include <cmath>

#include "engine/check.h"

namespace rf {

Renderer::Renderer(const Scene& scene)
    : scene_(scene),
      accel_(std::make_unique<Accel>(scene)),
      lights_(std::make_unique<LightSet>(scene)),
      textures_(std::make_unique<TextureEvaluator>(scene)),
      camera_(std::make_unique<PerspectiveCamera>(scene.camera, scene.film.width,
                                                  scene.film.height)) {
  check_renderable(scene);
  float t = std::tan(0.5f * scene.camera.fov_deg * kPi / 180.0f);
  context_.reset(new RenderContext(scene_, *accel_, *lights_, *textures_, *camera_, pass_cache_,
                                   2 * t / float(std::min(scene.film.width, scene.film.height))));
}

bool Renderer::has_lights() const { return !lights_->empty(); }

bool Renderer::splats() const { return integrator_splats(scene_.render.integrator.method); }

BufferHeader Renderer::header(uint32_t frame, const PassSet& passes) const {
  return frame_header(scene_, frame, passes);
}

SampleBuffer Renderer::render(const TaskKey& task, bool parallel) const {
  const Rect film{0, 0, scene_.film.width, scene_.film.height};
  RF_CHECK(task.rect.w > 0 && task.rect.h > 0 && film.contains(task.rect),
           "task rect " + to_string(task.rect) + " in a " + to_string(film) + " film");
  return render_task(*context_, task, parallel);
}

}  // namespace rf
