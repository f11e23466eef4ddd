// Moving emitters (docs/design.md "Time"): an area light on a deforming mesh, or placed by a
// moving instance (which prepare_instances turns into one), is sampled, hit and emits at the
// path's time. The box shutter's image of a moving Cornell box light is the mean of stills
// across the shutter (the statistics harness); direct, light and bdpt agree with path on it; a
// JSON emitter with keyframes becomes a deforming world mesh with the keys its track needs; ir
// and ppm refuse it.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>

#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/fixtures.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

using nlohmann::json;

// The Cornell box whose ceiling light slides 0.4 units along +x and turns 40 degrees about the
// vertical axis through its centre over frame 0 (a shutter open for the whole frame): a deforming
// world mesh with keys at kSteps + 1 times, the turn sampled as the importer samples one.
Scene moving_light(const test::CornellBox& settings) {
  Scene s = test::cornell_box(settings);
  size_t li = 0;
  while (li < s.meshes.size() && s.meshes[li].name != "Light") ++li;
  EXPECT_LT(li, s.meshes.size());
  Mesh& m = s.meshes[li];
  const Vec3 c{-0.005f, 1.98f, -0.03f};  // the light's centre
  constexpr int kSteps = 8;
  const std::vector<Vec3> rest = m.positions;
  for (int k = 0; k <= kSteps; ++k) {
    const float u = float(k) / kSteps;
    const Mat4 xf = Mat4::translate(c + Vec3(0.4f * u, 0, 0)) * Mat4::rotate({0, 1, 0}, 40 * u) *
                    Mat4::translate(-c);
    VertexKey key;
    key.time = u / 24.0;
    for (const Vec3& p : rest) key.positions.push_back(xf.point(p));
    for (const Vec3& n : m.normals) key.normals.push_back(normalize(xf.normal(n)));
    m.deform.push_back(std::move(key));
  }
  m.positions = m.deform.front().positions;
  m.normals = m.deform.front().normals;
  s.time = ShotTime{24, 0, 1};
  return s;
}

// Blur against stills (as MotionGeometry.BoxShutterBlurOfAMovingBoxIsTheMeanOfStills: Welch's t
// per pixel and channel at level 0.001, 32 passes at 24x24, 16 stills at the midpoints of 16
// slices of the shutter): light samples, emission seen by camera and BSDF rays, and their MIS
// weights all take the light where it is at the path's time. The smallest bias it sees: about
// 3.5 per-pixel standard errors in more than 7 of the 1,728 cells, or 1% of an image mean.
// The light's footprint on the ceiling moves about 2 pixels over the shutter, and the room's
// lighting changes smoothly with it, so the midpoint rule's error is far below a pixel's standard
// error (64 spp per pass at max depth 3, so that the image means are known to 0.4%). With light
// samples, emission points and MIS densities taken on the light's first key instead (the light
// set ignoring the time), 1,263 of the 1,728 cells fail, and direct against path 6 of 108.
TEST(MovingLight, BoxShutterBlurOfAMovingLightIsTheMeanOfStills) {
  const uint32_t passes = 32;
  const Scene moving = moving_light({"path", 24, 64, passes, 3, 3});
  ASSERT_TRUE(geometry_moves(moving));
  const test::ImageStats blurred = test::render_stats(moving, passes, 1);
  const test::Agreement a = test::compare(
      blurred, test::mean_of_stills([&](double t) { return test::geometry_still_at(moving, t); }, 0,
                                    1.0 / 24, 16, passes, 1));
  EXPECT_TRUE(a.passed) << a.message;
  std::printf("moving light against the mean of stills: %s\n", a.message.c_str());
}

