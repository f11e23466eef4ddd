// The glTF 2.0 importer (engine/formats/gltf, docs/formats/gltf.md): node hierarchy and
// transforms, instancing, the camera's yfov, KHR_lights_punctual's photometric units, the
// material mapping, textures (data: URI, external, embedded in a .glb), primitive modes and
// sparse accessors, one test per kind of malformed file (message names the file, the JSON pointer
// and the problem), and a glTF Cornell box that renders the same image as scene.json.
// The inputs are in tests/data/gltf/ (written by generate.py there; expected values read off it).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "engine/digest.h"
#include "engine/formats/importers.h"
#include "engine/fresnel.h"
#include "engine/scene.h"
#include "engine/texture.h"
#include "tests/support/fixtures.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

using json = nlohmann::json;
namespace fs = std::filesystem;

constexpr float kDeg = 180.0f / kPi;

std::string data(const std::string& name) {
  return test::source_dir() + "/tests/data/gltf/" + name;
}

std::string read_bytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

json read_json(const std::string& path) { return json::parse(read_bytes(path)); }

// Extracted images go to a private cache for the whole test binary.
class GltfEnvironment : public ::testing::Environment {
 public:
  void SetUp() override {
    dir_ = test::make_temp_dir("gltf-cache");
    ::setenv("XDG_CACHE_HOME", dir_.c_str(), 1);
  }
  std::string dir_;
};
GltfEnvironment* const env =
    static_cast<GltfEnvironment*>(::testing::AddGlobalTestEnvironment(new GltfEnvironment));

bool has_warning(const Scene& s, const std::string& pointer, const std::string& text) {
  for (const std::string& w : s.warnings)
    if (w.find(": " + pointer + ": ") != std::string::npos && w.find(text) != std::string::npos)
      return true;
  return false;
}

std::string all_warnings(const Scene& s) {
  std::string out;
  for (const std::string& w : s.warnings) out += w + "\n";
  return out;
}

void expect_vec(Vec3 got, Vec3 want, float tol, const std::string& what) {
  EXPECT_NEAR(got.x, want.x, tol) << what;
  EXPECT_NEAR(got.y, want.y, tol) << what;
  EXPECT_NEAR(got.z, want.z, tol) << what;
}

// Tolerance of transforms: single-precision products of a few terms of magnitude <= 7.
constexpr float kGeomTol = 1e-5f;

TEST(GltfTest, HierarchyTrsMatrixAndInstancing) {
  Scene s = import_scene(data("hierarchy.gltf"));
  // Mesh 0 is placed by two nodes: one object, two instances (in node order).
  ASSERT_EQ(s.objects.size(), 1u);
  ASSERT_EQ(s.instances.size(), 2u);
  EXPECT_TRUE(s.meshes.empty());
  const Mesh& m = s.objects[0].meshes.at(0);
  ASSERT_EQ(m.positions.size(), 4u);
  // root translate (0,0,-5) * trs (rotate 90 about y, scale 2): (1,-1,0) -> (0,-2,-7).
  expect_vec(s.instances[0].to_world.point(m.positions[1]), Vec3(0, -2, -7), kGeomTol, "trs");
  // root * matrix (translate 3,0,0, column-major): (1,-1,0) -> (4,-1,-5).
  expect_vec(s.instances[1].to_world.point(m.positions[1]), Vec3(4, -1, -5), kGeomTol, "matrix");
  // Normals and uvs: glTF's v runs down, the engine's up: glTF (0,1) -> (0,0).
  expect_vec(m.normals[0], Vec3(0, 0, 1), kGeomTol, "normal");
  EXPECT_FLOAT_EQ(m.uvs[0].x, 0);
  EXPECT_FLOAT_EQ(m.uvs[0].y, 0);
  EXPECT_FLOAT_EQ(m.uvs[2].y, 1);
  EXPECT_EQ(s.materials[m.material].type, MaterialType::Diffuse);
  // Camera: node 3, translate (0,1,0), rotate 90 about y: looks down -x; yfov 0.5 rad on a
  // landscape film (aspectRatio 1.5 -> 512 x 341) is the fov of the shorter (vertical) axis.
  EXPECT_EQ(s.film.width, 512);
  EXPECT_EQ(s.film.height, 341);
  EXPECT_NEAR(s.camera.fov_deg, 0.5f * kDeg, 1e-4f);
  expect_vec(s.camera.camera_to_world.point(Vec3(0.0f)), Vec3(0, 1, 0), kGeomTol, "eye");
  expect_vec(s.camera.camera_to_world.vector(Vec3(0, 0, -1)), Vec3(-1, 0, 0), kGeomTol, "view");
  EXPECT_TRUE(has_warning(s, "/nodes", "1 other camera node(s) ignored")) << all_warnings(s);
  // Defaults glTF does not carry (docs/formats/gltf.md).
  EXPECT_EQ(s.render.integrator.max_depth, 8);
  EXPECT_EQ(s.render.spp, 64u);
  EXPECT_EQ(s.render.integrator.type(), "path");
  // No light at all: a uniform white environment of radiance 1, with a warning.
  ASSERT_TRUE(s.environment.has_value());
  EXPECT_TRUE(s.environment->file.empty());
  expect_vec(s.environment->scale, Vec3(1, 1, 1), 0, "environment");
  EXPECT_TRUE(has_warning(s, "/", "the scene has no lights")) << all_warnings(s);
}

