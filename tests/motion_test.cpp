// Time and a moving camera (docs/scene-format.md "time", camera.keyframes): the box shutter's
// image is the average of still images across the shutter (the statistics harness), a zero-length
// shutter is the still at that instant bit for bit, frames move the camera, a still scene draws
// no time and keeps its settings text, the JSON keys and their errors, and light and bdpt, which
// connect light paths to the camera where it is at their time, agree with path.
#include <gtest/gtest.h>

#include <cstdio>
#include <nlohmann/json.hpp>

#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

using nlohmann::json;

const std::string kCornell = "scenes/cornell-box/scene.json";

// The Cornell box, small, its camera sliding 0.4 units to the right over one frame at 24 fps,
// the shutter open for the whole frame.
Scene moving_cornell(int spp_per_pass, uint32_t passes) {
  SceneOverrides o;
  o.width = 24, o.height = 24, o.max_depth = 4, o.passes = passes;
  o.spp = uint64_t(spp_per_pass) * passes;
  Scene s = load_scene(test::source_dir() + "/" + kCornell, o);
  const Mat4 c0 = s.camera.camera_to_world;
  Mat4 c1 = c0;
  c1.m[0][3] += 0.4f;
  s.camera.motion = AnimatedTransform({{0.0, c0}, {1.0 / 24, c1}});
  s.time = ShotTime{24, 0, 1};
  return s;
}

// The scene standing still where the moving one is at `time` (seconds).
Scene still_at(const Scene& moving, double time) {
  Scene s = moving;
  s.camera.camera_to_world = moving.camera.motion.at(time);
  s.camera.motion = AnimatedTransform();
  return s;
}

// Blur against stills: the moving camera's image, and per pass the mean of N = 16 still images
// at the midpoints of 16 equal slices of the shutter (the same pass, so the same seeds), agree
// under the harness (Welch's t per pixel and channel, level 0.001, 32 passes of 4 spp each).
// Midpoints make the time integral's error O(1/N^2) where a pixel's value is smooth in time and
// O(1/N) of the slice's share at an edge crossing it: a pixel's mean moves by at most ~1/16 of an
// edge's contrast times the fraction of slices the edge crosses, below the per-pixel standard
// error of 4 x 32 samples (about 10% of the pixel) in all but a few edge pixels, which the
// harness's outlier allowance takes. So the test sees a bias of about 3.5 per-pixel standard
// errors (some 30% of a pixel's value) in more than 7 of the 1,728 cells; the image means are
// known to about 1.3%, so their 1% check is weak here (the harness says so). With the camera held
// still (time ignored) the test fails: the blurred edges are far outside that.
TEST(Motion, BoxShutterBlurIsTheMeanOfStillsAcrossTheShutter) {
  const uint32_t passes = 32;
  const Scene moving = moving_cornell(4, passes);
  ASSERT_TRUE(moving.camera.moves());
  test::ImageStats blurred = test::render_stats(moving, passes, 1);
  constexpr int kSlices = 16;
  const test::Agreement a =
      test::compare(blurred, test::mean_of_stills([&](double t) { return still_at(moving, t); }, 0,
                                                  1.0 / 24, kSlices, passes, 1));
  EXPECT_TRUE(a.passed) << a.message;
  std::printf("blur against the mean of stills: %s\n", a.message.c_str());
  // And the blur is there: the still at the shutter's middle is not the blurred image.
  const test::Agreement sharp =
      test::compare(blurred, test::render_stats(still_at(moving, 0.5 / 24), passes, 1));
  EXPECT_FALSE(sharp.passed) << sharp.message;
}

