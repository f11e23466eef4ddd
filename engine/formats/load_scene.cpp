// import_scene: the importer by the file's extension between the steps every format shares;
// load_scene: then warnings, instances and overrides.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <filesystem>

#include "engine/formats/importers.h"
#include "engine/formats/scene_files.h"

namespace rf {

namespace {

std::string extension_of(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

}  // namespace

Scene import_scene(const std::string& path, const ImportLimits& limits) {
  const std::string ext = extension_of(path);
  auto importer = ext == ".pbrt"                    ? import_pbrt
                  : ext == ".xml"                   ? import_mitsuba
                  : ext == ".gltf" || ext == ".glb" ? import_gltf
                                                    : import_json;  // the rest
  SceneFiles files(path, limits);
  std::string bytes = files.read_main();
  Scene scene;
  scene.path = path;
  importer(bytes, files, scene);
  files.finish(scene, bytes);
  return scene;
}

Scene load_scene(const std::string& path, const SceneOverrides& overrides,
                 const ImportLimits& limits) {
  Scene scene = import_scene(path, limits);
  for (const std::string& w : scene.warnings) spdlog::warn("{}", w);
  prepare_instances(scene, limits.elements);
  apply_overrides(scene, overrides);
  return scene;
}

}  // namespace rf