TEST(GltfTest, PortraitYfovBecomesTheHorizontalFov) {
  std::string dir = test::make_temp_dir("gltf");
  json j = read_json(data("hierarchy.gltf"));
  j["cameras"][0]["perspective"]["aspectRatio"] = 0.5;
  test::write_text(dir + "/portrait.gltf", j.dump());
  Scene s = import_scene(dir + "/portrait.gltf");
  EXPECT_EQ(s.film.width, 256);
  EXPECT_EQ(s.film.height, 512);
  // The shorter axis is now horizontal: 2 atan(tan(yfov / 2) * 256 / 512).
  EXPECT_NEAR(s.camera.fov_deg, 2 * std::atan(std::tan(0.25) * 0.5) * kDeg, 1e-4f);
  // load_scene keeps the instances (Embree instances) and applies overrides (the fov stays on
  // the shorter axis).
  SceneOverrides ov;
  ov.width = 32, ov.height = 64;
  Scene f = load_scene(dir + "/portrait.gltf", ov);
  EXPECT_EQ(f.instances.size(), 2u);
  flatten_instances(f);
  EXPECT_EQ(f.meshes.size(), 2u);
  EXPECT_EQ(f.film.width, 32);
  EXPECT_NEAR(f.camera.fov_deg, s.camera.fov_deg, 1e-6f);
}

TEST(GltfTest, PunctualLightsInRadiometricUnits) {
  Scene s = import_scene(data("lights.gltf"));
  ASSERT_EQ(s.lights.size(), 3u);
  // Point: colour (1, .5, .25) x 4*683 cd / 683 lm/W = (4, 2, 1) W/sr at the node's position.
  const Light& p = s.lights[0];
  EXPECT_EQ(p.type, LightType::Point);
  expect_vec(p.position, Vec3(1, 2, 3), kGeomTol, "point position");
  expect_vec(p.intensity, Vec3(4, 2, 1), 1e-5f, "point W/sr");
  // Spot: 683 cd -> 1 W/sr; the node turns -z down to -y; cone angles in degrees.
  const Light& sp = s.lights[1];
  EXPECT_EQ(sp.type, LightType::Spot);
  expect_vec(sp.position, Vec3(0, 5, 0), kGeomTol, "spot position");
  expect_vec(sp.direction, Vec3(0, -1, 0), kGeomTol, "spot direction");
  expect_vec(sp.intensity, Vec3(1, 1, 1), 1e-6f, "spot W/sr");
  EXPECT_NEAR(sp.cone_angle_deg, 0.6f * kDeg, 1e-4f);
  EXPECT_NEAR(sp.falloff_start_deg, 0.2f * kDeg, 1e-4f);
  // Directional: 1366 lux -> 2 W/m^2, travelling down the node's -z.
  const Light& d = s.lights[2];
  EXPECT_EQ(d.type, LightType::Directional);
  expect_vec(d.direction, Vec3(0, 0, -1), kGeomTol, "sun direction");
  expect_vec(d.irradiance, Vec3(2, 2, 2), 1e-5f, "sun W/m^2");
  EXPECT_TRUE(has_warning(s, "/extensions/KHR_lights_punctual/lights/1/range", "ignored"))
      << all_warnings(s);
  // No camera: a documented default frames the bounds, with a warning.
  EXPECT_TRUE(has_warning(s, "/cameras", "no camera")) << all_warnings(s);
}

