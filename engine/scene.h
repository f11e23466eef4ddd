// The scene as plain data (yocto-gl style): arrays of materials, meshes and lights addressed by
// index, all geometry in world space after parsing. Trivially hashed and shipped to workers.
#pragma once

#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/animated_transform.h"
#include "engine/aov.h"
#include "engine/frame.h"
#include "engine/import_limits.h"
#include "engine/integrators/registry.h"
#include "engine/math.h"
#include "engine/scene_error.h"
#include "engine/shapes.h"

namespace rf {

// A material parameter: a constant, or (texture >= 0) a lookup in Scene::textures at the hit's uv.
struct ColorParam {
  RGB value{0.5f};
  int32_t texture = -1;
};
struct FloatParam {
  float value = 0;
  int32_t texture = -1;  // the texture's luminance (or its single channel)
};

enum class TextureType : uint8_t { Constant, Checkerboard, Image };

struct Texture {
  std::string name;
  TextureType type = TextureType::Constant;
  RGB value{0.5f};               // constant
  RGB color_a{0.0f}, color_b{1.0f};  // checkerboard: a where floor(u*scale)+floor(v*scale) is even
  Vec2 uv_scale{1.0f, 1.0f};     // uv multiplied by this before lookup (all kinds)
  Vec2 uv_offset{0.0f, 0.0f};
  std::string file;              // image: asset path relative to the scene file
  std::string resolved_path;     // image: path to open (scene dir + file)
  bool is_data = false;          // image: true = linear values (roughness maps); false = colour,
                                 // 8-bit images sRGB-decoded
  // Post-lookup remapping (all kinds; the defaults change nothing), used by glTF's factor x
  // texture products and its packed metallic-roughness maps (engine/texture.h states the order):
  RGB scale{1.0f};               // multiplies the looked-up RGB, channel by channel
  int8_t channel = -1;           // FloatParam: read channel 0..3 (R, G, B, A); -1 = single
                                 // channel or luminance
  bool squared = false;          // FloatParam: the scalar is squared last (perceptual roughness
                                 // -> GGX alpha)
};

enum class MaterialType : uint8_t {
  Diffuse,          // Lambertian
  Conductor,        // smooth conductor (mirror)
  Dielectric,       // smooth dielectric (glass)
  ThinDielectric,   // thin dielectric sheet (window pane)
  RoughConductor,   // GGX microfacet conductor
  RoughDielectric,  // GGX microfacet dielectric
  Plastic,          // coated diffuse: dielectric coating (smooth or GGX) over a diffuse base
};

// Every material kind reads the fields it needs (docs/scene-format.md lists which).
struct Material {
  std::string name;
  MaterialType type = MaterialType::Diffuse;
  ColorParam reflectance;           // diffuse albedo (diffuse, plastic base)
  ColorParam specular{RGB(1.0f)};   // specular tint (conductor tint mode, dielectrics, coating)
  FloatParam roughness{0.0f};       // GGX alpha (rough conductor/dielectric, plastic; 0 = smooth)
  float ior = 1.5f;                 // dielectrics and plastic coating: interior / exterior IOR
  RGB eta{0.143f, 0.374f, 1.442f};  // conductor complex IOR, real part per RGB (default: gold)
  RGB k{3.983f, 2.385f, 1.603f};    // conductor complex IOR, imaginary part per RGB
  bool conductor_tint = false;      // conductor: Schlick Fresnel with F0 = specular instead of eta/k
  bool separable_masking = false;   // rough conductor/dielectric: Smith G2 = G1 G1 (Mitsuba 3's
                                    // model) instead of height-correlated; set by the Mitsuba importer
};

// Emission on a shape makes it an area light. One-sided lights emit on the side the geometric
// normal points to (the winding's right-hand normal); two-sided ones on both.
struct Emission {
  RGB radiance{0.0f};
  bool two_sided = false;
};

// A deforming mesh's vertices at one time in seconds (Mesh::deform).
struct VertexKey {
  double time = 0;
  std::vector<Vec3> positions;  // world space, one per vertex of the mesh
  std::vector<Vec3> normals;    // the same, empty when the mesh has no normals
};

// A surface: triangles, or one exact sphere (then positions, normals, uvs and indices are empty
// and its only primitive is prim 0).
struct Mesh {
  std::string name;                // for messages: "shapes[3]" or the shape's "name"
  std::optional<SphereShape> sphere;
  std::vector<Vec3> positions;     // world space
  std::vector<Vec3> normals;       // world space per vertex, empty when flat shaded
  std::vector<Vec2> uvs;           // per vertex, may be empty
  std::vector<uint32_t> indices;   // 3 per triangle
  uint32_t material = 0;           // index into Scene::materials
  std::optional<Emission> emission;
  // A deforming mesh (JSON "deform", glTF skins and morph targets): its vertices at two or more
  // keys in increasing time, linear between keys and held before the first and after the last;
  // positions and normals above are the first key's. Empty for a mesh that keeps its shape. Only
  // world meshes deform (Scene::meshes), and only triangles.
  std::vector<VertexKey> deform;
  bool deforms() const { return deform.size() > 1; }
  size_t triangle_count() const { return indices.size() / 3; }
  // Triangles, or 1 for a sphere.
  size_t primitive_count() const { return sphere ? 1 : triangle_count(); }
};

struct Camera {
  Mat4 camera_to_world;    // camera space: +x right, +y up, looking down -z
  // A moving camera (JSON camera.keyframes): camera_to_world over time in seconds; not animated
  // for a still camera, whose transform is camera_to_world alone.
  AnimatedTransform motion;
  bool moves() const { return motion.animated(); }
  float fov_deg = 40.0f;   // field of view across the shorter image axis (as pbrt)
  float lens_radius = 0;   // thin lens aperture radius in scene units; 0 = pinhole
  float focus_distance = 1;  // distance along the view axis of the plane in focus
};

enum class FilterType : uint8_t { Box, Triangle, Gaussian };

struct FilterSettings {
  FilterType type = FilterType::Box;
  float radius = 0.5f;  // in pixels; box of radius 0.5 is exactly the pixel
  float sigma = 0.5f;   // gaussian standard deviation in pixels (truncated at radius)
};

struct FilmSettings {
  int width = 256, height = 256;
  FilterSettings filter;
};

enum class LightType : uint8_t { Point, Spot, Directional };

// Lights that are not shapes. Area lights are emissions on shapes (Mesh::emission); the
// environment is Scene::environment.
struct Light {
  std::string name;
  LightType type = LightType::Point;
  Vec3 position{0.0f};           // point, spot
  Vec3 direction{0, -1, 0};      // spot axis / direction light travels (directional), unit
  RGB intensity{1.0f};           // point, spot: W/sr (radiant intensity)
  RGB irradiance{1.0f};          // directional: W/m^2 on a surface facing it
  float cone_angle_deg = 30;     // spot: full cutoff half-angle
  float falloff_start_deg = 20;  // spot: smoothstep falloff from here to the cutoff
};

// Lat-long (equirectangular) environment map at infinity. For a unit direction d in map space
// (to_world maps it to the world): u = 0.5 + atan2(d.x, -d.z) / 2pi, v = acos(d.y) / pi, so the
// image centre looks down -z, the top row is +y, and u grows towards +x.
struct Environment {
  std::string file;             // asset path relative to the scene file ("" = constant)
  std::string resolved_path;
  RGB scale{1.0f};              // multiplies the map (or is the constant radiance)
  Mat4 to_world;                // rotation of the map
};

// A shot's time (docs/scene-format.md "time"). Frame F starts at F / fps seconds; a camera sample
// of frame F is taken at a time in the shutter interval [F + open, F + close] frames, uniform in
// it (a box shutter). Only a scene with motion reads it.
// The shutter's open and close, in frames, lie within this of the frame's start.
inline constexpr double kMaxShutterFrames = 1e6;
struct ShotTime {
  double fps = 24;
  double shutter_open = 0, shutter_close = 0.5;  // in frames, relative to the frame's start
  // The time in seconds of frame `frame` at shutter position u in [0, 1].
  double at(FrameNumber frame, float u) const {
    return (double(frame) + shutter_open + double(u) * (shutter_close - shutter_open)) / fps;
  }
};

// The integrator and its settings: max depth and Russian roulette are common to all (DESIGN.md
// "Max depth"); `method` is the integrator itself with its own parameters
// (engine/integrators/registry.h lists them).
struct IntegratorSettings {
  int max_depth = 5;      // scattering events (DESIGN.md "Max depth", pbrt-v4's meaning)
  int rr_min_depth = 3;   // Russian roulette starts after this many bounces
  Integrator method = PathIntegrator{};