// A zero-length shutter is the instant: the moving camera at frame 3 + 0.25 renders the bits of
// the still camera placed where it is then (the time stream moves no other number); so does a
// negative frame.
TEST(Motion, AZeroShutterIsTheStillAtThatInstant) {
  Scene moving = moving_cornell(4, 4);
  SceneOverrides o;
  o.shutter = "0.25";
  apply_overrides(moving, o);
  EXPECT_EQ(moving.time.shutter_open, 0.25);
  EXPECT_EQ(moving.time.shutter_close, 0.25);
  // The keys span frame 0 to 1: move them to frames 3 and 4 so that frame 3 sits inside.
  const Mat4 c0 = moving.camera.motion.keys()[0].m, c1 = moving.camera.motion.keys()[1].m;
  moving.camera.motion = AnimatedTransform({{3.0 / 24, c0}, {4.0 / 24, c1}});
  const Scene still = still_at(moving, 3.25 / 24);
  Renderer rm(moving), rs(still);
  const Rect frame{0, 0, moving.film.width, moving.film.height};
  const SampleBuffer a = rm.render(TaskKey{3, frame, 1}, true);
  const SampleBuffer b = rs.render(TaskKey{3, frame, 1}, true);
  EXPECT_EQ(a.sum, b.sum);
  // Another frame is another place: frame 4's image (the camera at key 1) differs.
  const SampleBuffer c = rm.render(TaskKey{4, frame, 1}, true);
  EXPECT_NE(a.sum, c.sum);
  // A negative frame is a time before 0: with the keys at frames -4 and -3, frame -4 at 0.25 is
  // the still at -3.75 / 24 s, with frame -4's own seeds (not frame 4's, nor frame 0's).
  Scene early = moving;
  early.camera.motion = AnimatedTransform({{-4.0 / 24, c0}, {-3.0 / 24, c1}});
  const Scene still_early = still_at(early, -3.75 / 24);
  Renderer re(early), rse(still_early);
  const SampleBuffer d = re.render(TaskKey{-4, frame, 1}, true);
  EXPECT_EQ(d.sum, rse.render(TaskKey{-4, frame, 1}, true).sum);
  EXPECT_NE(rse.render(TaskKey{4, frame, 1}, true).sum, d.sum);
  EXPECT_EQ(d.header.frame, -4);
  // The settings text names the time only where something moves.
  EXPECT_NE(settings_text(moving).find(";time=fps:24:shutter:0.25:0.25"), std::string::npos);
  EXPECT_EQ(settings_text(still).find("time="), std::string::npos);
}

json keyframed_scene() {
  return json::parse(R"({
    "version": 1,
    "time": {"fps": 25, "shutter": {"open": -0.25, "close": 0.25}},
    "camera": {"fov_deg": 40, "keyframes": [
      {"frame": 0, "look_at": {"eye": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0]}},
      {"frame": 10, "look_at": {"eye": [2, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0]}},
      {"time": 0.8, "look_at": {"eye": [2, 1, 5], "target": [0, 0, 0], "up": [0, 1, 0]}}]},
    "film": {"resolution": [16, 12]},
    "render": {"spp": 4, "passes": 1},
    "materials": {"white": {"type": "diffuse", "reflectance": 0.5}},
    "shapes": [{"type": "rectangle", "material": "white"}]
  })");
}

Scene load_json(const json& j) { return test::load_scene_text("scene.json", j.dump(2)); }
std::string load_error(const json& j) { return test::scene_text_error("scene.json", j.dump(2)); }

