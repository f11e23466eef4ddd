// The one error type of bad scene input.
#pragma once

#include <stdexcept>

namespace rf {

// Thrown for any bad scene input. The message names the file, the JSON path (or line) and what
// was expected, e.g. "scene.json: shapes[3].material: unknown material 'flor'".
struct SceneError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

}  // namespace rf
