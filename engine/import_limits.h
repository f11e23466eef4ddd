// Bounds on the work of importing one scene, whatever its format (docs/security.md, "Scene
// import"). A scene is untrusted input on a farm: depth limits alone do not bound the work of a
// file that includes another ten times, which includes the next ten times. A scene over a bound
// is refused with a SceneError naming the file, where in it, and the bound.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace rf {

// Nesting of JSON arrays and objects, XML elements and pbrt attribute blocks: deeper input is
// refused before a recursive reader (tinygltf's, the importers' own) sees it.
inline constexpr int kMaxNesting = 512;

struct ImportLimits {
  // Files read: the main file, every include (a file included ten times counts ten times),
  // mesh, buffer and image file (each once).
  uint64_t files = 10000;
  // Bytes of those reads.
  uint64_t bytes = uint64_t(8) << 30;
  // The scene's shapes, instances, objects, lights, materials and textures, plus the triangles
  // copied to world space for instanced emitters (Scene::prepare_instances).
  uint64_t elements = 10000000;

  // By the names `rayfarm coordinator --limit import_NAME=VALUE` uses (files, bytes, elements);
  // false if there is no such bound.
  bool set(const std::string& name, uint64_t value);
  static std::vector<std::string> names();
};

// Image reads (OpenImageIO, OpenEXR) on at most `threads` threads from now on in this process:
// the scene check's child sets 1, so that its CPU budget is one core's.
void set_import_threads(int threads);

}  // namespace rf
