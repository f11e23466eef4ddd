// What the farm needs to know of a scene without holding it (DESIGN.md "The coordinator"): the
// identity of its frames' buffers, its work split and its sample budget. The coordinator plans
// and checks a job from summaries that a child process made from the untrusted scene files
// (coordinator/scene_check.h); a local render makes them from the scene it holds.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "engine/aov.h"
#include "engine/frame.h"
#include "engine/sample_buffer.h"
#include "engine/scene.h"

namespace rf {

struct SceneSummary {
  std::string digest;  // the scene's (Scene::digest)
  uint64_t seed = 0;
  std::string integrator;  // its name
  std::string settings;    // settings_text(): what else changes pixels
  int width = 0, height = 0;
  AovSet aovs;
  uint32_t passes = 0;
  uint64_t spp = 0, spp_per_pass = 0;
  double noise_target = 0;
  bool splats = false;  // the integrator splats light paths over the whole frame
  bool operator==(const SceneSummary&) const = default;
};

SceneSummary summarize(const Scene& scene);

// The rects a frame is split into: tiles of tile_size (row-major, clipped at the border), or the
// whole frame for splatting integrators (and for tile_size <= 0).
TileGrid work_units(const SceneSummary& scene, int tile_size);
// The header every buffer of this scene's frame carries, for the given passes: scene digest,
// seed, frame, integrator and settings text, resolution, this build and CPU kind.
BufferHeader frame_header(const SceneSummary& scene, FrameNumber frame, const PassSet& passes);

// As JSON (the child process's answer, the coordinator's cache of it). from_json throws
// std::runtime_error naming the field that is missing or of the wrong type.
nlohmann::json to_json(const SceneSummary& s);
SceneSummary summary_from_json(const nlohmann::json& j);

}  // namespace rf
