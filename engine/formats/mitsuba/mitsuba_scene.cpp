// The Mitsuba 3 XML importer: not written yet; the file is refused with a clear error.
#include "engine/formats/importers.h"

namespace rf {

Scene load_mitsuba_scene(const std::string& path) {
  throw SceneError(path + ": Mitsuba 3 XML scenes cannot be read yet (this build reads .json scenes)");
}

}  // namespace rf
