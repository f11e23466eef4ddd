// load_scene: the importer by the file's extension, then instances, overrides and warnings.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "engine/formats/importers.h"

namespace rf {

namespace {

std::string extension_of(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

}  // namespace

Scene load_scene(const std::string& path, const SceneOverrides& overrides,
                 const ImportLimits& limits) {
  const std::string ext = extension_of(path);
  Scene scene = ext == ".pbrt"                    ? load_pbrt_scene(path, limits)
                : ext == ".xml"                   ? load_mitsuba_scene(path, limits)
                : ext == ".gltf" || ext == ".glb" ? load_gltf_scene(path, limits)
                                                  : load_json_scene(path, limits);  // the rest
  for (const std::string& w : scene.warnings) spdlog::warn("{}", w);
  prepare_instances(scene, limits.elements);
  apply_overrides(scene, overrides);
  return scene;
}

}  // namespace rf
