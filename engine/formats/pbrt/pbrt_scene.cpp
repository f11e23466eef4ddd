// The pbrt-v4 importer: not written yet; the file is refused with a clear error.
#include "engine/formats/importers.h"

namespace rf {

Scene load_pbrt_scene(const std::string& path) {
  throw SceneError(path + ": pbrt-v4 scenes cannot be read yet (this build reads .json scenes)");
}

}  // namespace rf
