#include "engine/scene_summary.h"

#include <algorithm>
#include <stdexcept>

#include "engine/build_info.h"

namespace rf {

SceneSummary summarize(const Scene& scene) {
  SceneSummary s;
  s.digest = scene.digest;
  s.seed = scene.render.seed;
  s.integrator = scene.render.integrator.type();
  s.settings = settings_text(scene);
  s.width = scene.film.width;
  s.height = scene.film.height;
  s.aovs = scene.render.aovs;
  s.passes = scene.render.passes;
  s.spp = scene.render.spp;
  s.spp_per_pass = scene.render.spp_per_pass();
  s.noise_target = scene.render.noise_target;
  s.splats = integrator_splats(scene.render.integrator.method);
  return s;
}

TileGrid work_units(const SceneSummary& scene, int tile_size) {
  return TileGrid(scene.width, scene.height, scene.splats ? 0 : tile_size);
}

BufferHeader frame_header(const SceneSummary& scene, FrameNumber frame, const PassSet& passes) {
  BufferHeader h;
  h.scene_digest = scene.digest;
  h.seed = scene.seed;
  h.frame = frame;
  h.integrator = scene.integrator;
  h.settings = scene.settings;
  h.width = scene.width;
  h.height = scene.height;
  h.aovs = scene.aovs;
  h.passes = passes;
  h.build_id = build_id();
  h.isa = cpu_isa();
  return h;
}

nlohmann::json to_json(const SceneSummary& s) {
  return {{"digest", s.digest},
          {"seed", s.seed},
          {"integrator", s.integrator},
          {"settings", s.settings},
          {"width", s.width},
          {"height", s.height},
          {"aovs", to_string(s.aovs)},
          {"passes", s.passes},
          {"spp", s.spp},
          {"spp_per_pass", s.spp_per_pass},
          {"noise_target", s.noise_target},
          {"splats", s.splats}};
}

SceneSummary summary_from_json(const nlohmann::json& j) {
  auto field = [&](const char* name) -> const nlohmann::json& {
    if (!j.is_object() || !j.contains(name))
      throw std::runtime_error(std::string("scene summary: no field \"") + name + "\"");
    return j.at(name);
  };
  SceneSummary s;
  try {
    s.digest = field("digest").get<std::string>();
    s.seed = field("seed").get<uint64_t>();
    s.integrator = field("integrator").get<std::string>();
    s.settings = field("settings").get<std::string>();
    s.width = field("width").get<int>();
    s.height = field("height").get<int>();
    s.aovs = parse_aovs(field("aovs").get<std::string>());
    s.passes = field("passes").get<uint32_t>();
    s.spp = field("spp").get<uint64_t>();
    s.spp_per_pass = field("spp_per_pass").get<uint64_t>();
    s.noise_target = field("noise_target").get<double>();
    s.splats = field("splats").get<bool>();
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(std::string("scene summary: ") + e.what());
  }
  if (s.width < 1 || s.height < 1 || s.width > kMaxResolution || s.height > kMaxResolution ||
      s.passes < 1 || s.spp_per_pass < 1)
    throw std::runtime_error("scene summary: resolution, passes or spp out of range");
  return s;
}

}  // namespace rf
