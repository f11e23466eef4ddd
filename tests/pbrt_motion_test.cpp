// pbrt-v4's motion (docs/formats/pbrt.md, "Motion"): ActiveTransform picks which of the two
// current transforms the transform directives change, TransformTimes says when they hold, and a
// shape, an object instance or the camera whose two transforms differ moves between them; the
// camera's shutter is the frame's. A motion-blurred pbrt file renders as the same scene written
// in rayfarm's JSON (the statistics harness).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

Scene load_pbrt(const std::string& text, const SceneOverrides& o = {}) {
  return test::load_scene_text("scene.pbrt", text, o);
}
std::string pbrt_error(const std::string& text) {
  return test::scene_text_error("scene.pbrt", text);
}

const char* kMoving = R"(TransformTimes 0 2
LookAt 0 0 5  0 0 0  0 1 0
ActiveTransform EndTime
Translate 1 0 0
ActiveTransform All
Camera "perspective" "float fov" 45 "float shutteropen" 0.25 "float shutterclose" 0.75
Film "rgb" "integer xresolution" 16 "integer yresolution" 16
WorldBegin
LightSource "point" "point3 from" [0 4 4] "rgb I" [10 10 10]
AttributeBegin
  ActiveTransform StartTime
  Translate -1 0 0
  ActiveTransform EndTime
  Translate 1 0 0
  ActiveTransform All
  Shape "sphere" "float radius" 0.5
AttributeEnd
ObjectBegin "post"
  Shape "trianglemesh" "point3 P" [0 0 0  1 0 0  0 1 0] "integer indices" [0 1 2]
ObjectEnd
AttributeBegin
  ActiveTransform EndTime
  Rotate 90 0 1 0
  ActiveTransform All
  ObjectInstance "post"
AttributeEnd
ObjectInstance "post"
Shape "trianglemesh" "point3 P" [-5 -1 -5  5 -1 -5  5 -1 5] "integer indices" [0 1 2]
)";

TEST(PbrtMotion, ActiveTransformMovesShapesInstancesAndTheCamera) {
  const Scene s = load_pbrt(kMoving);
  for (const std::string& w : s.warnings)
    EXPECT_EQ(w.find("motion blur is not supported"), std::string::npos) << w;
  // The shutter: one frame at 1 fps, open from 0.25 to 0.75 s.
  EXPECT_EQ(s.time.fps, 1);
  EXPECT_EQ(s.time.shutter_open, 0.25);
  EXPECT_EQ(s.time.shutter_close, 0.75);
  // The camera moves between its two transforms at TransformTimes 0 and 2.
  ASSERT_TRUE(s.camera.moves());
  EXPECT_EQ(s.camera.motion.keys().front().time, 0);
  EXPECT_EQ(s.camera.motion.keys().back().time, 2);
  EXPECT_NEAR(s.camera.motion.at(2).point({0, 0, 0}).x, -1.0f, 1e-6f);
  // The floor stays a world mesh; the sphere is an object placed by a moving instance, from
  // x = -1 at time 0 to x = +1 at time 2; the rotated post moves, the other one stands.
  ASSERT_EQ(s.meshes.size(), 1u);
  ASSERT_EQ(s.instances.size(), 3u);
  const Instance& ball = s.instances[0];
  ASSERT_TRUE(ball.moves());
  EXPECT_NE(s.objects[ball.object].name.find("Shape \"sphere\""), std::string::npos);
  EXPECT_TRUE(s.objects[ball.object].meshes.at(0).sphere.has_value());  // exact, object space
  EXPECT_NEAR(ball.motion.at(0).point({0, 0, 0}).x, -1.0f, 1e-6f);
  EXPECT_NEAR(ball.motion.at(1).point({0, 0, 0}).x, 0.0f, 1e-6f);
  EXPECT_NEAR(ball.motion.at(2).point({0, 0, 0}).x, 1.0f, 1e-6f);
  EXPECT_TRUE(s.instances[1].moves());
  EXPECT_NEAR(s.instances[1].motion.at(1).point({1, 0, 0}).z, -std::sqrt(0.5f), 1e-5f);  // 45 deg
  EXPECT_FALSE(s.instances[2].moves());
  // It renders, and the blur is there: the shutter's image is not the image at its middle.
  SceneOverrides o;
  o.spp = 4, o.passes = 1;
  const Scene blurred = load_pbrt(kMoving, o);
  o.shutter = "0.5";
  const Scene instant = load_pbrt(kMoving, o);
  Renderer rb(blurred), ri(instant);
  const Rect frame{0, 0, 16, 16};
  EXPECT_NE(rb.render(TaskKey{0, frame, 0}, true).sum, ri.render(TaskKey{0, frame, 0}, true).sum);
}

