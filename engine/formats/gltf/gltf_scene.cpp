// The glTF 2.0 importer: not written yet; the file is refused with a clear error.
#include "engine/formats/importers.h"

namespace rf {

Scene load_gltf_scene(const std::string& path) {
  throw SceneError(path + ": glTF 2.0 scenes cannot be read yet (this build reads .json scenes)");
}

}  // namespace rf