TEST(GltfTest, MaterialMapping) {
  Scene s = import_scene(data("materials.gltf"));
  ASSERT_EQ(s.meshes.size(), 10u);  // one per glTF mesh, in mesh order
  auto mat = [&](size_t mesh) -> const Material& {
    return s.materials.at(s.meshes[mesh].material);
  };
  // metal: rough conductor, Schlick F0 = base colour, alpha = roughness^2.
  EXPECT_EQ(mat(0).type, MaterialType::RoughConductor);
  EXPECT_TRUE(mat(0).conductor_tint);
  expect_vec(mat(0).specular.value, Vec3(0.9f, 0.6f, 0.3f), 1e-6f, "metal F0");
  EXPECT_FLOAT_EQ(mat(0).roughness.value, 0.25f);
  // dielectric: plastic, IOR 1.5, its base R compensated for the coat so that the diffuse albedo
  // (1 - F) R (1 - F_dr) / (1 - R F_dr) (engine/bsdfs/plastic.h) is glTF's (1 - F) baseColor.
  EXPECT_EQ(mat(1).type, MaterialType::Plastic);
  const float fdr = fresnel_diffuse_reflectance_interior(1.5f);
  const RGB base(0.2f, 0.4f, 0.6f), r = mat(1).reflectance.value;
  for (int k = 0; k < 3; ++k) {
    EXPECT_GT(r[k], base[k]);
    EXPECT_NEAR(r[k] * (1 - fdr) / (1 - r[k] * fdr), base[k], 1e-6f) << "channel " << k;
  }
  EXPECT_FLOAT_EQ(mat(1).roughness.value, 0.25f);
  EXPECT_FLOAT_EQ(mat(1).ior, 1.5f);
  // roughness 1 (the default) and specularFactor 0: Lambertian.
  EXPECT_EQ(mat(2).type, MaterialType::Diffuse);
  expect_vec(mat(2).reflectance.value, Vec3(0.8f, 0.7f, 0.6f), 1e-6f, "diffuse");
  EXPECT_EQ(mat(3).type, MaterialType::Diffuse);
  // transmission without a volume: thin-walled; with KHR_materials_volume: a rough solid.
  EXPECT_EQ(mat(4).type, MaterialType::ThinDielectric);
  EXPECT_FLOAT_EQ(mat(4).ior, 1.4f);
  EXPECT_EQ(mat(5).type, MaterialType::RoughDielectric);
  EXPECT_FLOAT_EQ(mat(5).roughness.value, 0.04f);
  // emissive (1, .5, .25) x emissiveStrength 8, doubleSided: a two-sided area light.
  ASSERT_TRUE(s.meshes[6].emission.has_value());
  expect_vec(s.meshes[6].emission->radiance, Vec3(8, 4, 2), 1e-6f, "emission");
  EXPECT_TRUE(s.meshes[6].emission->two_sided);
  EXPECT_FALSE(s.meshes[0].emission.has_value());
  // metallic 0.3: a dielectric, with a warning that says so.
  EXPECT_EQ(mat(7).type, MaterialType::Plastic);
  EXPECT_TRUE(has_warning(s, "/materials/7/pbrMetallicRoughness/metallicFactor", "not blended"));
  EXPECT_TRUE(has_warning(s, "/materials/8/alphaMode", "BLEND is not supported"));
  EXPECT_TRUE(has_warning(s, "/materials/8/extensions/KHR_materials_clearcoat", "not supported"));
  EXPECT_TRUE(has_warning(s, "/extensionsUsed/5", "KHR_materials_clearcoat"));
  // No material: glTF's default (base colour 1, metallic 1, roughness 1).
  EXPECT_EQ(mat(9).type, MaterialType::RoughConductor);
  EXPECT_FLOAT_EQ(mat(9).roughness.value, 1.0f);
  EXPECT_TRUE(has_warning(s, "/cameras", "no camera"));
  EXPECT_FALSE(s.environment.has_value());  // the lamp lights it
  EXPECT_EQ(s.warnings.size(), 5u) << all_warnings(s);
}

