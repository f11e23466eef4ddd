// The importers, one per format (engine/formats/<format>/): each reads its file and every file it
// references (registered through SceneFiles, so the farm ships them and the digest covers them)
// and returns the engine's Scene with its digest and assets set, before command-line overrides.
// load_scene (scene.h) picks one by the file's extension and applies the overrides.
//
// Error policy, every format: a problem is a SceneError naming the file, the line (or JSON/XML
// path) and the directive; a feature the importer does not support is a warning (in
// Scene::warnings and the log) when ignoring it changes the image little, an error when it would
// change it a lot (an unsupported material on a surface, an unsupported shape). Never a silent
// wrong image. Referenced files must lie inside the scene file's directory.
#pragma once

#include <string>

#include "engine/scene.h"

namespace rf {

// Each counts what it reads against `limits` (engine/import_limits.h).
Scene load_json_scene(const std::string& path,
                      const ImportLimits& limits = {});  // docs/scene-format.md
Scene load_pbrt_scene(const std::string& path, const ImportLimits& limits = {});  // pbrt-v4
Scene load_mitsuba_scene(const std::string& path,
                         const ImportLimits& limits = {});                        // Mitsuba 3 XML
Scene load_gltf_scene(const std::string& path, const ImportLimits& limits = {});  // .gltf and .glb

}  // namespace rf
