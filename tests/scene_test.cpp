// The scene format v1 (docs/scene-format.md): the shipped Cornell box, the OBJ and PLY readers,
// transforms, passes and overrides, and one test per kind of bad input asserting that the message
// names the file and the JSON path (or line) and says what is wrong.
#include <gtest/gtest.h>

#include <bit>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "engine/digest.h"
#include "engine/json_reader.h"
#include "engine/mesh_io.h"
#include "engine/scene.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

using json = nlohmann::json;
namespace fs = std::filesystem;

std::string cornell_path() { return test::source_dir() + "/scenes/cornell-box/scene.json"; }

// Geometric (right-hand) normal of triangle t of a mesh, unnormalised.
Vec3 face_normal(const Mesh& m, size_t t) {
  Vec3 a = m.positions[m.indices[3 * t]], b = m.positions[m.indices[3 * t + 1]],
       c = m.positions[m.indices[3 * t + 2]];
  return cross(b - a, c - a);
}

Vec3 face_centroid(const Mesh& m, size_t t) {
  return (m.positions[m.indices[3 * t]] + m.positions[m.indices[3 * t + 1]] +
          m.positions[m.indices[3 * t + 2]]) /
         3.0f;
}

const Mesh& mesh_named(const Scene& s, const std::string& name) {
  for (const Mesh& m : s.meshes)
    if (m.name == name) return m;
  throw std::runtime_error("no mesh " + name);
}

// A small valid scene that tests modify.
json minimal_scene() {
  return json::parse(R"({
    "version": 1,
    "camera": {"fov_deg": 40, "look_at": {"eye": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0]}},
    "film": {"resolution": [32, 24]},
    "render": {"integrator": {"type": "path", "max_depth": 5}, "spp": 16, "passes": 4, "seed": 7},
    "materials": {"white": {"type": "diffuse", "reflectance": 0.5}},
    "shapes": [{"type": "rectangle", "material": "white"}]
  })");
}

Scene load_json(const json& j, const std::string& tag = "scene") {
  std::string dir = test::make_temp_dir(tag);
  test::write_text(dir + "/scene.json", j.dump(2));
  return load_scene(dir + "/scene.json");
}

// ---------------------------------------------------------------------------------------------
// The shipped Cornell box

TEST(CornellBox, LoadsWithTheSettingsOfTheReference) {
  Scene s = load_scene(cornell_path());
  EXPECT_EQ(s.path, cornell_path());
  EXPECT_EQ(s.film.width, 256);
  EXPECT_EQ(s.film.height, 256);
  EXPECT_EQ(s.film.filter.type, FilterType::Box);
  EXPECT_FLOAT_EQ(s.film.filter.radius, 0.5f);
  EXPECT_EQ(s.render.integrator.type(), "path");
  EXPECT_EQ(s.render.integrator.max_depth, 64);
  EXPECT_EQ(s.render.spp, 256u);
  EXPECT_EQ(s.render.passes, 16u);
  EXPECT_EQ(s.render.seed, 1u);
  EXPECT_FLOAT_EQ(s.camera.fov_deg, 19.5f);
  // Camera at (0, 1, 6.8) looking down world -z with +y up.
  Vec3 eye = s.camera.camera_to_world.point(Vec3(0.0f));
  Vec3 view = s.camera.camera_to_world.vector(Vec3(0, 0, -1));
  EXPECT_NEAR(length(eye - Vec3(0, 1, 6.8f)), 0, 1e-6);
  EXPECT_NEAR(length(view - Vec3(0, 0, -1)), 0, 1e-6);

  size_t triangles = 0;
  for (const Mesh& m : s.meshes) triangles += m.triangle_count();
  EXPECT_EQ(s.meshes.size(), 8u);
  EXPECT_EQ(triangles, 5 * 2 + 2 * 12 + 2u);  // walls, floor, ceiling; two boxes; light
  EXPECT_EQ(s.assets, (std::vector<std::string>{"meshes/short-box.obj", "meshes/tall-box.obj"}));
}

TEST(CornellBox, MaterialsAreSortedByNameAndReferencedByIndex) {
  Scene s = load_scene(cornell_path());
  std::vector<std::string> names;
  for (const Material& m : s.materials) names.push_back(m.name);
  EXPECT_EQ(names, (std::vector<std::string>{"BackWall", "Ceiling", "Floor", "LeftWall", "Light",
                                             "RightWall", "ShortBox", "TallBox"}));
  const Material& left = s.materials[mesh_named(s, "LeftWall").material];
  EXPECT_EQ(left.name, "LeftWall");
  EXPECT_EQ(left.type, MaterialType::Diffuse);
  EXPECT_EQ(left.reflectance.value, RGB(0.63f, 0.065f, 0.05f));
  EXPECT_EQ(s.materials[mesh_named(s, "Light").material].reflectance.value, RGB(0.0f));
  EXPECT_EQ(s.materials[mesh_named(s, "TallBox").material].name, "TallBox");
}

TEST(CornellBox, OneOneSidedLightFacingDown) {
  Scene s = load_scene(cornell_path());
  size_t emitters = 0, emitting_triangles = 0;
  for (const Mesh& m : s.meshes)
    if (m.emission) ++emitters, emitting_triangles += m.triangle_count();
  EXPECT_EQ(emitters, 1u);
  EXPECT_EQ(emitting_triangles, 2u);
  const Mesh& light = mesh_named(s, "Light");
  ASSERT_TRUE(light.emission);
  EXPECT_EQ(light.emission->radiance, RGB(17, 12, 4));
  EXPECT_FALSE(light.emission->two_sided);
  for (size_t t = 0; t < light.triangle_count(); ++t) {
    Vec3 n = normalize(face_normal(light, t));
    EXPECT_NEAR(n.y, -1.0f, 1e-6) << "triangle " << t;
  }
}

TEST(CornellBox, WallsFaceIntoTheRoomAndBoxesOutward) {
  Scene s = load_scene(cornell_path());
  const Vec3 room_center(0, 1, 0);
  for (const char* name : {"Floor", "Ceiling", "BackWall", "RightWall", "LeftWall"}) {
    const Mesh& m = mesh_named(s, name);
    for (size_t t = 0; t < m.triangle_count(); ++t)
      EXPECT_GT(dot(face_normal(m, t), room_center - face_centroid(m, t)), 0) << name << " " << t;
  }
  for (const char* name : {"ShortBox", "TallBox"}) {
    const Mesh& m = mesh_named(s, name);
    Vec3 c(0.0f);
    for (Vec3 p : m.positions) c += p;
    c = c / float(m.positions.size());
    for (size_t t = 0; t < m.triangle_count(); ++t)
      EXPECT_GT(dot(face_normal(m, t), face_centroid(m, t) - c), 0) << name << " " << t;
  }
}

