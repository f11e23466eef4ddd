// Helpers shared by tests: paths to the source tree and the CLI binary, temporary directories,
// running the CLI and capturing its output.
#pragma once

#include <map>
#include <string>

// Built with AddressSanitizer (gcc defines __SANITIZE_ADDRESS__, clang has the feature): tests
// that bound a process's resident memory skip, since ASan's shadow memory and quarantine inflate
// it. test_support.cpp then also sets ASan's defaults for every test binary.
#if defined(__SANITIZE_ADDRESS__)
#define RAYFARM_TEST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define RAYFARM_TEST_ASAN 1
#endif
#endif

namespace rf::test {

// RFC 4648 base64 of bytes (data: URIs of test glTF files).
std::string base64(const std::string& in);

#ifdef RAYFARM_TEST_ASAN
inline constexpr bool kAddressSanitizer = true;
#else
inline constexpr bool kAddressSanitizer = false;
#endif

std::string source_dir();                  // the repository root
std::string rayfarm_binary();              // the built CLI
std::string make_temp_dir(const std::string& tag);  // fresh directory under the build tree's tmp

struct CommandResult {
  int exit_code = -1;
  std::string output;  // stdout and stderr together
};
// Runs a shell command line, capturing stdout+stderr.
CommandResult run_command(const std::string& command_line);

// Writes text to a file (creating parent directories).
void write_text(const std::string& path, const std::string& text);

}  // namespace rf::test

#include "engine/scene.h"

namespace rf::test {

// Writes `text` as `file_name` (its extension picks the format) in a fresh directory and loads it
// with load_scene; and the SceneError message that loading it gives, or "(loaded)".
// `files`: other files written beside it (name -> contents), which the scene may reference.
Scene load_scene_text(const std::string& file_name, const std::string& text,
                      const SceneOverrides& overrides = {},
                      const std::map<std::string, std::string>& files = {});
std::string scene_text_error(const std::string& file_name, const std::string& text,
                             const SceneOverrides& overrides = {},
                             const std::map<std::string, std::string>& files = {});

// The scene format's closed UV sphere (engine/shapes.h), flat shaded (no vertex normals, no uvs):
// outward right-hand winding, 2*n_theta*n_phi - 2*n_phi triangles.
Mesh make_uv_sphere(Vec3 center, float radius, int n_theta, int n_phi, uint32_t material);

// The parallelogram origin, origin + e1, origin + e1 + e2, origin + e2 as two triangles; its
// right-hand normal is cross(e1, e2).
Mesh make_quad(Vec3 origin, Vec3 e1, Vec3 e2, uint32_t material);

// A minimal valid scene around the given meshes: pinhole camera at eye looking at target,
// resolution w x h, path tracer, box filter. The digest is set from `tag`.
Scene make_scene(std::vector<Material> materials, std::vector<Mesh> meshes, Vec3 eye,
                 Vec3 target, int w, int h, const std::string& tag);

}  // namespace rf::test
