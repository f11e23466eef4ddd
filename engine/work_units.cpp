#include "engine/work_units.h"

#include <algorithm>

#include "engine/build_info.h"

namespace rf {

std::vector<Rect> work_units(const Scene& scene, int tile_size) {
  int w = scene.film.width, h = scene.film.height;
  if (integrator_splats(scene.render.integrator.method) || tile_size <= 0) return {Rect{0, 0, w, h}};
  std::vector<Rect> out;
  for (int y = 0; y < h; y += tile_size)
    for (int x = 0; x < w; x += tile_size)
      out.push_back({x, y, std::min(tile_size, w - x), std::min(tile_size, h - y)});
  return out;
}

BufferHeader frame_header(const Scene& scene, uint32_t frame, const PassSet& passes) {
  BufferHeader h;
  h.scene_digest = scene.digest;
  h.seed = scene.render.seed;
  h.frame = frame;
  h.integrator = scene.render.integrator.type();
  h.settings = settings_text(scene);
  h.width = scene.film.width;
  h.height = scene.film.height;
  h.aovs = scene.render.aovs;
  h.passes = passes;
  h.build_id = build_id();
  h.isa = cpu_isa();
  return h;
}

}  // namespace rf