  std::string type() const { return integrator_name(method); }  // "path", "bdpt", ...
  template <class T>
  T& as() { return std::get<T>(method); }  // throws std::bad_variant_access for another type
  template <class T>
  const T& as() const { return std::get<T>(method); }
};

struct RenderSettings {
  IntegratorSettings integrator;
  uint64_t spp = 64;          // total samples per pixel over all passes
  uint32_t passes = 16;       // spp must be a multiple of passes
  uint64_t seed = 0;
  double noise_target = 0;    // relMSE to stop at; 0 = render all passes
  std::string sampler = "sobol";  // or "independent"; sobol: Owen-scrambled, scrambled per pass
  // Light selection for next-event estimation (lights/light_selection.h): "power", "bvh" (a light
  // BVH that sees the shading point), or "auto" (the BVH when more than
  // LightSelection::kAutoBvhLights lights have a position).
  std::string light_selection = "auto";
  AovSet aovs;                // auxiliary outputs (engine/aov.h, docs/outputs.md)
  uint64_t spp_per_pass() const { return spp / passes; }
};

// Instancing (pbrt's ObjectBegin/ObjectInstance, glTF meshes placed by several nodes): an object
// is a group of meshes in its own space, placed any number of times by instances.
struct SceneObject {
  std::string name;
  std::vector<Mesh> meshes;  // object space
};
// A moving instance (JSON keyframes, glTF animations, pbrt's two transforms) has its
// object-to-world transform over time in seconds in `motion`; to_world is then motion's first key.
struct Instance {
  Instance() = default;
  Instance(uint32_t object_, const Mat4& to_world_) : object(object_), to_world(to_world_) {}
  uint32_t object = 0;  // index into Scene::objects
  Mat4 to_world;
  AnimatedTransform motion;  // not animated for an instance that does not move
  bool moves() const { return motion.animated(); }
};

struct Scene {
  std::string path;                 // the scene file as given
  std::string digest;               // SHA-256 (hex) of the scene file and every asset it uses
  std::vector<std::string> assets;  // asset paths relative to the scene file's directory
  Camera camera;
  FilmSettings film;
  RenderSettings render;
  ShotTime time;
  std::vector<Material> materials;
  std::vector<Texture> textures;
  std::vector<Mesh> meshes;
  std::vector<Light> lights;
  std::optional<Environment> environment;
  std::vector<SceneObject> objects;  // instanced geometry
  std::vector<Instance> instances;
  // What the importer ignored or approximated, each naming the file, line or path and the
  // directive (also logged as warnings when the scene is loaded).
  std::vector<std::string> warnings;
};

// Whether some geometry moves (an instance with an animated transform, a deforming mesh): its BVH
// is then one per frame (Accel). And whether anything moves: that, or the camera.
bool geometry_moves(const Scene& scene);
bool scene_moves(const Scene& scene);

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
  std::optional<std::string> sampler;
  std::optional<std::string> aovs;  // comma-separated AOV names, "" for none
  std::optional<std::string> light_selection;  // auto, power, bvh
  // --shutter: "OPEN,CLOSE" in frames, or one number for an instant (0: the frame's start).
  std::optional<std::string> shutter;
  bool operator==(const SceneOverrides&) const = default;
};