// The texture of textured.gltf (checker.png), texel values decoded from sRGB.
void expect_textured(const Scene& s) {
  ASSERT_EQ(s.textures.size(), 2u);
  const Texture& base = s.textures[0];
  EXPECT_FALSE(base.is_data);
  expect_vec(base.scale, Vec3(0.5f, 1, 1), 0, "baseColorFactor");
  // KHR_texture_transform scale 2, offset (0.5, 0) in the engine's flipped v.
  EXPECT_FLOAT_EQ(base.uv_scale.x, 2);
  EXPECT_FLOAT_EQ(base.uv_offset.x, 0.5f);
  EXPECT_FLOAT_EQ(base.uv_offset.y, -1.0f);
  const Material& m = s.materials.at(s.meshes.at(0).material);
  EXPECT_EQ(m.type, MaterialType::RoughConductor);  // metallicFactor 1: F0 = the texture
  EXPECT_EQ(m.specular.texture, 0);
  TextureEvaluator ev(s);
  ColorParam b{RGB(0.0f), 0};
  // glTF uv -> uv' = 2 uv + (0.5, 0) -> texel; engine uv = (u, 1 - v). Texel centres, so the
  // bilinear lookup returns the texel: tolerance half-float storage (2^-11 relative).
  expect_vec(ev.eval(b, {0.125f, 0.875f}, 0), Vec3(0, 1, 0), 1e-3f, "texel (1,0) green");
  expect_vec(ev.eval(b, {-0.125f, 0.875f}, 0), Vec3(0.5f, 0, 0), 1e-3f, "texel (0,0) red x 0.5");
  expect_vec(ev.eval(b, {-0.125f, 0.625f}, 0), Vec3(0, 0, 1), 1e-3f, "texel (0,1) blue");
}

