// Deforming meshes (Mesh::deform; docs/scene-format.md "deform", docs/design.md "Time"): vertex
// keys interpolated linearly, resampled at each frame's uniform Embree time steps. The box
// shutter's image of a deforming box is the mean of stills across the shutter (the statistics
// harness); a zero-length shutter is the still at that instant; hits land on the triangle at the
// ray's time, single rays and packets alike; ir and ppm refuse it; the JSON keys and their errors.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "engine/accel.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/fixtures.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

using nlohmann::json;

// Makes world mesh `name` deform: keys at `times` (seconds), key k's vertices moved by
// shape(k, vertex).
template <class Shape>
void deform_mesh(Scene& s, const std::string& name, const std::vector<double>& times,
                 Shape&& shape) {
  size_t i = 0;
  while (i < s.meshes.size() && s.meshes[i].name != name) ++i;
  ASSERT_LT(i, s.meshes.size()) << name;
  Mesh& m = s.meshes[i];
  m.deform.clear();
  const std::vector<Vec3> rest = m.positions;
  for (size_t k = 0; k < times.size(); ++k) {
    VertexKey key;
    key.time = times[k];
    for (const Vec3& p : rest) key.positions.push_back(shape(k, p));
    key.normals = m.normals;
    m.deform.push_back(std::move(key));
  }
  m.positions = m.deform.front().positions;
}

// The Cornell box whose tall box leans over frame 0 (a shutter open for the whole frame): its
// top slides 0.3 units along +x and it grows 20% taller, the floor's vertices staying put (a
// shear and a stretch, which no rigid motion gives).
Scene leaning_box(const test::CornellBox& settings) {
  Scene s = test::cornell_box(settings);
  const float floor_y = 0.0f;  // the Cornell box fixture's floor
  deform_mesh(s, "TallBox", {0.0, 1.0 / 24}, [&](size_t k, Vec3 p) {
    if (k == 0) return p;
    const float h = p.y - floor_y;
    return Vec3(p.x + 0.25f * h, floor_y + 1.2f * h, p.z);
  });
  s.time = ShotTime{24, 0, 1};
  return s;
}

// The tall box's vertices in the fixture span y in [0, 1.2]: check the fixture is the one the
// shear above assumes, so that the test deforms what it says.
TEST(Deform, TheFixturesTallBoxStandsOnTheFloor) {
  const Scene s = test::cornell_box({"path", 8, 1, 1});
  for (const Mesh& m : s.meshes)
    if (m.name == "TallBox") {
      Vec3 lo(kInf), hi(-kInf);
      mesh_bounds(m, lo, hi);
      EXPECT_NEAR(lo.y, 0.0f, 1e-3f);
      EXPECT_NEAR(hi.y, 1.2f, 1e-3f);
      return;
    }
  FAIL() << "no TallBox";
}

// Blur against stills, as MotionGeometry.BoxShutterBlurOfAMovingBoxIsTheMeanOfStills does for a
// moving instance, with the same statistics (Welch's t per pixel and channel at level 0.001, 32
// passes of 4 spp at 24x24, 16 stills at the midpoints of 16 equal slices of the shutter): the
// box's top sweeps some 3 pixels over the shutter, a still stands for a fifth of a pixel of it,
// below the per-pixel standard error in all but a few edge pixels (the harness's outlier
// allowance). With the packet path's hits taken on the mesh's first key instead of the triangle
// at the ray's time, 268 of the 1,728 cells fail; against the box held at its first key it fails.
TEST(Deform, BoxShutterBlurOfADeformingBoxIsTheMeanOfStills) {
  const uint32_t passes = 32;
  const Scene deforming = leaning_box({"path", 24, 4, passes, 3, 8});
  ASSERT_TRUE(geometry_moves(deforming));
  const test::ImageStats blurred = test::render_stats(deforming, passes, 1);
  constexpr int kSlices = 16;
  const test::Agreement a = test::compare(
      blurred, test::mean_of_stills([&](double t) { return test::geometry_still_at(deforming, t); },
                                    0, 1.0 / 24, kSlices, passes, 1));
  EXPECT_TRUE(a.passed) << a.message;
  std::printf("deforming box against the mean of stills: %s\n", a.message.c_str());
  const test::Agreement sharp = test::compare(
      blurred, test::render_stats(test::geometry_still_at(deforming, 0.0), passes, 1));
  EXPECT_FALSE(sharp.passed) << sharp.message;
}