// Reads a scene file and every file it references, applies the overrides and validates the
// result; the format is the file's extension: .json (docs/scene-format.md), .pbrt (pbrt-v4),
// .xml (Mitsuba 3), .gltf and .glb (glTF 2.0). Throws SceneError before any rendering can start.
// The importers are in engine/formats/ (one folder per format); nothing else knows the formats.
// The import's work is bounded by `limits` (files and bytes read, elements).
Scene load_scene(const std::string& path, const SceneOverrides& overrides = {},
                 const ImportLimits& limits = {});

// Applies and validates overrides on an already loaded scene (throws SceneError naming the flag).
void apply_overrides(Scene& scene, const SceneOverrides& overrides);
// The checks of apply_overrides that need no scene (names, ranges, spp a multiple of passes when
// both are given): the command line runs them before it reads a scene, so a bad flag is a usage
// error. Throws SceneError naming the flag.
void check_overrides(const SceneOverrides& overrides);

// Prepares instancing for rendering (load_scene calls it after the importer): checks every
// instance (object index, finite invertible transform) and moves lights out of objects: each
// instance of an object with an emissive mesh gets a world-space copy of that mesh in
// Scene::meshes, because area lights are sampled per world-space triangle (lights/light_set.h).
// Everything else stays instanced: the accelerator (accel.h) places one copy of each object's
// geometry with Embree instances, however many times it is placed. Objects placed by no instance
// are dropped from rendering (they cost nothing); throws SceneError naming the instance. The
// scene's elements and the triangles those copies add may be at most `max_elements`
// (ImportLimits::elements).
void prepare_instances(Scene& scene, uint64_t max_elements = ImportLimits{}.elements);
// The scene's shapes, objects, instances, lights, materials and textures (what ImportLimits::
// elements counts before instanced emitters are copied).
uint64_t scene_elements(const Scene& scene);