TEST(GltfTest, DataUriTexturesAndPackedRoughness) {
  Scene s = import_scene(data("textured.gltf"));
  expect_textured(s);
  const Texture& mr = s.textures[1];
  EXPECT_TRUE(mr.is_data);
  EXPECT_EQ(mr.channel, 1);  // roughness is green
  EXPECT_TRUE(mr.squared);   // alpha = (roughnessFactor * G)^2
  EXPECT_EQ(s.materials.at(s.meshes[0].material).roughness.texture, 1);
  // Extracted into the content-addressed cache.
  EXPECT_EQ(fs::path(mr.resolved_path).parent_path().string(), env->dir_ + "/rayfarm/gltf-images");
  TextureEvaluator ev(s);
  FloatParam r{0, 1};
  const float g00 = 64 / 255.0f, g11 = 255 / 255.0f;  // glTF texels (0,0) and (1,1)
  EXPECT_NEAR(ev.eval(r, {0.25f, 0.75f}, 0), (0.8f * g00) * (0.8f * g00), 1e-3f * 0.04f);
  EXPECT_NEAR(ev.eval(r, {0.75f, 0.25f}, 0), (0.8f * g11) * (0.8f * g11), 1e-3f * 0.64f);
  EXPECT_TRUE(has_warning(s, "/samplers/0", "the texture repeats")) << all_warnings(s);
  EXPECT_TRUE(has_warning(s, "/materials/0/pbrMetallicRoughness/metallicRoughnessTexture",
                          "cannot vary over a surface"));
  // As a dielectric (metallic 0) the textured base colour becomes a Lambertian, with a warning.
  std::string dir = test::make_temp_dir("gltf");
  json j = read_json(data("textured.gltf"));
  j["materials"][0]["pbrMetallicRoughness"]["metallicFactor"] = 0;
  test::write_text(dir + "/dielectric.gltf", j.dump());
  Scene d = import_scene(dir + "/dielectric.gltf");
  EXPECT_EQ(d.materials.at(d.meshes.at(0).material).type, MaterialType::Diffuse);
  EXPECT_EQ(d.materials.at(d.meshes.at(0).material).reflectance.texture, 0);
  EXPECT_TRUE(
      has_warning(d, "/materials/0/pbrMetallicRoughness/baseColorTexture", "rendered Lambertian"));
}

TEST(GltfTest, ExternalImageIsRegisteredForTheBundle) {
  Scene s = import_scene(data("textured_external.gltf"));
  ASSERT_EQ(s.textures.size(), 1u);
  EXPECT_EQ(s.textures[0].resolved_path, data("checker.png"));
  EXPECT_EQ(s.assets, std::vector<std::string>{"checker.png"});
  // The digest covers the image: a changed image changes it.
  std::string dir = test::make_temp_dir("gltf");
  fs::copy_file(data("textured_external.gltf"), dir + "/t.gltf");
  std::string png = read_bytes(data("checker.png"));
  test::write_text(dir + "/checker.png", png);
  std::string d1 = import_scene(dir + "/t.gltf").digest;
  png[png.size() - 20] ^= 1;
  test::write_text(dir + "/checker.png", png);
  EXPECT_NE(import_scene(dir + "/t.gltf").digest, d1);
}

// A .glb written here: textured.gltf's JSON with its geometry still in a data: URI buffer (1) and
// the base-colour PNG in the binary chunk (buffer 0), referenced by a bufferView.
std::string make_glb(const std::string& png) {
  json j = read_json(data("textured.gltf"));
  for (json& v : j["bufferViews"]) v["buffer"] = 1;
  j["buffers"].insert(j["buffers"].begin(), json{{"byteLength", png.size()}});
  j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", 0}, {"byteLength", png.size()}});
  j["images"][0] = {{"bufferView", j["bufferViews"].size() - 1}, {"mimeType", "image/png"}};
  std::string js = j.dump();
  js.append((4 - js.size() % 4) % 4, ' ');
  std::string bin = png;
  bin.append((4 - bin.size() % 4) % 4, '\0');
  auto u32 = [](uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); };
  std::string body = u32(uint32_t(js.size())) + u32(0x4E4F534A) + js + u32(uint32_t(bin.size())) +
                     u32(0x004E4942) + bin;
  return "glTF" + u32(2) + u32(uint32_t(12 + body.size())) + body;
}

