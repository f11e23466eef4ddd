// The scene as plain data (yocto-gl style): arrays of materials, meshes and lights addressed by
// index, all geometry in world space after parsing. Trivially hashed and shipped to workers.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/math.h"

namespace rf {

// Thrown for any bad scene input. The message names the file, the JSON path (or line) and what
// was expected, e.g. "scene.json: shapes[3].material: unknown material 'flor'".
struct SceneError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

enum class MaterialType : uint8_t { Diffuse };

struct Material {
  std::string name;
  MaterialType type = MaterialType::Diffuse;
  RGB reflectance{0.5f};  // diffuse albedo
};

// Emission on a shape makes it an area light. One-sided lights emit on the side the geometric
// normal points to (the winding's right-hand normal); two-sided ones on both.
struct Emission {
  RGB radiance{0.0f};
  bool two_sided = false;
};

struct Mesh {
  std::string name;                // for messages: "shapes[3]" or the shape's "name"
  std::vector<Vec3> positions;     // world space
  std::vector<Vec3> normals;       // world space per vertex, empty when flat shaded
  std::vector<Vec2> uvs;           // per vertex, may be empty
  std::vector<uint32_t> indices;   // 3 per triangle
  uint32_t material = 0;           // index into Scene::materials
  std::optional<Emission> emission;
  size_t triangle_count() const { return indices.size() / 3; }
};

struct Camera {
  Mat4 camera_to_world;   // camera space: +x right, +y up, looking down -z
  float fov_deg = 40.0f;  // field of view across the shorter image axis (as pbrt)
};

enum class FilterType : uint8_t { Box };

struct FilterSettings {
  FilterType type = FilterType::Box;
  float radius = 0.5f;  // in pixels; box of radius 0.5 is exactly the pixel
};

struct FilmSettings {
  int width = 256, height = 256;
  FilterSettings filter;
};

struct IntegratorSettings {
  std::string type = "path";
  int max_depth = 5;      // scattering events (DESIGN.md "Max depth", pbrt-v4's meaning)
  int rr_min_depth = 3;   // Russian roulette starts after this many bounces
};

struct RenderSettings {
  IntegratorSettings integrator;
  uint64_t spp = 64;          // total samples per pixel over all passes
  uint32_t passes = 16;       // spp must be a multiple of passes
  uint64_t seed = 0;
  uint32_t frame = 0;
  double noise_target = 0;    // relMSE to stop at; 0 = render all passes
  uint64_t spp_per_pass() const { return spp / passes; }
};

struct Scene {
  std::string path;                 // the scene file as given
  std::string digest;               // SHA-256 (hex) of the scene file and every asset it uses
  std::vector<std::string> assets;  // asset paths relative to the scene file's directory
  Camera camera;
  FilmSettings film;
  RenderSettings render;
  std::vector<Material> materials;
  std::vector<Mesh> meshes;
};

// Command-line overrides of the scene's settings; each is validated like the scene's own value.
struct SceneOverrides {
  std::optional<uint64_t> spp;
  std::optional<uint32_t> passes;
  std::optional<std::string> integrator;
  std::optional<uint64_t> seed;
  std::optional<int> width, height;
  std::optional<int> max_depth;
  std::optional<std::string> filter;
  std::optional<double> noise_target;
  std::optional<uint32_t> frame;
};

// Reads a scene file (JSON, docs/scene-format.md) and every mesh it references, applies the
// overrides and validates the result. Throws SceneError before any rendering can start.
Scene load_scene(const std::string& path, const SceneOverrides& overrides = {});

// Applies and validates overrides on an already loaded scene (throws SceneError naming the flag).
void apply_overrides(Scene& scene, const SceneOverrides& overrides);

// The names accepted for "integrator.type" and --integrator.
const std::vector<std::string>& known_integrators();

}  // namespace rf