// A zero-length shutter is the instant: Embree gets the box's vertices at that time in one step,
// the image the still box's at that instant, bit for bit.
TEST(Deform, AZeroShutterIsTheStillAtThatInstant) {
  Scene deforming = leaning_box({"path", 24, 4, 4, 3, 8});
  SceneOverrides o;
  o.shutter = "0.25";
  apply_overrides(deforming, o);
  const Scene still = test::geometry_still_at(deforming, 0.25 / 24);
  Renderer rd(deforming), rs(still);
  const Rect frame{0, 0, 24, 24};
  const SampleBuffer a = rd.render(TaskKey{0, frame, 1}, true);
  const SampleBuffer b = rs.render(TaskKey{0, frame, 1}, true);
  EXPECT_TRUE(test::bits_equal(a.sum, b.sum));
}

// A frame's BVH is a function of the scene and the frame, deforming meshes included: frame 17
// rendered by a renderer that built frames 1 to 16 before it (keeping Renderer::kKeepFrames) is
// the bits of a fresh renderer's frame 17, and frame 16 is another image. The box leans through
// keys at frames 0, 8 and 24, and the shutter spans the whole frame.
TEST(Deform, AFramesImageDoesNotDependOnTheFramesBefore) {
  Scene s = test::cornell_box({"path", 16, 2, 4, 3, 8});
  deform_mesh(s, "TallBox", {0.0, 8.0 / 24, 1.0}, [](size_t k, Vec3 p) {
    return Vec3(p.x + 0.1f * float(k) * p.y, p.y * (1 + 0.1f * float(k)), p.z);
  });
  s.time = ShotTime{24, 0, 1};
  const Rect frame{0, 0, 16, 16};
  Renderer reused(s);
  for (FrameNumber f = 1; f <= 16; ++f) reused.render(TaskKey{f, frame, 0}, true);
  const SampleBuffer a = reused.render(TaskKey{17, frame, 0}, true);
  Renderer fresh(s);
  const SampleBuffer b = fresh.render(TaskKey{17, frame, 0}, true);
  EXPECT_TRUE(test::bits_equal(a.sum, b.sum));
  const SampleBuffer c = fresh.render(TaskKey{16, frame, 0}, true);
  EXPECT_FALSE(test::bits_equal(a.sum, c.sum));
}

// A square in the plane z = Z(t) facing +z, Z piecewise linear over keys at times 0, 0.3 and 1
// (seconds; a shutter over [0, 1] at 1 fps) through 0, 1 and 0.5.
Scene bobbing_square(std::vector<double> times, std::vector<float> heights) {
  Scene s;
  s.materials.push_back(Material{});
  Mesh m;
  m.name = "square";
  m.positions = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  m.normals = {{0, 0, 1}, {0, 0, 1}, {0, 0, 1}, {0, 0, 1}};
  m.indices = {0, 1, 2, 0, 2, 3};
  s.meshes.push_back(m);
  deform_mesh(s, "square", times, [&](size_t k, Vec3 p) { return Vec3(p.x, p.y, heights[k]); });
  s.time = ShotTime{1, 0, 1};
  return s;
}

// Within one key segment Embree's two steps are the keys' interpolation: a ray down the z axis
// hits the square where it is at the ray's time, to float rounding.
TEST(Deform, HitsAreOnTheTriangleAtTheRaysTime) {
  const Scene s = bobbing_square({0.0, 1.0}, {0.0f, 1.0f});
  EXPECT_EQ(deform_time_steps(s.meshes[0], 0, 1), 2u);
  Accel accel(s, 0);
  EXPECT_EQ(accel.time_steps(), 2u);
  for (float time : {0.0f, 0.25f, 0.6f, 1.0f}) {
    SCOPED_TRACE(time);
    SurfaceHit hit;
    ASSERT_TRUE(accel.intersect(Ray{{0.2f, 0.3f, 5}, {0, 0, -1}, kInf, time}, hit));
    EXPECT_NEAR(hit.t, 5 - time, 1e-5f);
    EXPECT_NEAR(hit.p.z, time, 1e-6f);
    EXPECT_LE(std::fabs(hit.p.z - time), hit.p_error.z + 1e-7f);
    EXPECT_EQ(hit.ns, Vec3(0, 0, 1));
    EXPECT_EQ(accel.occluded(Ray{{0.2f, 0.3f, 5}, {0, 0, -1}, 4.5f, time}), time > 0.5f);
  }
}

