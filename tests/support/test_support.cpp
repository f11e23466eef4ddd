#include "tests/support/test_support.h"

#include <cmath>

#include <sys/wait.h>

#include <array>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include <unistd.h>

#include "engine/shapes.h"

#ifdef RAYFARM_TEST_ASAN
// OpenImageIO 2.4's TextureSystem::destroy deletes its object through a mismatched type, which
// AddressSanitizer reports inside the library; the rest stays checked. (tests/sanitize.sh sets
// the same in ASAN_OPTIONS for the processes the tests start.)
extern "C" const char* __asan_default_options() { return "new_delete_type_mismatch=0"; }
#endif

namespace rf::test {

Scene load_scene_text(const std::string& file_name, const std::string& text,
                      const SceneOverrides& overrides,
                      const std::map<std::string, std::string>& files) {
  const std::string dir = make_temp_dir("scene-text");
  write_text(dir + "/" + file_name, text);
  for (const auto& [name, contents] : files) write_text(dir + "/" + name, contents);
  return load_scene(dir + "/" + file_name, overrides);
}

std::string scene_text_error(const std::string& file_name, const std::string& text,
                             const SceneOverrides& overrides,
                             const std::map<std::string, std::string>& files) {
  try {
    load_scene_text(file_name, text, overrides, files);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "(loaded)";
}

std::string base64(const std::string& in) {
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  for (size_t i = 0; i < in.size(); i += 3) {
    uint32_t v = uint32_t(uint8_t(in[i])) << 16;
    if (i + 1 < in.size()) v |= uint32_t(uint8_t(in[i + 1])) << 8;
    if (i + 2 < in.size()) v |= uint32_t(uint8_t(in[i + 2]));
    out += k[v >> 18 & 63];
    out += k[v >> 12 & 63];
    out += i + 1 < in.size() ? k[v >> 6 & 63] : '=';
    out += i + 2 < in.size() ? k[v & 63] : '=';
  }
  return out;
}

std::string source_dir() { return RAYFARM_SOURCE_DIR; }
std::string rayfarm_binary() { return RAYFARM_BINARY; }

std::string make_temp_dir(const std::string& tag) {
  static std::atomic<int> counter{0};
  auto base = std::filesystem::temp_directory_path() / "rayfarm-tests";
  auto dir = base / (tag + "-" + std::to_string(::getpid()) + "-" + std::to_string(counter++));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir.string();
}

CommandResult run_command(const std::string& command_line) {
  CommandResult r;
  std::string cmd = command_line + " 2>&1";
  FILE* pipe = ::popen(cmd.c_str(), "r");
  if (!pipe) throw std::runtime_error("popen failed: " + command_line);
  std::array<char, 4096> buf;
  size_t n;
  while ((n = std::fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  int status = ::pclose(pipe);
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

void write_text(const std::string& path, const std::string& text) {
  auto p = std::filesystem::path(path);
  if (p.has_parent_path()) std::filesystem::create_directories(p.parent_path());
  std::ofstream out(path, std::ios::binary);
  out << text;
  if (!out) throw std::runtime_error("cannot write " + path);
}

}  // namespace rf::test

namespace rf::test {

Mesh make_uv_sphere(Vec3 c, float r, int n_theta, int n_phi, uint32_t material) {
  MeshData data = make_sphere(c, r, n_theta, n_phi);  // the scene format's sphere
  Mesh m;
  m.name = "sphere";
  m.material = material;
  m.positions = std::move(data.positions);
  m.indices = std::move(data.indices);  // flat shaded: no normals, no uvs
  return m;
}

Scene make_scene(std::vector<Material> materials, std::vector<Mesh> meshes, Vec3 eye, Vec3 target,
                 int w, int h, const std::string& tag) {
  Scene s;
  s.path = tag;
  s.digest = tag;
  s.camera.camera_to_world = Mat4::look_at(eye, target, {0, 1, 0});
  s.camera.fov_deg = 40;
  s.film.width = w;
  s.film.height = h;
  s.materials = std::move(materials);
  s.meshes = std::move(meshes);
  return s;
}

}  // namespace rf::test

namespace rf::test {

Mesh make_quad(Vec3 origin, Vec3 e1, Vec3 e2, uint32_t material) {
  Mesh m;
  m.name = "quad";
  m.material = material;
  m.positions = {origin, origin + e1, origin + e1 + e2, origin + e2};
  m.indices = {0, 1, 2, 0, 2, 3};
  return m;
}

}  // namespace rf::test
