#include "engine/formats/scene_files.h"

#include <filesystem>
#include <new>
#include <system_error>

#include "engine/digest.h"

namespace rf {

namespace fs = std::filesystem;

namespace {


// True when `p` (resolved through symbolic links) lies inside `root`.
bool inside(const fs::path& root, const fs::path& p) {
  std::error_code ec;
  fs::path r = fs::weakly_canonical(root, ec), c = fs::weakly_canonical(p, ec);
  if (ec == std::errc::not_enough_memory) throw std::bad_alloc();  // not "outside the root"
  if (ec) return false;
  auto rel = c.lexically_relative(r);
  return !rel.empty() && *rel.begin() != "..";
}

}  // namespace

SceneFiles::SceneFiles(const std::string& scene_path, const ImportLimits& limits)
    : scene_path_(scene_path),
      root_(fs::path(scene_path).parent_path().string()),
      limits_(limits) {}

std::string SceneFiles::read_main() {
  std::error_code ec;
  if (fs::is_directory(scene_path_, ec))
    throw SceneError(scene_path_ + ": is a directory, not a scene file");
  uintmax_t size = fs::file_size(scene_path_, ec);
  if (!ec) {
    if (size > limits_.bytes)
      throw SceneError(scene_path_ + ": " + std::to_string(size) +
                       " bytes; the import limit bytes is " + std::to_string(limits_.bytes));
    bytes_read_ += size;
  }
  ++files_read_;
  return read_scene_file(scene_path_);
}

void SceneFiles::count_read(const std::string& where, const std::string& name, uint64_t bytes) {
  if (files_read_ + 1 > limits_.files)
    fail(where, "reading '" + name + "' would make more than " + std::to_string(limits_.files) +
                    " file reads (the import limit files; every include counts, so includes "
                    "that include the same files many times exceed it)");
  if (bytes > limits_.bytes || bytes_read_ + bytes > limits_.bytes)
    fail(where, "reading '" + name + "' (" + std::to_string(bytes) +
                    " bytes) would make more than " + std::to_string(limits_.bytes) +
                    " bytes read (the import limit bytes)");
  ++files_read_;
  bytes_read_ += bytes;
}

void SceneFiles::fail(const std::string& where, const std::string& what) const {
  throw SceneError(scene_path_ + ": " + where + ": " + what);
}

std::string SceneFiles::name(const std::string& file, const std::string& where) const {
  if (file.empty()) fail(where, "must not be empty");
  if (file.find('\0') != std::string::npos) fail(where, "a file name must not contain NUL");
  if (file.find('\\') != std::string::npos) fail(where, "use '/' as the path separator");
  fs::path path(file);
  if (path.is_absolute() || file.front() == '/')
    fail(where, "absolute path '" + file + "' not allowed (asset paths are relative to the " +
                    "scene file's directory)");
  for (const fs::path& part : path)
    if (part == "..")
      fail(where, "'..' not allowed in asset path '" + file + "' (assets must lie in the " +
                      "scene file's directory or below it)");
  return path.lexically_normal().generic_string();
}

std::string SceneFiles::path_of(const std::string& name) const {
  return (fs::path(root_) / name).string();
}

std::string SceneFiles::add(const std::string& file, const std::string& where,
                            const std::string& noun) {
  return register_file(file, where, noun, nullptr);
}

std::string SceneFiles::read(const std::string& file, const std::string& where) {
  std::string bytes;
  register_file(file, where, "file", &bytes);
  return bytes;
}

const MeshData& SceneFiles::mesh(const std::string& file, const std::string& type,
                                 const std::string& where) {
  std::string n = name(file, where);
  if (auto it = meshes_.find(n); it != meshes_.end()) return it->second;
  std::string bytes;
  register_file(file, where, "mesh file", &bytes);
  std::string kind = type.empty() ? fs::path(n).extension().string() : "." + type;
  try {
    if (kind == ".obj") return meshes_[n] = parse_obj(bytes, n);
    if (kind == ".ply") return meshes_[n] = parse_ply(bytes, n);
  } catch (const SceneError& e) {
    fail(where, e.what());
  }
  fail(where, "'" + n + "': unknown mesh format (expected .obj or .ply)");
}

std::string SceneFiles::register_file(const std::string& file, const std::string& where,
                                      const std::string& noun, std::string* bytes_out) {
  std::string n = name(file, where);
  bool known = digests_.count(n) > 0;
  if (known && !bytes_out) return n;
  fs::path full = fs::path(root_) / n;
  std::error_code ec;
  if (!fs::is_regular_file(full, ec))
    fail(where, noun + " '" + n + "' not found (looked for " + full.string() + ")");
  if (!inside(root_.empty() ? fs::path(".") : fs::path(root_), full))
    fail(where, "'" + n + "' leads outside the scene file's directory (a symbolic link?)");
  uintmax_t size = fs::file_size(full, ec);
  count_read(where, n, ec ? 0 : uint64_t(size));
  std::string bytes;
  try {
    bytes = read_file_bytes(full.string());
  } catch (const std::exception& e) {
    fail(where, e.what());
  }
  if (!known) {
    digests_[n] = sha256_hex(bytes);
    names_.push_back(n);
  }
  if (bytes_out) *bytes_out = std::move(bytes);
  return n;
}

void SceneFiles::finish(Scene& scene, std::string_view main_bytes) const {
  Sha256 h;
  h.update(main_bytes);
  for (const std::string& a : names_) {
    h.update(std::string_view("\0", 1));
    h.update(a);
    h.update(std::string_view("\0", 1));
    h.update(digests_.at(a));
  }
  scene.assets = names_;
  scene.digest = h.hex_digest();
}

std::string read_scene_file(const std::string& path) {
  try {
    return read_file_bytes(path);
  } catch (const std::exception& e) {
    throw SceneError(path + ": cannot read scene file (" + e.what() + ")");
  }
}

}  // namespace rf