// Keys inside the shutter: kStepsPerSegment steps per key segment, uniform over the shutter.
// At a step's time the square is where the keys put it (the steps are the keys' interpolation
// there); between steps Embree interpolates its steps, not the keys, so a key that falls between
// two steps is cut by at most the motion over one step.
TEST(Deform, KeysInsideTheShutterAreResampledUniformly) {
  const Scene s = bobbing_square({0.0, 0.3, 1.0}, {0.0f, 1.0f, 0.5f});
  const uint32_t steps = deform_time_steps(s.meshes[0], 0, 1);
  EXPECT_EQ(steps, 1 + 2 * kStepsPerSegment);
  EXPECT_EQ(deform_time_steps(s.meshes[0], -2, -1), 1u);    // before the first key
  EXPECT_EQ(deform_time_steps(s.meshes[0], 0.1, 0.1), 1u);  // an instant
  EXPECT_EQ(deform_time_steps(s.meshes[0], 0.4, 0.9), 2u);  // inside one segment
  Accel accel(s, 0);
  auto z_of_keys = [](double t) { return t < 0.3 ? t / 0.3 : 1 - 0.5 * (t - 0.3) / 0.7; };
  for (uint32_t k = 0; k < steps; ++k) {
    const float time = float(k) / float(steps - 1);
    SurfaceHit hit;
    ASSERT_TRUE(accel.intersect(Ray{{0.1f, 0.1f, 5}, {0, 0, -1}, kInf, time}, hit));
    EXPECT_NEAR(hit.p.z, z_of_keys(time), 1e-5) << "step " << k;
  }
  // At the middle key (t = 0.3, between steps 4 and 5 of 16 segments) the steps' chord is below
  // the peak by at most the motion over one step (1 / 0.3 per second, 1/16 s per step).
  SurfaceHit hit;
  ASSERT_TRUE(accel.intersect(Ray{{0.1f, 0.1f, 5}, {0, 0, -1}, kInf, 0.3f}, hit));
  EXPECT_LT(hit.p.z, 1.0f);
  EXPECT_GT(hit.p.z, 1.0f - (1 / 0.3f) / 16);
}

// A packet's hits on a deforming mesh are the single-ray query's, lane by lane: the packet path
// must take the triangle at each lane's time, not the mesh's first key.
TEST(Deform, PacketHitsEqualSingleRayHits) {
  const Scene s = bobbing_square({0.0, 1.0}, {0.0f, 1.0f});
  Accel accel(s, 0);
  Accel::RayPacket packet;
  Ray rays[Accel::kPacket];
  for (int i = 0; i < Accel::kPacket; ++i) {
    rays[i] = Ray{{-0.8f + 0.1f * float(i), 0.05f * float(i), 5},
                  {0, 0, -1},
                  kInf,
                  float(i) / (Accel::kPacket - 1)};
    packet.set(i, rays[i]);
  }
  Accel::PacketHits hits;
  accel.intersect_packet(packet, Accel::kPacket, hits, /*coherent=*/true);
  for (int i = 0; i < Accel::kPacket; ++i) {
    SCOPED_TRACE(i);
    SurfaceHit single;
    ASSERT_TRUE(accel.intersect(rays[i], single));
    ASSERT_TRUE(hits.found[i]);
    const SurfaceHit h = hits.hit(i);
    EXPECT_EQ(h.p, single.p);
    EXPECT_EQ(h.t, single.t);
    EXPECT_EQ(h.time, single.time);
    EXPECT_NEAR(h.p.z, rays[i].time, 1e-6f);
  }
}

TEST(Deform, IrAndPppmRefuseDeformingGeometry) {
  for (const char* name : {"ir", "ppm"}) {
    const Scene s = leaning_box({name, 8, 1, 1});
    try {
      Renderer r(s);
      ADD_FAILURE() << name << " rendered a deforming mesh";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("shape 'TallBox' deforms during the shot"),
                std::string::npos)
          << e.what();
    }
  }
}

json deforming_scene() {
  return json::parse(R"({
    "version": 1,
    "time": {"fps": 10},
    "camera": {"fov_deg": 40, "look_at": {"eye": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0]}},
    "film": {"resolution": [16, 12]},
    "render": {"spp": 4, "passes": 1},
    "materials": {"white": {"type": "diffuse", "reflectance": 0.5}},
    "shapes": [
      {"type": "rectangle", "material": "white", "transform": {"translate": [0, 0, -1]}},
      {"type": "mesh", "name": "sheet", "material": "white", "transform": {"translate": [0, 0, 1]},
       "positions": [0, 0, 0, 1, 0, 0, 0, 1, 0], "normals": [0, 0, 1, 0, 0, 1, 0, 0, 1],
       "indices": [0, 1, 2],
       "deform": [{"frame": 0},
                  {"frame": 5, "positions": [0, 0, 0, 2, 0, 0, 0, 1, 0],
                   "normals": [0, 0, 1, 0, 0, 1, 0, 0, 1]},
                  {"time": 1, "file": "bent.obj"}]}
    ]
  })");
}

