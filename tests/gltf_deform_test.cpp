// glTF skins and morph targets (docs/formats/gltf.md, "Skins and morph targets"), on files the
// test writes with known keys: morph weights animated LINEAR, STEP and CUBICSPLINE, still weights,
// a constant weights track, and a two-joint skin with an inverse bind matrix; the deforming
// meshes' vertices at chosen times equal the closed forms, and bad skins are named.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <nlohmann/json.hpp>

#include "engine/scene.h"
#include "tests/support/gltf_file.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

using nlohmann::json;

using File = test::GltfFile;

Scene load_text(const std::string& text) { return test::load_scene_text("scene.gltf", text); }
std::string load_error(const std::string& text) {
  return test::scene_text_error("scene.gltf", text);
}

Vec3 vertex_at(const Mesh& m, double t, size_t v) {
  std::vector<Vec3> p, n;
  deformed_vertices(m, t, p, n);
  return p.at(v);
}

void expect_near(Vec3 got, Vec3 want, float tol, const std::string& what) {
  EXPECT_NEAR(got.x, want.x, tol) << what;
  EXPECT_NEAR(got.y, want.y, tol) << what;
  EXPECT_NEAR(got.z, want.z, tol) << what;
}

// One triangle (0,0,0), (1,0,0), (0,1,0) with two morph targets: target 0 lifts every vertex by
// +z, target 1 moves vertex 1 by +x. Node 0 animates the weights LINEAR over keys 0, 1, 2 s
// ((0,0), (1,0), (1,1)); node 1 STEP ((0,0) then (1,0) at 1 s); node 2 CUBICSPLINE (weight 0 from
// 0 to 1 with out-tangent 3 at the start); node 3 has still weights (0.5, 0); node 4's track holds
// (0.25, 0) at every key.
File morph_file() {
  File f;
  const size_t pos = f.floats({0, 0, 0, 1, 0, 0, 0, 1, 0}, "VEC3");
  const size_t t0 = f.floats({0, 0, 1, 0, 0, 1, 0, 0, 1}, "VEC3");
  const size_t t1 = f.floats({0, 0, 0, 1, 0, 0, 0, 0, 0}, "VEC3");
  f.j["meshes"].push_back({{"primitives",
                            {{{"attributes", {{"POSITION", pos}}},
                              {"targets", {{{"POSITION", t0}}, {{"POSITION", t1}}}}}}},
                           {"weights", {0, 0}}});
  for (int i = 0; i < 5; ++i) f.node({{"mesh", 0}});
  f.j["nodes"][3]["weights"] = {0.5, 0};
  f.channel(0, "weights", "LINEAR", {0, 1, 2}, {0, 0, 1, 0, 1, 1});
  f.channel(1, "weights", "STEP", {0, 1}, {0, 0, 1, 0});
  // (in-tangents, values, out-tangents) per key, two weights each.
  f.channel(2, "weights", "CUBICSPLINE", {0, 1}, {0, 0, 0, 0, 3, 0, 0, 0, 1, 0, 0, 0});
  f.channel(4, "weights", "LINEAR", {0, 1, 2}, {0.25f, 0, 0.25f, 0, 0.25f, 0});
  return f;
}

TEST(GltfDeform, MorphWeightsEvaluateToTheirClosedForms) {
  const Scene s = load_text(morph_file().text());
  ASSERT_EQ(s.meshes.size(), 5u);  // one world mesh per placing node, in node order
  constexpr float kTol = 1e-6f;
  const Mesh &linear = s.meshes[0], &step = s.meshes[1], &cubic = s.meshes[2], &still = s.meshes[3],
             &held = s.meshes[4];
  // LINEAR: keys at the weights' keys only (vertices are linear in the weights).
  ASSERT_TRUE(linear.deforms());
  ASSERT_EQ(linear.deform.size(), 3u);
  expect_near(vertex_at(linear, 0.5, 0), {0, 0, 0.5f}, kTol, "linear 0.5");
  expect_near(vertex_at(linear, 1.5, 1), {1.5f, 0, 1}, kTol, "linear 1.5");
  expect_near(vertex_at(linear, 5.0, 1), {2, 0, 1}, kTol, "linear after the last key");
  // STEP: the key's value until the next key (held to kStepHold before it).
  ASSERT_TRUE(step.deforms());
  expect_near(vertex_at(step, 0.5, 0), {0, 0, 0}, kTol, "step 0.5");
  expect_near(vertex_at(step, 0.999, 0), {0, 0, 0}, kTol, "step 0.999");
  expect_near(vertex_at(step, 1.0, 0), {0, 0, 1}, kTol, "step 1");
  // CUBICSPLINE: w(u) = 3 h10(u) + h01(u) = u^3 - 3u^2 + 3u, sampled at kSplineSteps steps: at
  // u = 0.25 (a sample) 0.578125.
  ASSERT_TRUE(cubic.deforms());
  EXPECT_EQ(cubic.deform.size(), 9u);
  expect_near(vertex_at(cubic, 0.25, 0), {0, 0, 0.578125f}, kTol, "cubic 0.25");
  // Still weights: the morphed shape, not deforming; a constant track collapses to still too.
  EXPECT_FALSE(still.deforms());
  expect_near(still.positions[2], {0, 1, 0.5f}, kTol, "still weights");
  EXPECT_FALSE(held.deforms());
  expect_near(held.positions[0], {0, 0, 0.25f}, kTol, "constant track");
  EXPECT_TRUE(geometry_moves(s));
}