TEST(CornellBox, DigestIsStableAndFollowsTheDocumentedDefinition) {
  Scene a = load_scene(cornell_path());
  Scene b = load_scene(cornell_path());
  ASSERT_EQ(a.digest.size(), 64u);
  EXPECT_EQ(a.digest.find_first_not_of("0123456789abcdef"), std::string::npos);
  EXPECT_EQ(a.digest, b.digest);

  // docs/scene-format.md: sha256(scene bytes, then per asset "\0" path "\0" hex sha256(asset)).
  std::string dir = test::source_dir() + "/scenes/cornell-box/";
  Sha256 h;
  h.update(read_file_bytes(cornell_path()));
  for (const std::string& asset : a.assets) {
    h.update(std::string_view("\0", 1));
    h.update(asset);
    h.update(std::string_view("\0", 1));
    h.update(sha256_hex(read_file_bytes(dir + asset)));
  }
  EXPECT_EQ(a.digest, h.hex_digest());
}

TEST(CornellBox, DigestChangesWithAnAsset) {
  std::string dir = test::make_temp_dir("cornell-copy");
  fs::copy(test::source_dir() + "/scenes/cornell-box", dir, fs::copy_options::recursive);
  std::string before = load_scene(dir + "/scene.json").digest;
  std::string obj = read_file_bytes(dir + "/meshes/tall-box.obj");
  test::write_text(dir + "/meshes/tall-box.obj", obj + "# edited\n");
  EXPECT_NE(load_scene(dir + "/scene.json").digest, before);
}

// ---------------------------------------------------------------------------------------------
// Mesh readers

TEST(Obj, ReadsCornerFormatsNegativeIndicesAndFansPolygons) {
  std::string dir = test::make_temp_dir("obj");
  test::write_text(dir + "/a.obj",
                   "# a quad and a pentagon\n"
                   "o thing\n"
                   "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                   "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                   "vn 0 0 1\n"
                   "usemtl whatever\ns off\n"
                   "f 1/1/1 2/2/1 3/3/1 4/4/1\n"
                   "v 2 0 0\nv 3 0 0\nv 3 1 0\nv 2.5 2 0\nv 2 1 0\n"
                   "vt 0 0\n"
                   "f -5/-1/-1 -4/-1/1 -3/5/1 -2/5/1 -1/5/1\r\n");
  MeshData m = load_obj(dir + "/a.obj");
  EXPECT_EQ(m.indices.size(), 3u * (2 + 3));  // quad -> 2 triangles, pentagon -> 3
  ASSERT_EQ(m.positions.size(), 9u);          // distinct (v, vt, vn) corners
  EXPECT_EQ(m.normals.size(), 9u);
  EXPECT_EQ(m.uvs.size(), 9u);
  EXPECT_EQ(m.positions[m.indices[0]], Vec3(0, 0, 0));
  EXPECT_EQ(m.positions[m.indices[1]], Vec3(1, 0, 0));
  EXPECT_EQ(m.positions[m.indices[2]], Vec3(1, 1, 0));
  EXPECT_EQ(m.positions[m.indices[5]], Vec3(0, 1, 0));
  // The pentagon fans around its first corner (2, 0, 0); its last triangle ends at (2, 1, 0).
  EXPECT_EQ(m.positions[m.indices[6]], Vec3(2, 0, 0));
  EXPECT_EQ(m.positions[m.indices[12]], Vec3(2, 0, 0));
  EXPECT_EQ(m.positions[m.indices[14]], Vec3(2, 1, 0));
  EXPECT_EQ(m.normals[m.indices[14]], Vec3(0, 0, 1));
}

TEST(Obj, PlainAndNormalOnlyCorners) {
  MeshData plain = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "plain.obj");
  EXPECT_EQ(plain.positions.size(), 3u);
  EXPECT_TRUE(plain.normals.empty());
  EXPECT_TRUE(plain.uvs.empty());
  MeshData n = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n", "n.obj");
  EXPECT_EQ(n.normals.size(), 3u);
  EXPECT_TRUE(n.uvs.empty());
  // Normals on only some corners cannot be used: the mesh falls back to flat shading.
  MeshData mixed = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2 3\n", "mixed.obj");
  EXPECT_TRUE(mixed.normals.empty());
}

TEST(Obj, ErrorsNameFileAndLine) {
  auto error = [](const char* text) -> std::string {
    try {
      parse_obj(text, "x.obj");
    } catch (const SceneError& e) {
      return e.what();
    }
    return "no error";
  };
  EXPECT_NE(error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n").find("x.obj:4: vertex index 0"),
            std::string::npos);
  EXPECT_NE(error("v 0 0 0\nf 1 -2 1\n").find("x.obj:2: vertex index -2 out of range"),
            std::string::npos);
  EXPECT_NE(error("v 0 0 zero\n").find("x.obj:1: expected a finite number, got 'zero'"),
            std::string::npos);
  EXPECT_NE(error("v 0 0 0\nv 1 0 0\nf 1 2\n").find("x.obj:3: face needs at least 3 vertices"),
            std::string::npos);
  EXPECT_NE(error("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/4 2 3\n").find("texture coordinate index 4"),
            std::string::npos);
}

const char* kAsciiPly =
    "ply\n"
    "format ascii 1.0\n"
    "comment written by scene_test\n"
    "element vertex 5\n"
    "property float x\nproperty float y\nproperty float z\n"
    "property float nx\nproperty float ny\nproperty float nz\n"
    "property float s\nproperty float t\n"
    "element face 2\n"
    "property list uchar int vertex_indices\n"
    "property uchar flags\n"
    "end_header\n"
    "0 0 0 0 0 1 0 0\n"
    "1 0 0 0 0 1 1 0\n"
    "1 1 0 0 0 1 1 1\n"
    "0 1 0 0 0 1 0 1\n"
    "0.5 2 0 0 0 1 0.5 1\n"
    "4 0 1 2 3 7\n"
    "3 3 2 4 0\n";