const char* kBentObj =
    "v 0 0 0.5\nv 2 0 0\nv 0 2 0\nvn 0 0 1\nvn 0 0 1\nvn 0 0 1\nf 1//1 2//2 3//3\n";

Scene load_json(const json& j) {
  return test::load_scene_text("scene.json", j.dump(2), {}, {{"bent.obj", kBentObj}});
}
std::string load_error(const json& j) {
  return test::scene_text_error("scene.json", j.dump(2), {}, {{"bent.obj", kBentObj}});
}

TEST(Deform, JsonShapesTakeDeformKeys) {
  const Scene s = load_json(deforming_scene());
  ASSERT_EQ(s.meshes.size(), 2u);
  const Mesh& m = s.meshes[1];
  ASSERT_TRUE(m.deforms());
  ASSERT_EQ(m.deform.size(), 3u);
  EXPECT_DOUBLE_EQ(m.deform[1].time, 0.5);
  EXPECT_DOUBLE_EQ(m.deform[2].time, 1.0);
  // Every key is moved by the shape's transform; the first is the shape's own vertices.
  EXPECT_EQ(m.positions[1], Vec3(1, 0, 1));
  EXPECT_EQ(m.deform[1].positions[1], Vec3(2, 0, 1));
  EXPECT_EQ(m.deform[2].positions[0], Vec3(0, 0, 1.5f));
  EXPECT_EQ(m.deform[2].normals.size(), 3u);
  std::vector<Vec3> p, n;
  deformed_vertices(m, 0.25, p, n);
  EXPECT_EQ(p[1], Vec3(1.5f, 0, 1));
  deformed_vertices(m, 9, p, n);  // held after the last key
  EXPECT_EQ(p[2], Vec3(0, 2, 1));
  EXPECT_TRUE(geometry_moves(s));
  Vec3 lo, hi;
  scene_bounds(s, lo, hi);
  EXPECT_GE(hi.y, 2.0f);  // the last key's reach
  EXPECT_GE(hi.z, 1.5f);
}

TEST(Deform, BadDeformKeysNameTheShapeAndTheKey) {
  auto expect = [](const json& j, const std::string& what) {
    const std::string e = load_error(j);
    EXPECT_NE(e.find(what), std::string::npos) << e;
  };
  json j = deforming_scene();
  j["shapes"][1]["deform"][1]["frame"] = -1;
  expect(j, "shapes[1].deform[1].frame: keys must be in increasing time");
  j = deforming_scene();
  j["shapes"][1]["deform"][1]["positions"] = {0, 0, 0, 1, 0, 0};
  expect(j, "shapes[1].deform[1]: has 2 vertices; the shape has 3");
  j = deforming_scene();
  j["shapes"][1]["deform"][1].erase("normals");
  expect(j, "shapes[1].deform[1]: needs a normal per vertex");
  j = deforming_scene();
  j["shapes"][1]["deform"][2]["file"] = "bent.png";
  expect(j, "shapes[1].deform[2].file: 'bent.png' is not an .obj or .ply mesh");
  j = deforming_scene();
  j["shapes"][1]["deform"] = json::array({{{"frame", 0}}});
  expect(j, "shapes[1].deform: needs at least two keys");
  j = deforming_scene();
  j["shapes"][1]["keyframes"] = json::array({{{"frame", 0}}});
  expect(j, "shapes[1].deform: a shape deforms ('deform') or moves by 'keyframes', not both");
  j = deforming_scene();
  j["shapes"][0]["deform"] = json::array({{{"frame", 0}}, {{"frame", 1}}});
  j["shapes"][0]["type"] = "cube";
  expect(j, "shapes[0].deform: only triangle meshes deform");
  // A deforming emitter loads (tests/moving_light_test.cpp renders one).
  j = deforming_scene();
  j["shapes"][1]["emission"] = {{"radiance", 2}};
  EXPECT_TRUE(load_json(j).meshes[1].deforms());
  j = deforming_scene();
  j["objects"] = json::array({{{"name", "o"}, {"shapes", json::array({j["shapes"][1]})}}});
  expect(j, "objects[0].shapes[0]");  // an instanced object's shape does not deform
}

}  // namespace
}  // namespace rf
