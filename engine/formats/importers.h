// The importers, one per format (engine/formats/<format>/), all of one shape: each takes the main
// file's bytes and fills the scene (whose path is set), reading every file it references through
// SceneFiles (so the farm ships them and the digest covers them). import_scene owns what they
// share: it picks the importer by the file's extension, reads the main file (counted against the
// limits), and sets the digest and assets after it; load_scene (scene.h) then prepares instances
// and applies command-line overrides.
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

class SceneFiles;

void import_json(const std::string& bytes, SceneFiles& files, Scene& scene);     // the rest
void import_pbrt(const std::string& bytes, SceneFiles& files, Scene& scene);     // .pbrt, pbrt-v4
void import_mitsuba(const std::string& bytes, SceneFiles& files, Scene& scene);  // .xml, Mitsuba 3
void import_gltf(const std::string& bytes, SceneFiles& files, Scene& scene);     // .gltf, .glb

// The scene in `path` as its importer reads it, with its digest and assets, before instances are
// prepared and overrides applied. Counts what it reads against `limits`.
Scene import_scene(const std::string& path, const ImportLimits& limits = {});

}  // namespace rf