TEST(Motion, JsonTimeAndCameraKeyframes) {
  const Scene s = load_json(keyframed_scene());
  EXPECT_EQ(s.time.fps, 25);
  EXPECT_EQ(s.time.shutter_open, -0.25);
  EXPECT_EQ(s.time.shutter_close, 0.25);
  ASSERT_TRUE(s.camera.moves());
  ASSERT_EQ(s.camera.motion.keys().size(), 3u);
  EXPECT_DOUBLE_EQ(s.camera.motion.keys()[1].time, 10.0 / 25);
  EXPECT_DOUBLE_EQ(s.camera.motion.keys()[2].time, 0.8);
  // Halfway between the first two keys the eye is halfway (a translation along x; the look-at
  // rotation turns with it, and the eye is the transform's origin).
  const Vec3 eye = s.camera.motion.at(5.0 / 25).point(Vec3(0.0f));
  EXPECT_NEAR(eye.x, 1.0f, 1e-5f);
  EXPECT_NEAR(eye.z, 5.0f, 1e-5f);
  // Seconds for the shutter: 0.01 s at 25 fps is a quarter of a frame.
  json j = keyframed_scene();
  j["time"]["shutter"] = json::parse(R"({"open": 0, "close": 0.01, "unit": "seconds"})");
  EXPECT_DOUBLE_EQ(load_json(j).time.shutter_close, 0.25);
  // A camera whose keys all agree stands still: no time in its settings.
  j = keyframed_scene();
  for (auto& k : j["camera"]["keyframes"]) k["look_at"] = j["camera"]["keyframes"][0]["look_at"];
  EXPECT_FALSE(load_json(j).camera.moves());
}

TEST(Motion, BadTimeAndKeyframesAreNamed) {
  auto with = [](const char* pointer, const json& value) {
    json j = keyframed_scene();
    j[json::json_pointer(pointer)] = value;
    return j;
  };
  const std::pair<json, std::string> cases[] = {
      {with("/camera/keyframes/1/frame", 30),
       "camera.keyframes[2].time: keys must be in increasing time"},
      {with("/time/shutter/close", -0.5), "time.shutter.close: the shutter closes"},
      {with("/time/shutter/curve", "gaussian"),
       "time.shutter.curve: unknown shutter curve 'gaussian'"},
      {with("/time/shutter/unit", "ticks"), "time.shutter.unit: unknown unit 'ticks'"},
      {with("/time/fps", 0), "time.fps: must be above 0"},
      {with("/camera/keyframes/0/time", 0), "camera.keyframes[0]: give its 'frame' or its 'time'"},
      {with("/camera/keyframes", json::array()), "camera.keyframes: needs at least one key"},
      {with("/camera/look_at", keyframed_scene()["camera"]["keyframes"][0]["look_at"]),
       "camera.keyframes: give the camera's 'keyframes' or one 'look_at'"},
  };
  for (const auto& [scene, expected] : cases) {
    const std::string e = load_error(scene);
    EXPECT_NE(e.find(expected), std::string::npos) << "expected '" << expected << "' in: " << e;
  }
  EXPECT_THROW(check_overrides(SceneOverrides{.shutter = "0.5,0.25"}), SceneError);
  EXPECT_THROW(check_overrides(SceneOverrides{.shutter = "soon"}), SceneError);
}

// light connects each light path to the camera placed at the path's time, bdpt its camera
// sample's light subpath and t = 1 strategies to the camera at the sample's time: on the moving
// camera they agree with path under the harness (4x4 blocks: splats correlate pixels within a
// pass; 16 spp per pass, 32 passes). With every connection made to the camera where it stands
// at the shutter's opening, light fails 95 of the 108 cells and bdpt 75. The smallest bias it
// sees: about 3.5 block standard errors in more than 2 cells, or 1% of an image mean.
TEST(Motion, LightAndBdptAgreeWithPathUnderAMovingCamera) {
  auto with = [](const char* integrator) {
    Scene s = moving_cornell(16, 32);
    s.render.integrator.method = make_integrator(integrator);
    return s;
  };
  const test::ImageStats path = test::render_stats(with("path"), 32, 4);
  for (const char* name : {"light", "bdpt"}) {
    SCOPED_TRACE(name);
    const test::ImageStats other = test::render_stats(with(name), 32, 4);
    const test::Agreement a = test::compare(other, path);
    EXPECT_TRUE(a.passed) << a.message;
    std::printf("%s vs path under the moving camera: %s\n", name, a.message.c_str());
  }
}

}  // namespace
}  // namespace rf