// direct (light and BSDF sampling with MIS), light (light paths starting on the light at their
// time, connected to the camera) and bdpt (every strategy's light vertex at the sample's time)
// agree with path on the moving light under the harness (4x4 blocks: splats correlate pixels
// within a pass; 16 spp per pass, 32 passes; direct at max depth 1 against path at max depth 1).
TEST(MovingLight, DirectLightAndBdptAgreeWithPath) {
  const test::ImageStats path = test::render_stats(moving_light({"path", 24, 64, 32, 5}), 32, 4);
  for (const char* name : {"light", "bdpt"}) {
    SCOPED_TRACE(name);
    const test::ImageStats other = test::render_stats(moving_light({name, 24, 64, 32, 6}), 32, 4);
    const test::Agreement a = test::compare(other, path);
    EXPECT_TRUE(a.passed) << a.message;
    std::printf("%s vs path on the moving light: %s\n", name, a.message.c_str());
  }
  const test::ImageStats path1 =
      test::render_stats(moving_light({"path", 24, 128, 32, 5, 1}), 32, 4);
  const test::ImageStats direct =
      test::render_stats(moving_light({"direct", 24, 128, 32, 6, 1}), 32, 4);
  const test::Agreement a = test::compare(direct, path1);
  EXPECT_TRUE(a.passed) << a.message;
  std::printf("direct vs path (depth 1) on the moving light: %s\n", a.message.c_str());
}

// Energy: a rectangular emitter spinning a quarter turn about the vertical axis through a point
// of a diffuse sensor plane below it sends that point the same irradiance at every instant (the
// rectangle only turns about the point's axis), so the time-integrated irradiance there, seen by
// a one-pixel camera with a 0.02 degree field of view, equals the static emitter's: path, direct
// and bdpt, each against its own static render, under the harness (1 pixel, 32 passes of 4,096
// samples: the image means known to 0.005-0.03%, so the t-test sees a bias of some 0.02-0.1%).
// With keys every 90/8 degrees instead, the chords between keys shrink the turning emitter and
// it fails: 0.52% less irradiance (z = -108 for path) - why linear_sample_times cuts a turn finer.
Scene spinning_emitter(const char* integrator, bool spins) {
  Scene s;
  s.film.width = s.film.height = 1;
  s.render.spp = 4096 * 32;
  s.render.passes = 32;
  s.render.integrator.method = make_integrator(integrator);
  s.render.integrator.max_depth = 2;
  s.camera.fov_deg = 0.02f;
  s.camera.camera_to_world = Mat4::look_at({0.6f, 0.3f, 0}, {0, 0, 0}, {0, 1, 0});
  Material grey;
  grey.reflectance.value = RGB(0.5f);
  s.materials.push_back(grey);
  Mesh floor;
  floor.name = "sensor";
  floor.positions = {{-4, 0, -4}, {4, 0, -4}, {4, 0, 4}, {-4, 0, 4}};
  floor.indices = {0, 2, 1, 0, 3, 2};  // facing +y
  s.meshes.push_back(floor);
  Mesh lamp;
  lamp.name = "lamp";
  lamp.positions = {
      {-0.3f, 0.5f, -0.08f}, {0.3f, 0.5f, -0.08f}, {0.3f, 0.5f, 0.08f}, {-0.3f, 0.5f, 0.08f}};
  lamp.indices = {0, 1, 2, 0, 2, 3};  // facing -y
  lamp.emission = Emission{RGB(5.0f), false};
  if (spins) {  // keys every 90 / 128 degrees: the chord's shortfall 1 - cos(0.35 deg) = 2e-5
    for (int k = 0; k <= 128; ++k) {
      const Mat4 r = Mat4::rotate({0, 1, 0}, 90.0f * float(k) / 128);
      VertexKey key;
      key.time = k / 128.0 / 24;
      for (const Vec3& p : lamp.positions) key.positions.push_back(r.point(p));
      lamp.deform.push_back(std::move(key));
    }
  }
  s.meshes.push_back(lamp);
  s.time = ShotTime{24, 0, 1};
  return s;
}