TEST(Ply, Ascii) {
  MeshData m = parse_ply(kAsciiPly, "a.ply");
  ASSERT_EQ(m.positions.size(), 5u);
  EXPECT_EQ(m.normals.size(), 5u);
  ASSERT_EQ(m.uvs.size(), 5u);
  EXPECT_EQ(m.indices, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 3, 2, 4}));
  EXPECT_EQ(m.positions[4], Vec3(0.5f, 2, 0));
  EXPECT_EQ(m.normals[2], Vec3(0, 0, 1));
  EXPECT_EQ(m.uvs[2].x, 1);
  EXPECT_EQ(m.uvs[4].x, 0.5f);
}

// Appends v in the given byte order.
template <typename T>
void put(std::string& out, T v, bool big_endian) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if (big_endian == (std::endian::native == std::endian::little)) std::reverse(b, b + sizeof(T));
  out.append(b, sizeof(T));
}

// A binary PLY: 4 vertices (x y z as float, plus a double "quality" that must be skipped), one
// quad face with an int count, and an extra element that must be skipped.
std::string binary_ply(bool big_endian) {
  std::string s = std::string("ply\nformat ") +
                  (big_endian ? "binary_big_endian" : "binary_little_endian") +
                  " 1.0\n"
                  "element vertex 4\n"
                  "property float x\nproperty float y\nproperty float z\n"
                  "property double quality\n"
                  "element face 1\n"
                  "property list int uint vertex_index\n"
                  "element edge 1\n"
                  "property int vertex1\nproperty int vertex2\n"
                  "end_header\n";
  const float p[4][3] = {{0, 0, 0}, {2, 0, 0}, {2, 3, 0}, {0, 3, -1.5f}};
  for (auto& v : p) {
    for (float c : v) put(s, c, big_endian);
    put(s, 0.25, big_endian);
  }
  put(s, int32_t(4), big_endian);
  for (uint32_t i : {0u, 1u, 2u, 3u}) put(s, i, big_endian);
  put(s, int32_t(0), big_endian);
  put(s, int32_t(1), big_endian);
  return s;
}

TEST(Ply, BinaryLittleEndianFromAFile) {
  std::string dir = test::make_temp_dir("ply");
  test::write_text(dir + "/b.ply", binary_ply(false));
  MeshData m = load_ply(dir + "/b.ply");
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_TRUE(m.normals.empty());
  EXPECT_TRUE(m.uvs.empty());
  EXPECT_EQ(m.indices, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3}));
  EXPECT_EQ(m.positions[2], Vec3(2, 3, 0));
  EXPECT_EQ(m.positions[3], Vec3(0, 3, -1.5f));
}

TEST(Ply, BinaryBigEndian) {
  MeshData m = parse_ply(binary_ply(true), "b.ply");
  ASSERT_EQ(m.positions.size(), 4u);
  EXPECT_EQ(m.indices.size(), 6u);
  EXPECT_EQ(m.positions[3], Vec3(0, 3, -1.5f));
}

TEST(Ply, ErrorsNameFileAndProblem) {
  auto error = [](const std::string& bytes) -> std::string {
    try {
      parse_ply(bytes, "p.ply");
    } catch (const SceneError& e) {
      return e.what();
    }
    return "no error";
  };
  std::string bin = binary_ply(false);
  EXPECT_NE(error(bin.substr(0, bin.size() - 12)).find("p.ply: element 'face' row 0 of 1"),
            std::string::npos);
  EXPECT_NE(error("plx\n").find("not a PLY file"), std::string::npos);
  EXPECT_NE(error("ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\n0\n")
                .find("needs properties x, y and z"),
            std::string::npos);
  std::string bad_index = kAsciiPly;
  bad_index.replace(bad_index.find("3 3 2 4"), 7, "3 3 2 9");
  EXPECT_NE(error(bad_index).find("vertex index 9 out of range (5 vertices)"), std::string::npos);
}

// ---------------------------------------------------------------------------------------------
// Shapes, transforms, settings

TEST(Shapes, TransformOpsApplyInTheOrderWritten) {
  json j = minimal_scene();
  // Corner (-1, -1, 0) of the rectangle: scale by 2 -> (-2, -2, 0), then translate -> (-1, -2, 0).
  j["shapes"][0]["transform"] = json::parse(R"([{"scale": 2}, {"translate": [1, 0, 0]}])");
  j["shapes"].push_back(json::parse(R"({"type": "rectangle", "material": "white",
      "transform": [{"translate": [1, 0, 0]}, {"scale": 2}]})"));
  j["shapes"].push_back(json::parse(R"({"type": "rectangle", "material": "white",
      "transform": {"rotate": {"axis": [0, 0, 1], "angle_deg": 90}}})"));
  j["shapes"].push_back(json::parse(R"({"type": "rectangle", "material": "white",
      "transform": [{"matrix": [1, 0, 0, 5,  0, 1, 0, 6,  0, 0, 1, 7,  0, 0, 0, 1]}]})"));
  Scene s = load_json(j);
  EXPECT_EQ(s.meshes[0].positions[0], Vec3(-1, -2, 0));
  EXPECT_EQ(s.meshes[1].positions[0], Vec3(0, -2, 0));  // (-1+1, -1) * 2
  // Rotating (1, -1, 0) by +90 degrees about z gives (1, 1, 0).
  EXPECT_NEAR(length(s.meshes[2].positions[1] - Vec3(1, 1, 0)), 0, 1e-6);
  EXPECT_EQ(s.meshes[3].positions[2], Vec3(6, 7, 7));
}

TEST(Shapes, RectangleAndCubeWindOutward) {
  json j = minimal_scene();
  j["shapes"].push_back(json::parse(R"({"type": "cube", "material": "white"})"));
  // A mirror keeps the front side: the rectangle's transformed normal (0, 0, -1) stays the
  // geometric normal.
  j["shapes"].push_back(json::parse(
      R"({"type": "rectangle", "material": "white", "transform": {"scale": [1, 1, -1]}})"));
  Scene s = load_json(j);
  for (size_t t = 0; t < 2; ++t) EXPECT_GT(face_normal(s.meshes[0], t).z, 0);
  ASSERT_EQ(s.meshes[1].triangle_count(), 12u);
  for (size_t t = 0; t < 12; ++t)
    EXPECT_NEAR(dot(normalize(face_normal(s.meshes[1], t)), face_centroid(s.meshes[1], t)), 1.0f,
                1e-6)  // outward unit normal: the face plane lies at distance +1
        << "triangle " << t;
  for (size_t t = 0; t < 2; ++t) EXPECT_LT(face_normal(s.meshes[2], t).z, 0);
}

