// glTF node animations (docs/formats/gltf.md, "Animations"), on a file the test writes with
// known keyframes: LINEAR translation and rotation, STEP rotation, CUBICSPLINE translation, a
// track that does not move, an animated parent; the world transforms at chosen times equal the
// closed forms, a track that does not move stays static geometry, and bad channels are named.
#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>

#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/gltf_file.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

using nlohmann::json;

using AnimatedFile = test::GltfFile;

// A glTF with one triangle mesh (mesh 0) for nodes to place.
AnimatedFile triangle_file() {
  AnimatedFile f;
  const size_t pos = f.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3");
  f.j["meshes"].push_back({{"primitives", {{{"attributes", {{"POSITION", pos}}}}}}});
  return f;
}

const float kS = float(std::sqrt(0.5));  // sin and cos of 45 degrees

// The file of the tests: node 0 slides (LINEAR), node 1 turns a quarter about +y (LINEAR), node 2
// snaps a quarter turn at t = 1 (STEP), node 3 follows a cubic (CUBICSPLINE), node 4's track
// holds one value, node 5 is a child of node 0 (moved by its parent).
AnimatedFile animated_file() {
  AnimatedFile f = triangle_file();
  for (int i = 0; i < 5; ++i) f.node({{"mesh", 0}});
  f.node({{"mesh", 0}, {"translation", {0, 0, 5}}});
  f.j["nodes"][0]["children"] = {5};
  f.j["scenes"] = {{{"nodes", {0, 1, 2, 3, 4}}}};
  f.channel(0, "translation", "LINEAR", {0, 1, 2}, {0, 0, 0, 1, 0, 0, 1, 2, 0});
  f.channel(1, "rotation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, kS, 0, kS});
  f.channel(2, "rotation", "STEP", {0, 1}, {0, 0, 0, 1, 0, kS, 0, kS});
  // x(u) from 0 to 1 over [0, 1], out-tangent 3 at the start, in-tangent 0 at the end:
  // (in, value, out) per key.
  f.channel(3, "translation", "CUBICSPLINE", {0, 1},
            {0, 0, 0, 0, 0, 0, 3, 0, 0,  //
             0, 0, 0, 1, 0, 0, 0, 0, 0});
  f.channel(4, "translation", "LINEAR", {0, 1, 2}, {2, 0, 0, 2, 0, 0, 2, 0, 0});
  return f;
}

Scene load_text(const std::string& text) { return test::load_scene_text("scene.gltf", text); }
std::string load_error(const std::string& text) {
  return test::scene_text_error("scene.gltf", text);
}

// The instance placing node n's mesh (objects are made in mesh order, instances in node order).
const Instance& placed_by(const Scene& s, size_t k) { return s.instances.at(k); }

void expect_point(const Mat4& m, Vec3 p, Vec3 want, float tol, const char* what) {
  const Vec3 got = m.point(p);
  EXPECT_NEAR(got.x, want.x, tol) << what;
  EXPECT_NEAR(got.y, want.y, tol) << what;
  EXPECT_NEAR(got.z, want.z, tol) << what;
}

TEST(GltfAnimation, KeyframesEvaluateToTheirClosedForms) {
  const Scene s = load_text(animated_file().text());
  // One mesh placed by six nodes: an object and six instances, node order 0, 5, 1, 2, 3, 4.
  ASSERT_EQ(s.objects.size(), 1u);
  ASSERT_EQ(s.instances.size(), 6u);
  const Instance &slide = placed_by(s, 0), &child = placed_by(s, 1), &turn = placed_by(s, 2),
                 &snap = placed_by(s, 3), &cubic = placed_by(s, 4), &still = placed_by(s, 5);
  constexpr float kTol = 1e-5f;
  // LINEAR translation: (t, 0, 0) then (1, t - 1, 0)... at t in [1, 2]: (1, 2 (t - 1), 0).
  ASSERT_TRUE(slide.moves());
  expect_point(slide.motion.at(0.5), {0, 0, 0}, {0.5f, 0, 0}, kTol, "slide 0.5");
  expect_point(slide.motion.at(1.5), {0, 0, 0}, {1, 1, 0}, kTol, "slide 1.5");
  expect_point(slide.motion.at(3.0), {0, 0, 0}, {1, 2, 0}, kTol, "slide after the last key");
  // The child rides on its parent: (0, 0, 5) + the parent's translation.
  ASSERT_TRUE(child.moves());
  expect_point(child.motion.at(1.5), {0, 0, 0}, {1, 1, 5}, kTol, "child 1.5");
  // LINEAR rotation: a slerp, 45 degrees about +y at t = 0.5 (x axis to (cos, 0, -sin)).
  ASSERT_TRUE(turn.moves());
  expect_point(turn.motion.at(0.5), {1, 0, 0}, {kS, 0, -kS}, kTol, "turn 0.5");
  // STEP: the first key's rotation until t = 1, then the second's.
  ASSERT_TRUE(snap.moves());
  expect_point(snap.motion.at(0.5), {1, 0, 0}, {1, 0, 0}, kTol, "snap 0.5");
  expect_point(snap.motion.at(0.999), {1, 0, 0}, {1, 0, 0}, kTol, "snap 0.999");
  expect_point(snap.motion.at(1.0), {1, 0, 0}, {0, 0, -1}, kTol, "snap 1");
  // CUBICSPLINE: x(u) = 3 (u^3 - 2u^2 + u) + (3u^2 - 2u^3); at the sampled u = 0.25 and 0.5 the
  // closed form (0.578125, 0.875), and between samples within the linear interpolation of the
  // 8 steps per segment (|x''| <= 6 here: error <= 6 / 8 (1/8)^2... below 0.012).
  ASSERT_TRUE(cubic.moves());
  auto x = [](double u) { return 3 * (u * u * u - 2 * u * u + u) + (3 * u * u - 2 * u * u * u); };
  expect_point(cubic.motion.at(0.25), {0, 0, 0}, {float(x(0.25)), 0, 0}, kTol, "cubic 0.25");
  expect_point(cubic.motion.at(0.5), {0, 0, 0}, {float(x(0.5)), 0, 0}, kTol, "cubic 0.5");
  expect_point(cubic.motion.at(0.3), {0, 0, 0}, {float(x(0.3)), 0, 0}, 0.012f, "cubic 0.3");
  // A track that holds one value collapses to a static placement.
  EXPECT_FALSE(still.moves());
  expect_point(still.to_world, {0, 0, 0}, {2, 0, 0}, kTol, "still");
  EXPECT_TRUE(geometry_moves(s));
}

// A STEP track whose keys are closer than a float's step at the hold time: the hold just before
// the last key (t1 - 1e-6 of the gap) rounds to the key as a float. It holds the first value
// (the fuzzer found it reading past the keys; under ASan this test fails without the fix).
TEST(GltfAnimation, AStepHoldJustBeforeTheLastKeyHoldsTheFirstValue) {
  AnimatedFile f = triangle_file();
  f.node({{"mesh", 0}});
  f.j["scenes"] = {{{"nodes", {0}}}};
  f.channel(0, "translation", "STEP", {1.0f, 1.001f}, {0, 0, 0, 4, 0, 0});
  const Scene s = load_text(f.text());
  ASSERT_EQ(s.instances.size(), 1u);
  const Instance& step = s.instances[0];
  ASSERT_TRUE(step.moves());
  const double t1 = double(1.001f), hold = t1 - 1e-6 * (t1 - 1.0);
  ASSERT_EQ(float(hold), 1.001f) << "the case needs a hold that rounds to the key";
  expect_point(step.motion.at(hold), {0, 0, 0}, {0, 0, 0}, 1e-5f, "just before the last key");
  expect_point(step.motion.at(t1), {0, 0, 0}, {4, 0, 0}, 1e-5f, "at the last key");
}

// A mesh placed once by a node whose track does not move is static world geometry, as without
// the animation: the importer collapses the constant track.
TEST(GltfAnimation, AConstantTrackStaysStaticGeometry) {
  AnimatedFile f = triangle_file();
  f.node({{"mesh", 0}});
  f.j["scenes"] = {{{"nodes", {0}}}};
  f.channel(0, "translation", "LINEAR", {0, 1}, {2, 0, 0, 2, 0, 0});
  const Scene s = load_text(f.text());
  EXPECT_TRUE(s.instances.empty());
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_FLOAT_EQ(s.meshes[0].positions[1].x, 3.0f);
  EXPECT_FALSE(geometry_moves(s));
}

TEST(GltfAnimation, ItRendersWithMotionBlur) {
  AnimatedFile f = animated_file();
  f.j["cameras"] = {{{"type", "perspective"}, {"perspective", {{"yfov", 1.0}, {"znear", 0.1}}}}};
  f.j["nodes"].push_back({{"camera", 0}, {"translation", {0.5, 0.5, 12}}});
  f.j["scenes"][0]["nodes"].push_back(f.j["nodes"].size() - 1);
  SceneOverrides o;
  o.width = o.height = 16, o.spp = 4, o.passes = 1;
  const Scene s = test::load_scene_text("scene.gltf", f.text(), o);
  Renderer r(s);
  const Rect frame{0, 0, 16, 16};
  EXPECT_NE(r.render(TaskKey{6, frame, 0}, true).sum, r.render(TaskKey{30, frame, 0}, true).sum);
}

TEST(GltfAnimation, BadChannelsAreNamed) {
  AnimatedFile f = animated_file();
  f.j["animations"][0]["channels"][1]["target"]["node"] = 99;
  EXPECT_NE(load_error(f.text()).find(
                "/animations/0/channels/1/target/node: the channel's node 99 does not exist"),
            std::string::npos)
      << load_error(f.text());
  f = animated_file();
  f.j["animations"][0]["channels"][0]["sampler"] = 42;
  EXPECT_NE(
      load_error(f.text()).find("/animations/0/channels/0/sampler: sampler 42 does not exist"),
      std::string::npos)
      << load_error(f.text());
  f = animated_file();
  f.j["animations"][0]["samplers"][1]["interpolation"] = "BEZIER";
  EXPECT_NE(load_error(f.text()).find("/animations/0/samplers/1/interpolation: unknown"),
            std::string::npos)
      << load_error(f.text());
  f = animated_file();  // key times out of order
  {
    const size_t in = f.floats({0, 2, 1}, "SCALAR");
    f.j["animations"][0]["samplers"][0]["input"] = in;
  }
  EXPECT_NE(load_error(f.text()).find("/animations/0/samplers/0/input: key times must be finite "
                                      "and increasing: key 2"),
            std::string::npos)
      << load_error(f.text());
  f = animated_file();  // three values for two keys
  f.j["animations"][0]["samplers"][1]["input"] = f.j["animations"][0]["samplers"][2]["input"];
  f.j["animations"][0]["samplers"][1]["output"] = f.j["animations"][0]["samplers"][0]["output"];
  EXPECT_NE(load_error(f.text()).find("/animations/0/samplers/1/output"), std::string::npos)
      << load_error(f.text());
  f = animated_file();  // an animated node with a matrix
  f.j["nodes"][1]["matrix"] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  EXPECT_NE(
      load_error(f.text()).find("/animations/0/channels/1/target/node: node 1 has a 'matrix'"),
      std::string::npos)
      << load_error(f.text());
  // Morph-target weights on a node whose mesh has no targets (tests/gltf_deform_test.cpp has
  // the ones that animate).
  f = animated_file();
  f.channel(4, "rotation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0, 0, 1});
  f.j["animations"][0]["channels"].back()["target"]["path"] = "weights";
  EXPECT_NE(load_error(f.text()).find("/animations/0/channels/5/target/node: the channel animates "
                                      "the morph weights of node 4, whose mesh has no morph "
                                      "targets"),
            std::string::npos)
      << load_error(f.text());
}

}  // namespace
}  // namespace rf