TEST(PbrtMotion, BadMotionIsNamedAtItsLine) {
  std::string t = kMoving;
  t.replace(t.find("TransformTimes 0 2"), 18, "TransformTimes 1 1");
  EXPECT_NE(pbrt_error(t).find("scene.pbrt:1: TransformTimes: the end time must be after the "
                               "start time"),
            std::string::npos)
      << pbrt_error(t);
  // A moving emitter loads: a deforming world mesh (tests/moving_light_test.cpp renders one).
  t = kMoving;
  t.replace(t.find("  Shape \"sphere\""), 2, "  AreaLightSource \"diffuse\" \"rgb L\" [1 1 1]\n  ");
  EXPECT_EQ(pbrt_error(t), "(loaded)");
}

// The Cornell box's tall box sliding 0.3 units along +x over the shutter, written in pbrt-v4
// (ActiveTransform EndTime around a Translate) and in rayfarm's JSON (keyframes at 0 and 1 s at
// 1 fps, the shutter open from 0 to 1 s): the two agree under the harness (Welch's t per pixel
// and channel at level 0.001, 32 passes of 4 spp at 32x32, depth 16; common random numbers, as
// PbrtAgreement.CornellBoxMatchesTheJsonScene).
TEST(PbrtMotion, AMovingBoxRendersAsTheJsonScene) {
  const std::string dir = test::source_dir() + "/scenes/cornell-box/";
  std::ifstream in(dir + "scene-v4.pbrt");
  std::stringstream ss;
  ss << in.rdbuf();
  std::string pbrt = ss.str();
  const std::string tall = "\nNamedMaterial \"TallBox\"";
  const size_t at = pbrt.find(tall);
  ASSERT_NE(at, std::string::npos);
  const size_t end = pbrt.find("AttributeBegin", at);  // the light's block, after the tall box
  ASSERT_NE(end, std::string::npos);
  pbrt.insert(end, "AttributeEnd\n");
  pbrt.insert(at + 1,
              "AttributeBegin\nActiveTransform EndTime\nTranslate 0.3 0 0\nActiveTransform All\n");
  const std::string tmp = test::make_temp_dir("pbrt-motion-cornell");
  test::write_text(tmp + "/scene.pbrt", pbrt);
  std::filesystem::copy(dir + "meshes", tmp + "/meshes", std::filesystem::copy_options::recursive);
  nlohmann::json j = nlohmann::json::parse(std::ifstream(dir + "scene.json"));
  j["time"] = {{"fps", 1}, {"shutter", {{"open", 0}, {"close", 1}}}};
  for (auto& shape : j["shapes"])
    if (shape["name"] == "TallBox")
      shape["keyframes"] = nlohmann::json::parse(
          R"([{"time": 0}, {"time": 1, "transform": {"translate": [0.3, 0, 0]}}])");
  test::write_text(tmp + "/scene.json", j.dump());
  SceneOverrides o;
  o.width = 32, o.height = 32, o.max_depth = 16, o.spp = 128, o.passes = 32, o.seed = 1;
  o.filter = "box", o.integrator = "path";
  const Scene a = load_scene(tmp + "/scene.pbrt", o);
  const Scene b = load_scene(tmp + "/scene.json", o);
  ASSERT_TRUE(geometry_moves(a));
  ASSERT_TRUE(geometry_moves(b));
  const test::Agreement r =
      test::compare(test::render_stats(a, 32, 1), test::render_stats(b, 32, 1));
  EXPECT_TRUE(r.passed) << r.message;
  std::printf("moving cornell pbrt vs json: %s\n", r.message.c_str());
}

}  // namespace
}  // namespace rf