TEST(Shapes, InlineMeshNormalsNamesAndDegenerateTriangles) {
  json j = minimal_scene();
  j["shapes"][0] = json::parse(R"({
    "type": "mesh", "name": "tri", "material": "white",
    "positions": [0, 0, 0,  1, 0, 0,  0, 1, 0,  2, 2, 2],
    "normals": [0, 0, 2,  0, 0, 1,  0, 0, 1,  0, 0, 1],
    "uvs": [0, 0, 1, 0, 0, 1, 1, 1],
    "indices": [0, 1, 2,  3, 3, 3],
    "transform": {"scale": [2, 1, 1]},
    "emission": {"radiance": 3, "two_sided": true}
  })");
  Scene s = load_json(j);
  const Mesh& m = s.meshes[0];
  EXPECT_EQ(m.name, "tri");
  EXPECT_EQ(m.triangle_count(), 1u);  // the zero-area triangle is dropped
  EXPECT_EQ(m.positions[1], Vec3(2, 0, 0));
  EXPECT_EQ(m.normals[0], Vec3(0, 0, 1));  // transformed and normalised
  ASSERT_TRUE(m.emission);
  EXPECT_EQ(m.emission->radiance, RGB(3.0f));
  EXPECT_TRUE(m.emission->two_sided);
  EXPECT_EQ(load_json(minimal_scene()).meshes[0].name, "shapes[0]");
}

TEST(Settings, DefaultsAndPasses) {
  json j = minimal_scene();
  j.erase("render");
  Scene s = load_json(j);
  EXPECT_EQ(s.render.integrator.type(), "path");
  EXPECT_EQ(s.render.spp, 64u);
  EXPECT_EQ(s.render.passes, 4u);  // gcd(64, 16) = 16, halved to 4 (16 spp per pass)
  EXPECT_EQ(s.render.sampler, "sobol");
  EXPECT_EQ(s.film.filter.type, FilterType::Box);
  EXPECT_FLOAT_EQ(s.film.filter.radius, 0.5f);
  j["render"] = json::parse(R"({"spp": 24, "seed": 18446744073709551615, "noise_target": 0.01})");
  s = load_json(j);
  EXPECT_EQ(s.render.passes, 4u);  // gcd(24, 16) = 8, halved to 4
  for (auto [spp, passes] : {std::pair<uint64_t, uint32_t>{1, 1}, {2, 2}, {16, 4}, {100, 4},
                             {256, 4}, {512, 8}, {1024, 16}, {4096, 16}, {7, 1}, {1536, 16}})
    EXPECT_EQ(default_passes(spp), passes) << spp << " spp";
  EXPECT_EQ(s.render.seed, 18446744073709551615ull);
  EXPECT_DOUBLE_EQ(s.render.noise_target, 0.01);
  EXPECT_EQ(s.render.integrator.max_depth, 5);
  EXPECT_EQ(s.render.integrator.rr_min_depth, 3);
}

// The example in docs/scene-format.md must stay a valid scene.
TEST(Docs, ExampleSceneLoads) {
  std::string doc = read_file_bytes(test::source_dir() + "/docs/scene-format.md");
  size_t begin = doc.find("```json\n");
  ASSERT_NE(begin, std::string::npos);
  begin += 8;
  std::string text = doc.substr(begin, doc.find("```", begin) - begin);
  std::string dir = test::make_temp_dir("doc-example");
  test::write_text(dir + "/scene.json", text);
  test::write_text(dir + "/meshes/bunny.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  Scene s = load_scene(dir + "/scene.json");
  ASSERT_EQ(s.meshes.size(), 3u);
  EXPECT_EQ(s.film.width, 640);
  // The floor faces up and the light faces down, as the text says.
  EXPECT_NEAR(normalize(face_normal(mesh_named(s, "floor"), 0)).y, 1.0f, 1e-6);
  EXPECT_NEAR(normalize(face_normal(mesh_named(s, "light"), 0)).y, -1.0f, 1e-6);
  EXPECT_NEAR(mesh_named(s, "light").positions[0].y, 3.0f, 1e-6);
}

TEST(Settings, CameraToWorldMatrix) {
  json j = minimal_scene();
  j["camera"] = json::parse(R"({"type": "perspective", "fov_deg": 30,
      "to_world": [1, 0, 0, 1,  0, 1, 0, 2,  0, 0, 1, 3,  0, 0, 0, 1]})");
  Scene s = load_json(j);
  EXPECT_EQ(s.camera.camera_to_world.point(Vec3(0.0f)), Vec3(1, 2, 3));
}

std::string override_error(Scene s, const SceneOverrides& o) {
  try {
    apply_overrides(s, o);
  } catch (const SceneError& e) {
    return e.what();
  }
  return "no error";
}

TEST(Overrides, ValidatedAndNamedByFlag) {
  Scene s = load_scene(cornell_path());  // spp 256, passes 16
  SceneOverrides o;
  o.spp = 100;
  o.passes = 16;
  EXPECT_EQ(override_error(s, o), "--spp: must be a multiple of --passes (16), got 100");
  o = {};
  o.passes = 3;
  EXPECT_EQ(override_error(s, o), "--passes: must divide the scene's spp (256), got 3");
  o = {};
  o.integrator = "pathh";
  EXPECT_EQ(override_error(s, o), "--integrator: unknown integrator 'pathh' (known: " +
                                      join_names(known_integrators()) + ")");
  o = {};
  o.width = 0;
  EXPECT_EQ(override_error(s, o), "--res: width must be between 1 and 32768, got 0");
  o = {};
  o.max_depth = -1;
  EXPECT_EQ(override_error(s, o), "--max-depth: must be at least 0, got -1");
  o = {};
  o.filter = "lanczos";
  EXPECT_EQ(override_error(s, o), "--filter: unknown filter 'lanczos' (known: box, triangle, gaussian)");
  o = {};
  o.noise_target = -1;
  EXPECT_NE(override_error(s, o).find("--noise-target"), std::string::npos);
  o = {};
  o.spp = 0;
  EXPECT_EQ(override_error(s, o), "--spp: must be at least 1, got 0");

  // A rejected override leaves the scene as it was.
  o = {};
  o.width = 64;
  o.spp = 100;
  o.passes = 16;
  EXPECT_THROW(apply_overrides(s, o), SceneError);
  EXPECT_EQ(s.film.width, 256);
  EXPECT_EQ(s.render.spp, 256u);
}