// A skin of two joints: node 0 (joint 0) at the origin; node 1 (joint 1), its child at (0, 1, 0),
// turning a quarter about +z over [0, 1] s (LINEAR), with the inverse bind matrix translate(0, -1,
// 0). The skinned mesh (node 2, whose own translation the spec says to ignore) has vertex 0 at
// (1, 1, 0) on joint 1, vertex 1 at the origin on joint 0, vertex 2 at (0, 2, 0) half on each.
File skin_file(uint16_t joint_of_vertex0 = 1) {
  File f;
  const size_t pos = f.floats({1, 1, 0, 0, 0, 0, 0, 2, 0}, "VEC3");
  const size_t joints = f.ushorts({joint_of_vertex0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0});
  const size_t weights = f.floats({1, 0, 0, 0, 1, 0, 0, 0, 0.5f, 0.5f, 0, 0}, "VEC4");
  f.j["meshes"].push_back(
      {{"primitives",
        {{{"attributes", {{"POSITION", pos}, {"JOINTS_0", joints}, {"WEIGHTS_0", weights}}}}}}});
  f.node({{"children", {1}}});
  f.node({{"translation", {0, 1, 0}}});
  f.node({{"mesh", 0}, {"skin", 0}, {"translation", {5, 0, 0}}});
  const size_t ibm = f.floats({1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0,  0, 1,  //
                               1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, -1, 0, 1},
                              "MAT4");
  f.j["skins"] = {{{"joints", {0, 1}}, {"inverseBindMatrices", ibm}}};
  f.j["scenes"] = {{{"nodes", {0, 2}}}};
  const float s = float(std::sqrt(0.5));
  f.channel(1, "rotation", "LINEAR", {0, 1}, {0, 0, 0, 1, 0, 0, s, s});
  return f;
}

TEST(GltfDeform, SkinnedVerticesFollowTheirJoints) {
  const Scene s = load_text(skin_file().text());
  ASSERT_EQ(s.meshes.size(), 1u);
  const Mesh& m = s.meshes[0];
  ASSERT_TRUE(m.deforms());
  // The joint's quarter turn is cut into 2^k steps (its rotation baked into vertices, the chord
  // within 1e-4 of the track's size: linear_sample_times).
  const size_t steps = m.deform.size() - 1;
  EXPECT_GE(steps, 32u);
  EXPECT_LE(steps, size_t(kMaxLinearSteps));
  EXPECT_EQ(steps & (steps - 1), 0u);
  constexpr float kTol = 1e-5f;
  const float c = float(std::sqrt(0.5));
  // At rest the mesh is where it was modelled (the node's own translation ignored).
  expect_near(vertex_at(m, 0.0, 0), {1, 1, 0}, kTol, "rest");
  // Vertex 0 turns about joint 1's origin (0, 1, 0): 45 degrees at 0.5 s, 90 at 1 s.
  expect_near(vertex_at(m, 0.5, 0), {c, 1 + c, 0}, kTol, "vertex 0 at 0.5 s");
  expect_near(vertex_at(m, 1.0, 0), {0, 2, 0}, kTol, "vertex 0 at 1 s");
  expect_near(vertex_at(m, 0.5, 1), {0, 0, 0}, kTol, "vertex 1 on the still joint");
  // Vertex 2 is half on each joint: (0, 2, 0) on the still one, (-sin, 1 + cos, 0) on the
  // turning one at its angle.
  expect_near(vertex_at(m, 0.5, 2), {-0.5f * c, 0.5f * (2 + 1 + c), 0}, kTol, "vertex 2 at 0.5 s");
  // Between keys the vertex moves on the chord: halfway between the first two keys it is
  // cos(a / 2) from the pivot, a = (pi / 2) / steps the turn between keys.
  const Vec3 mid = vertex_at(m, 0.5 / double(steps), 0) - Vec3(0, 1, 0);
  EXPECT_NEAR(length(mid), std::cos(0.25 * kPi / double(steps)), 2e-6);
}

TEST(GltfDeform, BadSkinsAndWeightsAreNamed) {
  std::string e = load_error(skin_file(/*joint_of_vertex0=*/5).text());
  EXPECT_NE(e.find("/meshes/0/primitives/0/attributes/JOINTS_0: vertex 0: joint index 5 is out "
                   "of range (the skin has 2 joints)"),
            std::string::npos)
      << e;
  File f = skin_file();
  f.j["skins"][0]["joints"] = {0, 7};
  e = load_error(f.text());
  EXPECT_NE(e.find("/skins/0/joints/1: node 7 does not exist"), std::string::npos) << e;
  f = skin_file();
  f.j["nodes"][2]["skin"] = 3;
  e = load_error(f.text());
  EXPECT_NE(e.find("/nodes/2/skin: skin 3 does not exist"), std::string::npos) << e;
  // A weights channel on a node whose mesh has no morph targets.
  f = skin_file();
  f.channel(2, "weights", "LINEAR", {0, 1}, {0, 1});
  e = load_error(f.text());
  EXPECT_NE(e.find("/animations/0/channels/1/target/node: the channel animates the morph weights "
                   "of node 2, whose mesh has no morph targets"),
            std::string::npos)
      << e;
  // A weights channel with too few values for the mesh's two targets.
  f = morph_file();
  f.j["animations"][0]["samplers"][0]["output"] = f.floats({0, 1, 2}, "SCALAR");
  e = load_error(f.text());
  EXPECT_NE(e.find("/animations/0/samplers/0/output"), std::string::npos) << e;
}

}  // namespace
}  // namespace rf