TEST(GltfTest, GlbEmbeddedPngIsExtractedDeterministically) {
  std::string dir = test::make_temp_dir("gltf");
  std::string png = read_bytes(data("checker.png"));
  test::write_text(dir + "/textured.glb", make_glb(png));
  Scene s = import_scene(dir + "/textured.glb");
  std::string expected = env->dir_ + "/rayfarm/gltf-images/" + sha256_hex(png) + ".png";
  EXPECT_EQ(s.textures.at(0).resolved_path, expected);
  EXPECT_EQ(read_bytes(expected), png);
  expect_textured(s);
  // A second import (a farm worker's) names the same file.
  EXPECT_EQ(import_scene(dir + "/textured.glb").textures.at(0).resolved_path, expected);
  // Truncated by one byte: refused by the header check before any parsing.
  std::string glb = make_glb(png);
  test::write_text(dir + "/cut.glb", glb.substr(0, glb.size() - 1));
  std::string e = test::error_of([&] { import_scene(dir + "/cut.glb"); });
  EXPECT_NE(e.find("cut.glb: (GLB header): "), std::string::npos) << e;
  EXPECT_NE(e.find("(truncated)"), std::string::npos) << e;
}

TEST(GltfTest, PrimitiveModesIndexTypesAndSparse) {
  Scene s = import_scene(data("primitives.gltf"));
  ASSERT_EQ(s.meshes.size(), 4u) << all_warnings(s);  // strip, fan, list, sparse (points skipped)
  // Strip 0 1 2 3 4 (u8 indices): every other triangle swaps its first two vertices.
  EXPECT_EQ(s.meshes[0].indices, (std::vector<uint32_t>{0, 1, 2, 2, 1, 3, 2, 3, 4}));
  // Fan 0 1 3 2 (u32 indices): (1, 3, 0), (3, 2, 0).
  EXPECT_EQ(s.meshes[1].indices, (std::vector<uint32_t>{1, 3, 0, 3, 2, 0}));
  EXPECT_EQ(s.meshes[2].indices, (std::vector<uint32_t>{0, 1, 2}));  // no indices: 0..n-1
  EXPECT_TRUE(s.meshes[2].normals.empty());                          // no normals: flat
  // Sparse: element 2 of (0,0,1) (1,0,1) (0,1,1) replaced by (5,5,5).
  expect_vec(s.meshes[3].positions[1], Vec3(1, 0, 1), 0, "dense");
  expect_vec(s.meshes[3].positions[2], Vec3(5, 5, 5), 0, "sparse");
  EXPECT_TRUE(has_warning(s, "/meshes/2/primitives/0/mode", "points and lines")) << all_warnings(s);
}

TEST(GltfTest, InterleavedNormalizedAndQuantizedAccessors) {
  Scene s = import_scene(data("interleaved.gltf"));
  ASSERT_EQ(s.meshes.size(), 2u) << all_warnings(s);
  const Mesh& m = s.meshes[0];
  // Positions and normals interleaved in one 24-byte stride.
  expect_vec(m.positions[1], Vec3(2, 0, 0), 0, "interleaved position");
  expect_vec(m.positions[2], Vec3(0, 2, 0), 0, "interleaved position");
  expect_vec(m.normals[1], Vec3(0, 0, 1), 0, "interleaved normal");
  // Normalized u8 uvs (0,255) (255,255) (0,0) -> glTF (0,1) (1,1) (0,0) -> engine v = 1 - v.
  EXPECT_FLOAT_EQ(m.uvs[0].y, 0);
  EXPECT_FLOAT_EQ(m.uvs[1].x, 1);
  EXPECT_FLOAT_EQ(m.uvs[2].y, 1);
  // KHR_mesh_quantization: plain (not normalized) int16 positions, 8-byte stride.
  expect_vec(s.meshes[1].positions[1], Vec3(4, 0, 0), 0, "quantized position");
  expect_vec(s.meshes[1].positions[2], Vec3(0, 4, 0), 0, "quantized position");
}