TEST(Overrides, Applied) {
  SceneOverrides o;
  o.spp = 100;  // the scene's 16 passes do not divide 100: passes become gcd(100, 16) = 4
  o.seed = 9;
  o.width = 64;
  o.height = 32;
  o.max_depth = 3;
  o.noise_target = 0.5;
  o.filter = "box";
  o.integrator = "path";
  Scene s = load_scene(cornell_path(), o);
  EXPECT_EQ(s.render.spp, 100u);
  EXPECT_EQ(s.render.passes, 4u);
  EXPECT_EQ(s.render.seed, 9u);
  EXPECT_EQ(s.film.width, 64);
  EXPECT_EQ(s.film.height, 32);
  EXPECT_EQ(s.render.integrator.max_depth, 3);
  EXPECT_DOUBLE_EQ(s.render.noise_target, 0.5);
  SceneOverrides keep;
  keep.spp = 512;  // 16 divides 512: the scene's passes stay
  EXPECT_EQ(load_scene(cornell_path(), keep).render.passes, 16u);
  SceneOverrides both;
  both.spp = 30;
  both.passes = 5;
  Scene b = load_scene(cornell_path(), both);
  EXPECT_EQ(b.render.spp_per_pass(), 6u);
}

// The registry's names are its variant's, each once, and each makes its own integrator.
TEST(Integrators, KnownNames) {
  const std::vector<std::string>& names = known_integrators();
  EXPECT_EQ(names.size(), std::variant_size_v<Integrator>);
  EXPECT_EQ(std::set<std::string>(names.begin(), names.end()).size(), names.size());
  for (const std::string& name : names) EXPECT_EQ(integrator_name(make_integrator(name)), name);
  EXPECT_THROW(make_integrator("pathh"), std::invalid_argument);
}

// Other renderers' integrator types map through the modules' own lists (module.h).
TEST(Integrators, ImportedTypesMapThroughTheModules) {
  EXPECT_EQ(integrator_for_pbrt("ambientocclusion"), "ao");
  EXPECT_EQ(integrator_for_pbrt("volpath"), "path");
  EXPECT_EQ(integrator_for_pbrt("sppm"), "ppm");
  EXPECT_EQ(integrator_for_pbrt("bdpt"), "bdpt");
  EXPECT_EQ(integrator_for_pbrt("lightpath"), "light");
  EXPECT_EQ(integrator_for_pbrt("mystery"), "");
  EXPECT_EQ(integrator_for_mitsuba("ptracer"), "light");
  EXPECT_EQ(integrator_for_mitsuba("prb"), "path");
  EXPECT_EQ(integrator_for_mitsuba("ambientocclusion"), "");
  EXPECT_EQ(mitsuba_integrator_types(),
            "direct, path, volpath, volpathmis, prb (as path), ptracer (as light), bdpt");
  // Each imported type is claimed by one module at most.
  std::map<std::string, int> claims;
  for (const std::string& name : known_integrators())
    std::visit(
        [&](const auto& i) {
          using T = std::decay_t<decltype(i)>;
          std::istringstream pbrt(T::kPbrtTypes), mitsuba(T::kMitsubaTypes);
          for (std::string w; pbrt >> w;) ++claims["pbrt:" + w];
          for (std::string w; mitsuba >> w;) ++claims["mitsuba:" + w];
        },
        make_integrator(name));
  for (const auto& [type, n] : claims) EXPECT_EQ(n, 1) << type;
  EXPECT_EQ(claims.size(), 17u);  // 10 pbrt-v4 types, 7 Mitsuba 3 types
  EXPECT_FALSE(integrator_needs_lights(make_integrator("ao")));
  EXPECT_TRUE(integrator_needs_lights(make_integrator("path")));
}

// ---------------------------------------------------------------------------------------------
TEST(Format, MaterialsTexturesLightsEnvironmentCameraSampler) {
  json j = minimal_scene();
  j["textures"] = {{"checks", {{"type", "checkerboard"}, {"color_a", 0.1}, {"color_b", {0.9, 0.8, 0.7}}, {"scale", 8}}},
                   {"grey", {{"type", "constant"}, {"value", 0.25}}}};
  j["materials"] = {
      {"white", {{"type", "diffuse"}, {"reflectance", {{"texture", "checks"}}}}},
      {"gold", {{"type", "rough_conductor"}, {"preset", "gold"}, {"roughness", {{"texture", "grey"}}}}},
      {"tinted", {{"type", "conductor"}, {"tint", {0.9, 0.5, 0.2}}}},
      {"glass", {{"type", "dielectric"}, {"ior", 1.5}}},
      {"frosted", {{"type", "rough_dielectric"}, {"ior", 1.33}, {"roughness", 0.2}}},
      {"pane", {{"type", "thin_dielectric"}}},
      {"plastic", {{"type", "plastic"}, {"reflectance", {0.2, 0.3, 0.8}}, {"roughness", 0.1}}}};
  j["shapes"].push_back({{"type", "sphere"}, {"material", "glass"}, {"center", {0, 1, 0}}, {"radius", 0.5}, {"tessellation", {8, 16}}});
  j["shapes"].push_back({{"type", "disk"}, {"material", "gold"}, {"segments", 12}});
  j["lights"] = {{{"type", "point"}, {"position", {0, 2, 0}}, {"intensity", {1, 2, 3}}},
                 {{"type", "spot"}, {"position", {0, 2, 0}}, {"target", {0, 0, 0}}, {"intensity", 5}, {"cone_angle_deg", 25}},
                 {{"type", "directional"}, {"direction", {0, -2, 0}}, {"irradiance", 3}}};
  j["environment"] = {{"radiance", {0.1, 0.2, 0.3}}, {"transform", {{"rotate", {{"axis", {0, 1, 0}}, {"angle_deg", 90}}}}}};
  j["camera"]["aperture_radius"] = 0.05;
  j["camera"]["focus_distance"] = 5;
  j["film"]["filter"] = {{"type", "gaussian"}, {"sigma", 0.4}};
  j["render"]["sampler"] = "sobol";
  Scene s = load_json(j, "format");
  ASSERT_EQ(s.materials.size(), 7u);
  auto mat = [&](const std::string& n) -> const Material& {
    for (const Material& m : s.materials)
      if (m.name == n) return m;
    throw std::runtime_error(n);
  };
  EXPECT_EQ(mat("white").reflectance.texture, 0);  // textures in sorted name order: checks, grey
  EXPECT_EQ(mat("gold").type, MaterialType::RoughConductor);
  EXPECT_EQ(mat("gold").roughness.texture, 1);
  EXPECT_TRUE(mat("tinted").conductor_tint);
  EXPECT_EQ(mat("tinted").specular.value, RGB(0.9f, 0.5f, 0.2f));
  EXPECT_EQ(mat("frosted").type, MaterialType::RoughDielectric);
  EXPECT_FLOAT_EQ(mat("frosted").ior, 1.33f);
  EXPECT_EQ(mat("pane").type, MaterialType::ThinDielectric);
  EXPECT_EQ(mat("plastic").type, MaterialType::Plastic);
  EXPECT_EQ(s.textures[0].type, TextureType::Checkerboard);
  EXPECT_FLOAT_EQ(s.textures[0].uv_scale.x, 8);
  // Sphere: 2*8*16 - 2*16 triangles, unit normals pointing away from the centre.
  const Mesh& sphere = s.meshes[1];
  EXPECT_EQ(sphere.triangle_count(), 2u * 8 * 16 - 2 * 16);
  for (size_t i = 0; i < sphere.positions.size(); ++i) {
    EXPECT_NEAR(length(sphere.positions[i] - Vec3(0, 1, 0)), 0.5f, 1e-5f);
    EXPECT_GT(dot(sphere.normals[i], sphere.positions[i] - Vec3(0, 1, 0)), 0.49f);
  }
  for (size_t t = 0; t < sphere.triangle_count(); ++t)
    EXPECT_GT(dot(face_normal(sphere, t), face_centroid(sphere, t) - Vec3(0, 1, 0)), 0) << t;
  EXPECT_EQ(s.meshes[2].triangle_count(), 12u);
  ASSERT_EQ(s.lights.size(), 3u);
  EXPECT_EQ(s.lights[1].type, LightType::Spot);
  EXPECT_NEAR(s.lights[1].direction.y, -1.0f, 1e-6f);
  EXPECT_FLOAT_EQ(s.lights[1].falloff_start_deg, 20.0f);  // default, below the cone
  EXPECT_NEAR(s.lights[2].direction.y, -1.0f, 1e-6f);     // normalised
  ASSERT_TRUE(s.environment.has_value());
  EXPECT_TRUE(s.environment->file.empty());
  EXPECT_FLOAT_EQ(s.camera.lens_radius, 0.05f);
  EXPECT_EQ(s.film.filter.type, FilterType::Gaussian);
  EXPECT_FLOAT_EQ(s.film.filter.radius, 1.5f);
  EXPECT_EQ(s.render.sampler, "sobol");
}