TEST(MovingLight, ASpinningEmitterSendsItsAxisTheStaticIrradiance) {
  for (const char* name : {"path", "direct", "bdpt"}) {
    SCOPED_TRACE(name);
    const Scene moving = spinning_emitter(name, true), still = spinning_emitter(name, false);
    ASSERT_TRUE(geometry_moves(moving));
    const test::Agreement a =
        test::compare(test::render_stats(moving, 32, 1), test::render_stats(still, 32, 1));
    EXPECT_TRUE(a.passed) << a.message;
    std::printf("%s, spinning against static emitter: %s\n", name, a.message.c_str());
  }
}

TEST(MovingLight, IrAndPpmRefuseAMovingLight) {
  for (const char* name : {"ir", "ppm"}) {
    const Scene s = moving_light({name, 8, 1, 1});
    try {
      Renderer r(s);
      ADD_FAILURE() << name << " rendered a moving light";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("shape 'Light' deforms during the shot"),
                std::string::npos)
          << e.what();
    }
  }
}

// A JSON emitter with keyframes is an object placed by a moving instance; prepare_instances
// makes its world copy a deforming mesh: a key at each of the track's keys, and within a segment
// that turns, 2^k steps (linear_sample_times); a translation needs none. An emissive sphere is
// tessellated.
TEST(MovingLight, AJsonEmitterWithKeyframesBecomesADeformingWorldMesh) {
  const json j = json::parse(R"({
    "version": 1,
    "camera": {"fov_deg": 40, "look_at": {"eye": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0]}},
    "film": {"resolution": [16, 12]},
    "render": {"spp": 4, "passes": 1},
    "materials": {"white": {"type": "diffuse", "reflectance": 0.5}},
    "shapes": [
      {"type": "rectangle", "material": "white"},
      {"type": "rectangle", "name": "lamp", "material": "white", "emission": {"radiance": 4},
       "keyframes": [{"frame": 0}, {"frame": 12, "transform": {"translate": [1, 0, 0]}},
                     {"frame": 24, "transform": [{"rotate": {"axis": [0, 0, 1], "angle_deg": 90}},
                                                 {"translate": [1, 0, 0]}]}]},
      {"type": "sphere", "name": "bulb", "material": "white", "radius": 0.1,
       "emission": {"radiance": 2},
       "keyframes": [{"frame": 0}, {"frame": 24, "transform": {"translate": [0, 1, 0]}}]}
    ]
  })");
  const Scene s = test::load_scene_text("scene.json", j.dump(2));
  const Mesh* lamp = nullptr;
  const Mesh* bulb = nullptr;
  for (const Mesh& m : s.meshes) {
    if (m.name.rfind("lamp", 0) == 0) lamp = &m;
    if (m.name.rfind("bulb", 0) == 0) bulb = &m;
  }
  ASSERT_TRUE(lamp && bulb);
  ASSERT_TRUE(lamp->deforms());
  // Keys at 0 and 0.5 s (a translation: no steps), then the quarter turn's steps to 1 s.
  const std::vector<double> turn = linear_sample_times(
      AnimatedTransform({{0.0, Mat4::identity()}, {1.0, Mat4::rotate({0, 0, 1}, 90)}}));
  EXPECT_GT(turn.size(), 8u);
  EXPECT_EQ(lamp->deform.size(), 1 + turn.size());
  std::vector<Vec3> p, n;
  deformed_vertices(*lamp, 0.25, p, n);  // halfway through the translation: exact
  EXPECT_NEAR(p[0].x, -1 + 0.5f, 1e-6f);
  EXPECT_TRUE(bulb->deforms());
  EXPECT_FALSE(bulb->sphere.has_value());  // tessellated
  EXPECT_EQ(bulb->deform.size(), 2u);
  Renderer r(s);  // path renders it
  const SampleBuffer b = r.render(TaskKey{0, Rect{0, 0, 16, 12}, 0}, false);
  EXPECT_GT(b.sum.size(), 0u);
}

}  // namespace
}  // namespace rf