// Each malformed file: the message starts with the file and the JSON pointer and says why.
TEST(GltfTest, MalformedFilesNameThePointerAndTheProblem) {
  struct Case {
    const char* file;
    const char* pointer;
    const char* reason;
  };
  const Case cases[] = {
      {"accessor_out_of_bounds.gltf", "/accessors/0", "100 elements of 12 bytes"},
      {"missing_buffer.gltf", "/buffers/0/uri", "'missing.bin' not found"},
      {"image_outside.gltf", "/images/0/uri", "'..' not allowed"},
      {"required_extension.gltf", "/extensionsRequired/0",
       "required extension KHR_draco_mesh_compression is not supported"},
      {"bad_index.gltf", "/accessors/3", "index 7 (element 2) out of range"},
      {"cycle.gltf", "/nodes/1/children/0", "node 0 is reached twice"},
      {"bad_stride.gltf", "/bufferViews/0/byteStride",
       "must be a multiple of 4 in [4, 252], got number 6"},
      {"stride_too_small.gltf", "/bufferViews/0/byteStride",
       "must be a multiple of 4 in [12, 252]"},
      {"orthographic.gltf", "/cameras/0/type", "'orthographic' is not supported"},
      {"no_position.gltf", "/meshes/0/primitives/0/attributes", "POSITION is missing"},
      {"bad_material.gltf", "/meshes/0/primitives/0/material", "material 5 does not exist"},
      {"truncated.glb", "(GLB header)", "(truncated)"},
  };
  for (const Case& c : cases) {
    std::string path = data(std::string("bad/") + c.file);
    std::string e = test::error_of([&] { load_scene(path); });
    EXPECT_EQ(e.rfind(path + ": " + c.pointer + ": ", 0), 0u) << c.file << ": " << e;
    EXPECT_NE(e.find(c.reason), std::string::npos) << c.file << ": " << e;
  }
}

// The command line renders a .gltf (load_scene dispatches by extension) and prints its warnings.
TEST(GltfTest, CliRendersAGltfFile) {
  std::string dir = test::make_temp_dir("gltf-cli");
  auto r = test::run_command("XDG_CACHE_HOME=" + dir + " " + test::rayfarm_binary() + " render " +
                             data("materials.gltf") + " -o " + dir +
                             "/m.exr --res 16x16 --spp 4 --passes 1 -q");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(fs::exists(dir + "/m.exr")) << r.output;
  EXPECT_NE(r.output.find("/materials/8/alphaMode: BLEND is not supported"), std::string::npos)
      << r.output;
  auto bad = test::run_command(test::rayfarm_binary() + " render " + data("bad/cycle.gltf") +
                               " -o " + dir + "/x.exr -q");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("cycle.gltf: /nodes/1/children/0: node 0 is reached twice"),
            std::string::npos)
      << bad.output;
}

// ---------------------------------------------------------------------------------------------
// Agreement: the Cornell box written as glTF from scene.json's own data renders the same image.