TEST(Format, ImageAssetsAreInTheDigest) {
  json j = minimal_scene();
  j["textures"] = {{"img", {{"type", "image"}, {"file", "tex/a.png"}, {"data", true}}}};
  std::string dir = test::make_temp_dir("asset");
  test::write_text(dir + "/tex/a.png", "not really a png, only hashed here");
  test::write_text(dir + "/scene.json", j.dump());
  Scene a = load_scene(dir + "/scene.json");
  EXPECT_EQ(a.assets, std::vector<std::string>{"tex/a.png"});
  EXPECT_TRUE(a.textures[0].is_data);
  test::write_text(dir + "/tex/a.png", "changed");
  EXPECT_NE(load_scene(dir + "/scene.json").digest, a.digest);
}

// Bad scenes: each message names the file, the JSON path (or line) and the problem.

struct BadScene {
  std::string name;
  // Writes any side files into dir and returns the scene text.
  std::function<std::string(const std::string& dir)> make;
  std::string where;  // JSON path or line
  std::string what;
};

std::ostream& operator<<(std::ostream& os, const BadScene& b) { return os << b.name; }

std::function<std::string(const std::string&)> edit(std::function<void(json&)> f) {
  return [f](const std::string&) {
    json j = minimal_scene();
    f(j);
    return j.dump(2);
  };
}

std::function<std::string(const std::string&)> with_shape(const char* shape) {
  return edit([shape](json& j) { j["shapes"][0] = json::parse(shape); });
}

// The shape's text is spliced in so literals nlohmann would not write (1e999) survive.
std::function<std::string(const std::string&)> with_matrix(const char* matrix) {
  std::string shape = std::string(R"({"type": "rectangle", "material": "white", )") +
                      R"("transform": [{"translate": [0, 0, 1]}, {"matrix": )" + matrix + "}]}";
  return [shape](const std::string&) {
    json j = minimal_scene();
    j["shapes"][0] = "SHAPE";
    std::string text = j.dump();
    return text.replace(text.find("\"SHAPE\""), 7, shape);
  };
}