// Expands every instance into world-space copies of its object's meshes (Scene::meshes) and
// clears objects and instances: the flattened equivalent of an instanced scene (tests compare
// the two).
void flatten_instances(Scene& scene);

// World-space axis-aligned bounds of the meshes and of every instance's object (the object's
// box transformed); lo > hi when the scene has no geometry.
void scene_bounds(const Scene& scene, Vec3& lo, Vec3& hi);
// Grows [lo, hi] by a mesh's bounds (its triangles' vertices, every key's for a deforming mesh,
// or its sphere's box).
void mesh_bounds(const Mesh& m, Vec3& lo, Vec3& hi);
// A deforming mesh's vertices at `time` (seconds): each key's exactly at its time, linear between
// keys ((1 - f) a + f b in float), held past the ends. normals is left empty when the mesh has
// none; the interpolated normals are not normalised.
void deformed_vertices(const Mesh& m, double time, std::vector<Vec3>& positions,
                       std::vector<Vec3>& normals);

// Names and defaults every format maps onto.
// A film's width and height: every pixel index fits a signed 32-bit int (2^30 pixels), and a raster
// position keeps 9 bits below the pixel. Frames beyond memory are kept in tiles on disk
// (FrameAccumulator, ProgressiveOptions::memory_budget), at 104 bytes a pixel.
inline constexpr int kMaxResolution = 32768;
// Splatting integrators (light, bdpt) carry a whole-frame splat plane in every task.
inline constexpr uint64_t kMaxSplatPixels = uint64_t(4096) * 4096;
const std::vector<std::string>& known_filters();   // box, triangle, gaussian
FilterType filter_type(const std::string& name);    // one of known_filters()
float default_filter_radius(FilterType type);       // box 0.5, triangle 1, gaussian 1.5 pixels
const std::vector<std::string>& known_samplers();  // independent, sobol
uint32_t default_passes(uint64_t spp);  // gcd(spp, 16), halved down to 4 for >= 64 spp per pass

// Conductors by name: complex IOR (eta, k) averaged over the R, G, B bands of measured data.
struct ConductorPreset {
  const char* name;  // gold, silver, copper, aluminium
  RGB eta, k;
};
const std::vector<ConductorPreset>& conductor_presets();
const ConductorPreset* conductor_preset(const std::string& name);  // nullptr if unknown


}  // namespace rf