// The loaded JSON scene's world-space meshes, diffuse materials, emission and camera as glTF:
// base colour = reflectance (metallic 0, roughness 1 -> Lambertian), the light's radiance as
// emissiveFactor x KHR_materials_emissive_strength, the camera as a node matrix with yfov = fov
// (a square film).
std::string cornell_gltf(const Scene& s) {
  std::string bin;
  json j = {
      {"asset", {{"version", "2.0"}}}, {"extensionsUsed", {"KHR_materials_emissive_strength"}},
      {"bufferViews", json::array()},  {"accessors", json::array()},
      {"materials", json::array()},    {"meshes", json::array()},
      {"nodes", json::array()}};
  auto add = [&](const void* p, size_t bytes, size_t count, const char* type, int ctype) {
    j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", bytes}});
    bin.append(static_cast<const char*>(p), bytes);
    j["accessors"].push_back({{"bufferView", j["bufferViews"].size() - 1},
                              {"componentType", ctype},
                              {"count", count},
                              {"type", type}});
    return j["accessors"].size() - 1;
  };
  std::vector<int> scene_nodes;
  for (const Mesh& m : s.meshes) {
    const Material& mat = s.materials[m.material];
    EXPECT_EQ(mat.type, MaterialType::Diffuse);
    RGB r = mat.reflectance.value;
    json gm = {
        {"name", m.name},
        {"pbrMetallicRoughness", {{"baseColorFactor", {r.x, r.y, r.z, 1}}, {"metallicFactor", 0}}}};
    if (m.emission) {
      EXPECT_FALSE(m.emission->two_sided);
      RGB e = m.emission->radiance;
      float strength = max_component(e);
      gm["emissiveFactor"] = {e.x / strength, e.y / strength, e.z / strength};
      gm["extensions"] = {{"KHR_materials_emissive_strength", {{"emissiveStrength", strength}}}};
    }
    j["materials"].push_back(gm);
    json prim = {{"material", j["materials"].size() - 1}};
    prim["attributes"]["POSITION"] =
        add(m.positions.data(), m.positions.size() * 12, m.positions.size(), "VEC3", 5126);
    if (!m.normals.empty())
      prim["attributes"]["NORMAL"] =
          add(m.normals.data(), m.normals.size() * 12, m.normals.size(), "VEC3", 5126);
    prim["indices"] = add(m.indices.data(), m.indices.size() * 4, m.indices.size(), "SCALAR", 5125);
    j["meshes"].push_back({{"primitives", {prim}}});
    j["nodes"].push_back({{"mesh", j["meshes"].size() - 1}});
    scene_nodes.push_back(int(j["nodes"].size() - 1));
  }
  json matrix = json::array();
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) matrix.push_back(s.camera.camera_to_world.m[r][c]);
  EXPECT_EQ(s.film.width, s.film.height);
  j["cameras"] = {{{"type", "perspective"},
                   {"perspective",
                    {{"yfov", s.camera.fov_deg / kDeg}, {"aspectRatio", 1.0}, {"znear", 0.01}}}}};
  j["nodes"].push_back({{"camera", 0}, {"matrix", matrix}});
  scene_nodes.push_back(int(j["nodes"].size() - 1));
  j["scenes"] = {{{"nodes", scene_nodes}}};
  j["buffers"] = {{{"byteLength", bin.size()},
                   {"uri", "data:application/octet-stream;base64," + test::base64(bin)}}};
  return j.dump();
}

// 64x64, max depth 64, 32 passes x 24 spp each, independent seeds. Tolerance: the harness's
// (per-pixel Welch t at level 0.001 with a binomial outlier allowance, image means within 1%);
// 768 spp keeps the image means' combined standard error under the harness's 0.3% (at 512 spp
// the blue channel's was 0.36%).
TEST(GltfTest, CornellBoxAgreesWithTheJsonScene) {
  SceneOverrides ov;
  ov.width = ov.height = 64;
  ov.max_depth = 64;
  ov.spp = 768;
  ov.passes = 32;
  ov.filter = "box";
  ov.seed = 1;
  Scene js = load_scene(test::source_dir() + "/scenes/cornell-box/scene.json", ov);
  std::string dir = test::make_temp_dir("gltf-cornell");
  test::write_text(dir + "/cornell.gltf", cornell_gltf(js));
  ov.seed = 2;
  Scene gs = load_scene(dir + "/cornell.gltf", ov);
  EXPECT_TRUE(gs.warnings.empty()) << all_warnings(gs);
  ASSERT_EQ(gs.meshes.size(), js.meshes.size());
  EXPECT_NEAR(gs.camera.fov_deg, js.camera.fov_deg, 1e-4f);
  test::ImageStats a = test::render_stats(js, 32, 1), b = test::render_stats(gs, 32, 1);
  test::Agreement ag = test::compare(a, b);
  EXPECT_TRUE(ag.passed) << ag.message;
  std::printf("glTF Cornell box: %s\n", ag.message.c_str());
  // The converged box's image means (tests/cornell_test.cpp) within 1% (issue 11): the glTF
  // render's standard error is about 0.2% of each mean, so 1% is 5 standard errors.
  test::expect_cornell_means(test::image_means(b), 0.0025, "Cornell box (glTF)");
}

}  // namespace
}  // namespace rf