const std::vector<BadScene>& bad_scenes() {
  static const std::vector<BadScene> cases = {
      {"SyntaxError",
       [](const std::string&) {
         return "{\n  \"version\": 1,\n  \"camera\" {\"fov_deg\": 40}\n}\n";
       },
       "line 3, column 12", "expected ':'"},
      {"UnknownTopLevelKey", edit([](json& j) { j["camrea"] = j["camera"]; }), "camrea",
       "unknown key (expected one of: format, version, time, camera"},
      {"WrongVersion", edit([](json& j) { j["version"] = 2; }), "version",
       "unsupported format version 2 (this build reads version 1)"},
      {"MissingVersion", edit([](json& j) { j.erase("version"); }), "version",
       "required key is missing"},
      {"WrongFormatName", edit([](json& j) { j["format"] = "pbrt"; }), "format",
       "expected \"rayfarm-scene\""},
      {"DuplicateKey",
       [](const std::string&) {
         std::string t = minimal_scene().dump();
         std::string m = R"("white":{"reflectance":0.5,"type":"diffuse"})";
         return t.replace(t.find(m), m.size(), m + "," + m);
       },
       "materials.white", "duplicate key"},
      {"UnknownMaterialReference", edit([](json& j) { j["shapes"][0]["material"] = "whte"; }),
       "shapes[0].material", "unknown material 'whte' (known: white)"},
      {"UnknownMaterialType", edit([](json& j) { j["materials"]["white"]["type"] = "glass"; }),
       "materials.white.type", "unknown material type 'glass' (known: diffuse, conductor"},
      {"ReflectanceAboveOne", edit([](json& j) {
         j["materials"]["white"]["reflectance"] = {0.5, 1.2, 0.5};
       }),
       "materials.white.reflectance[1]", "must be at most 1, got 1.2"},
      {"MaterialKeyTypo", edit([](json& j) { j["materials"]["white"]["reflectence"] = 0.5; }),
       "materials.white.reflectence", "unknown key (expected one of: reflectance, type)"},
      {"MissingMeshFile",
       with_shape(R"({"type": "obj", "material": "white", "file": "meshes/nope.obj"})"),
       "shapes[0].file", "mesh file 'meshes/nope.obj' not found"},
      {"MeshPathWithDotDot",
       with_shape(R"({"type": "obj", "material": "white", "file": "meshes/../../x.obj"})"),
       "shapes[0].file", "'..' not allowed in asset path"},
      {"AbsoluteMeshPath", with_shape(R"({"type": "ply", "material": "white", "file": "/x.ply"})"),
       "shapes[0].file", "absolute path '/x.ply' not allowed"},
      {"NegativeResolution", edit([](json& j) {
         j["film"]["resolution"] = {-4, 24};
       }),
       "film.resolution[0]", "must be at least 1, got -4"},
      {"ZeroResolution", edit([](json& j) {
         j["film"]["resolution"] = {32, 0};
       }),
       "film.resolution[1]", "must be at least 1, got 0"},
      {"HugeResolution", edit([](json& j) {
         j["film"]["resolution"] = {40000, 24};
       }),
       "film.resolution[0]", "must be at most 32768, got 40000"},
      // JSON has no NaN: a "NaN" string is a type error at its path...
      {"NaNStringInMatrix", with_matrix(R"([1, 0, 0, 0, 0, "NaN", 0, 0, 0, 0, 1, 0, 0, 0, 0, 1])"),
       "shapes[0].transform[1].matrix[5]", "expected a number, got string \"NaN\""},
      // ...a finite double beyond float range is not finite as float...
      {"HugeNumberInMatrix", with_matrix("[1e300, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]"),
       "shapes[0].transform[1].matrix[0]", "not finite in single precision"},
      // ...and 1e999 overflows double: nlohmann refuses it while parsing, so the line is named.
      {"InfinityInMatrix", with_matrix("[1e999, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]"),
       "line 1, column", "number 1e999 is out of range"},
      {"SingularMatrix", with_matrix("[1, 0, 0, 0, 0, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0, 1]"),
       "shapes[0].transform[1].matrix", "matrix is singular"},
      {"ProjectiveMatrix", with_matrix("[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 1, 1]"),
       "shapes[0].transform[1].matrix", "last row must be [0, 0, 0, 1]"},
      {"ZeroScale",
       with_shape(R"({"type": "cube", "material": "white", "transform": [{"scale": [1, 0, 1]}]})"),
       "shapes[0].transform[0].scale", "singular: a scale factor is 0"},
      {"TwoOpsInOneTransformStep", with_shape(R"({"type": "cube", "material": "white",
                      "transform": [{"scale": 2, "translate": [0, 0, 1]}]})"),
       "shapes[0].transform[0]", "expected exactly one of translate, scale, rotate, matrix"},
      {"SppNotMultipleOfPasses", edit([](json& j) { j["render"]["spp"] = 18; }), "render.spp",
       "must be a multiple of render.passes (4), got 18"},
      {"NegativeMaxDepth", edit([](json& j) { j["render"]["integrator"]["max_depth"] = -1; }),
       "render.integrator.max_depth", "must be at least 0, got -1"},
      {"UnknownIntegrator", edit([](json& j) { j["render"]["integrator"]["type"] = "pathh"; }),
       "render.integrator.type",
       "unknown integrator 'pathh' (known: " + join_names(known_integrators()) + ")"},
      {"NegativeSeed", edit([](json& j) { j["render"]["seed"] = -1; }), "render.seed",
       "expected a non-negative integer, got number -1"},
      {"FovOutOfRange", edit([](json& j) { j["camera"]["fov_deg"] = 180; }), "camera.fov_deg",
       "must be between 0 and 180 degrees (exclusive), got 180"},
      {"ZeroFov", edit([](json& j) { j["camera"]["fov_deg"] = 0; }), "camera.fov_deg",
       "must be between 0 and 180"},
      {"CameraUpParallelToView", edit([](json& j) {
         j["camera"]["look_at"]["up"] = {0, 0, 2};
       }),
       "camera.look_at.up", "must not be zero or parallel to the view direction"},
      {"CameraBothPlacements", edit([](json& j) {
         j["camera"]["to_world"] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
       }),
       "camera", "give either 'look_at' or 'to_world', not both"},
      {"CameraMatrixWithScale", edit([](json& j) {
         j["camera"].erase("look_at");
         j["camera"]["to_world"] = {2, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
       }),
       "camera.to_world", "must be a rotation"},
      {"UnknownFilter", edit([](json& j) {
         j["film"]["filter"] = {{"type", "lanczos"}};
       }),
       "film.filter.type", "unknown filter 'lanczos' (known: box, triangle, gaussian)"},
      {"NegativeRadiance", edit([](json& j) {
         j["shapes"][0]["emission"] = {{"radiance", {-1, 1, 1}}};
       }),
       "shapes[0].emission.radiance[0]", "must be at least 0, got -1"},
      {"UnknownShapeType", with_shape(R"({"type": "torus", "material": "white"})"),
       "shapes[0].type", "unknown shape type 'torus'"},
      {"ShapeKeyTypo", with_shape(R"({"type": "mesh", "material": "white", "positon": [0, 0, 0],
                      "positions": [0, 0, 0, 1, 0, 0, 0, 1, 0], "indices": [0, 1, 2]})"),
       "shapes[0].positon", "unknown key"},
      {"InlineIndexOutOfRange", with_shape(R"({"type": "mesh", "name": "tri", "material": "white",
                      "positions": [0, 0, 0, 1, 0, 0, 0, 1, 0], "indices": [0, 1, 7]})"),
       "shapes[0]", "index 7 (triangle 0) out of range (3 vertices)"},
      {"PositionsNotMultipleOfThree",
       with_shape(R"({"type": "mesh", "material": "white", "positions": [0, 0, 0, 1],
                      "indices": [0, 0, 0]})"),
       "shapes[0].positions", "expected a flat array of 3*n numbers, got 4"},
      {"OnlyDegenerateTriangles", with_shape(R"({"type": "mesh", "material": "white",
                      "positions": [0, 0, 0, 1, 0, 0, 2, 0, 0], "indices": [0, 1, 2]})"),
       "shapes[0]", "all triangles are degenerate (zero area)"},
      {"ObjWithBadFaceIndex",
       [](const std::string& dir) {
         test::write_text(dir + "/meshes/bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
         return with_shape(R"({"type": "obj", "material": "white", "file": "meshes/bad.obj"})")(
             dir);
       },
       "shapes[0].file", "meshes/bad.obj:4: vertex index 9 out of range (3 vertices"},
      {"PlyWithTruncatedBinaryData",
       [](const std::string& dir) {
         std::string ply = binary_ply(false);
         test::write_text(dir + "/t.ply", ply.substr(0, ply.size() - 12));
         return with_shape(R"({"type": "ply", "material": "white", "file": "./t.ply"})")(dir);
       },
       "shapes[0].file", "t.ply: element 'face' row 0 of 1: unexpected end of data"},
      {"UnknownTextureReference", edit([](json& j) {
         j["materials"]["white"]["reflectance"] = {{"texture", "wood"}};
       }),
       "materials.white.reflectance.texture", "unknown texture 'wood' (known: none)"},
      {"MissingTextureFile", edit([](json& j) {
         j["textures"] = {{"wood", {{"type", "image"}, {"file", "wood.png"}}}};
       }),
       "textures.wood.file", "file 'wood.png' not found"},
      {"RoughConductorWithoutRoughness", edit([](json& j) {
         j["materials"]["white"] = {{"type", "rough_conductor"}, {"preset", "gold"}};
       }),
       "materials.white.roughness", "required key is missing"},
      {"UnknownConductorPreset", edit([](json& j) {
         j["materials"]["white"] = {{"type", "conductor"}, {"preset", "unobtainium"}};
       }),
       "materials.white.preset", "unknown conductor 'unobtainium' (known: gold, silver"},
      {"DielectricIorBelowOne", edit([](json& j) {
         j["materials"]["white"] = {{"type", "dielectric"}, {"ior", 0.9}};
       }),
       "materials.white.ior", "must be between 1 and 4"},
      {"SpotWithoutDirection", edit([](json& j) {
         j["lights"] = {{{"type", "spot"}, {"position", {0, 1, 0}}, {"intensity", 1}}};
       }),
       "lights[0]", "exactly one of 'target' or 'direction'"},
      {"SpotFalloffBeyondCone", edit([](json& j) {
         j["lights"] = {{{"type", "spot"}, {"position", {0, 1, 0}}, {"intensity", 1},
                         {"direction", {0, -1, 0}}, {"cone_angle_deg", 20}, {"falloff_start_deg", 30}}};
       }),
       "lights[0].falloff_start_deg", "must be in [0, cone_angle_deg]"},
      {"EnvironmentBothFileAndRadiance", edit([](json& j) {
         j["environment"] = {{"radiance", 1}, {"file", "sky.exr"}};
       }),
       "environment", "exactly one of 'file'"},
      {"EnvironmentScaledTransform", edit([](json& j) {
         j["environment"] = {{"radiance", 1}, {"transform", {{{"scale", 2}}}}};
       }),
       "environment.transform", "must be a rotation"},
      {"ThinLensWithoutFocus", edit([](json& j) { j["camera"]["aperture_radius"] = 0.1; }),
       "camera.focus_distance", "required when aperture_radius > 0"},
      {"SigmaOnBoxFilter", edit([](json& j) {
         j["film"]["filter"] = {{"type", "box"}, {"sigma", 0.5}};
       }),
       "film.filter.sigma", "only the gaussian filter has a sigma"},
      {"AoKeyOnPathIntegrator",
       edit([](json& j) { j["render"]["integrator"]["max_distance"] = 1; }),
       "render.integrator.max_distance",
       "unknown key (expected one of: type, max_depth, rr_min_depth)"},
      {"UnknownDirectStrategy", edit([](json& j) {
         j["render"]["integrator"] = {{"type", "direct"}, {"strategy", "both"}};
       }),
       "render.integrator.strategy", "expected \"light\", \"bsdf\" or \"mis\", got 'both'"},
      {"DirectWithoutSamples", edit([](json& j) {
         j["render"]["integrator"] = {{"type", "direct"}, {"light_samples", 0}, {"bsdf_samples", 0}};
       }),
       "render.integrator", "light_samples and bsdf_samples cannot both be 0"},
      // 2^28 photons asked for 16 GiB and ended in a bare bad_alloc; the cap names the field.
      {"TooManyPhotons", edit([](json& j) {
         j["render"]["integrator"] = {{"type", "ppm"}, {"photons", 1 << 28}};
       }),
       "render.integrator.photons", "16777216"},
      {"UnknownSampler", edit([](json& j) { j["render"]["sampler"] = "halton"; }), "render.sampler",
       "unknown sampler 'halton' (known: independent, sobol, sobol-sequence)"},
      {"SphereNegativeRadius",
       with_shape(R"({"type": "sphere", "material": "white", "radius": -1})"), "shapes[0].radius",
       "must be > 0"},
      // A referenced file may not lead outside the scene's directory, a symbolic link included.
      {"TextureSymlinkOutsideTheSceneDirectory",
       [](const std::string& dir) {
         std::string outside = test::make_temp_dir("outside") + "/secret.png";
         test::write_text(outside, "not an image");
         std::filesystem::create_symlink(outside, dir + "/wood.png");
         json j = minimal_scene();
         j["textures"] = {{"wood", {{"type", "image"}, {"file", "wood.png"}}}};
         return j.dump(2);
       },
       "textures.wood.file", "'wood.png' leads outside the scene file's directory"},
  };
  return cases;
}

class BadSceneTest : public testing::TestWithParam<BadScene> {};

TEST_P(BadSceneTest, MessageNamesFilePathAndProblem) {
  const BadScene& bad = GetParam();
  std::string dir = test::make_temp_dir("bad");
  std::string file = dir + "/" + bad.name + ".json";
  test::write_text(file, bad.make(dir));
  try {
    load_scene(file);
    FAIL() << "loaded without error";
  } catch (const SceneError& e) {
    std::string msg = e.what();
    EXPECT_EQ(msg.rfind(file + ": ", 0), 0u) << msg;  // starts with the scene file
    EXPECT_NE(msg.find(": " + bad.where), std::string::npos) << msg;
    EXPECT_NE(msg.find(bad.what), std::string::npos) << msg;
  }
}

INSTANTIATE_TEST_SUITE_P(Scene, BadSceneTest, testing::ValuesIn(bad_scenes()),
                         [](const auto& info) { return info.param.name; });

TEST(BadScene, MissingSceneFile) {
  try {
    load_scene("/nonexistent/scene.json");
    FAIL();
  } catch (const SceneError& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/scene.json: cannot read scene file"),
              std::string::npos);
  }
}

}  // namespace
}  // namespace rf
