// The files a scene reads besides itself, as the farm ships them (DESIGN.md "Coordinator": scene
// bundles are content-addressed, asset names are relative paths inside the bundle). Every format's
// importer registers what it reads here: meshes, images, included scene files. Names are
// relative to the main scene file's directory (the bundle root), '/'-separated, without ".." or
// an absolute path, and must not lead outside the root through a symbolic link. The scene's digest
// covers the main file's bytes and every registered file's name and SHA-256. Every read is counted
// against the scene's ImportLimits (files and bytes, engine/import_limits.h).
#pragma once

#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "engine/import_limits.h"
#include "engine/mesh_io.h"
#include "engine/scene.h"

namespace rf {

class SceneFiles {
 public:
  explicit SceneFiles(const std::string& scene_path, const ImportLimits& limits = {});

  // The main scene file's bytes (the first read counted); throws SceneError naming the path.
  std::string read_main();
  const std::string& root() const { return root_; }  // the main file's directory
  const ImportLimits& limits() const { return limits_; }
  // Checks a referenced file name (relative to the root) and returns it normalised
  // ("./a//b.obj" -> "a/b.obj"). Errors are SceneErrors "<scene file>: <where>: <why>".
  std::string name(const std::string& file, const std::string& where) const;
  // Where a checked name is on disk.
  std::string path_of(const std::string& name) const;
  // Registers a file the scene reads (an image, an included file): checks that it exists inside
  // the root and hashes it; returns its name. Registering a name twice is harmless.
  std::string add(const std::string& file, const std::string& where,
                  const std::string& noun = "file");
  // add() and the file's bytes (for included scene files a parser reads itself).
  std::string read(const std::string& file, const std::string& where);
  // add() and the mesh in it: OBJ or PLY by `type` ("obj", "ply"; empty: by the extension),
  // parsed once per name. Throws SceneError naming `where` and the file's own line.
  const MeshData& mesh(const std::string& file, const std::string& type, const std::string& where);

  // Sets scene.assets (in order of first use) and scene.digest from the main file's bytes:
  // SHA-256 over them, then per asset a NUL, its name, a NUL and the hex SHA-256 of its bytes.
  void finish(Scene& scene, std::string_view main_bytes) const;

 private:
  [[noreturn]] void fail(const std::string& where, const std::string& what) const;
  std::string register_file(const std::string& file, const std::string& where,
                            const std::string& noun, std::string* bytes_out);
  // Counts a read of `bytes` bytes against the limits before it is made.
  void count_read(const std::string& where, const std::string& name, uint64_t bytes);

  std::string scene_path_, root_;
  ImportLimits limits_;
  uint64_t files_read_ = 0, bytes_read_ = 0;
  std::vector<std::string> names_;  // in order of first use
  std::map<std::string, std::string> digests_;
  std::map<std::string, MeshData> meshes_;
};

// The main scene file's bytes; throws SceneError naming the path.
std::string read_scene_file(const std::string& path);

}  // namespace rf
