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

Scene load_scene(const std::string& path, const SceneOverrides& overrides) {
  const std::string ext = extension_of(path);
  Scene scene = ext == ".pbrt"                    ? load_pbrt_scene(path)
                : ext == ".xml"                   ? load_mitsuba_scene(path)
                : ext == ".gltf" || ext == ".glb" ? load_gltf_scene(path)
                                                  : load_json_scene(path);  // .json and the rest
  for (const std::string& w : scene.warnings) spdlog::warn("{}", w);
  prepare_instances(scene);
  apply_overrides(scene, overrides);
  return scene;
}

}  // namespace rf
