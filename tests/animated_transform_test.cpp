// Keyframed transforms (engine/animated_transform.h): decomposition round trips, interpolation
// against closed forms (translation and scale linear, rotation by the shorter arc at constant
// angular speed, no shrinking), keys returned bit for bit, clamping, static tracks collapsing,
// and bad keys named.
#include "engine/animated_transform.h"

#include <gtest/gtest.h>

#include <cmath>

namespace rf {
namespace {

// Within 1e-5 of each entry: the matrices are float; the decomposition is double.
void expect_near(const Mat4& a, const Mat4& b, float tol = 1e-5f) {
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) EXPECT_NEAR(a.m[i][j], b.m[i][j], tol) << "entry " << i << j;
}

TEST(AnimatedTransform, DecomposeComposeRoundTrips) {
  const Mat4 trs =
      ((Mat4::translate({1, -2, 3}) * Mat4::rotate({1, 2, 0.5f}, 70)) * Mat4::scale({2, 0.5f, 3}));
  expect_near(compose(decompose(trs)), trs);
  // A reflection (negative determinant) and a shear come back too.
  Mat4 odd = Mat4::scale({-1, 2, 1});
  odd.m[0][1] = 0.3f;
  expect_near(compose(decompose(odd)), odd);
  // The rotation part is a rotation: its quaternion has unit length and S is symmetric.
  const DecomposedTransform d = decompose(trs);
  EXPECT_NEAR(d.r.w * d.r.w + d.r.x * d.r.x + d.r.y * d.r.y + d.r.z * d.r.z, 1.0, 1e-12);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(d.s[i][j], d.s[j][i], 1e-6);
  Mat4 projective;
  projective.m[3][2] = 1;
  EXPECT_THROW(decompose(projective), std::domain_error);
  EXPECT_THROW(decompose(Mat4::scale({1, 0, 1})), std::domain_error);
}

TEST(AnimatedTransform, InterpolatesAsClosedForms) {
  // Translation and scale: linear.
  AnimatedTransform move({{0.0, Mat4::translate({0, 0, 0})}, {2.0, Mat4::translate({4, -2, 8})}});
  EXPECT_TRUE(move.animated());
  expect_near(move.at(0.5), Mat4::translate({1, -0.5f, 2}));
  AnimatedTransform grow({{0.0, Mat4::scale({1, 1, 1})}, {1.0, Mat4::scale({3, 1, 5})}});
  expect_near(grow.at(0.5), Mat4::scale({2, 1, 3}));
  // Rotation: constant angular speed about the axis, as a rotation (no shrinking: interpolating
  // the matrices would give cos 45 deg scale at the midpoint of a 90 degree turn).
  AnimatedTransform spin({{0.0, Mat4::rotate({0, 0, 1}, 0)}, {1.0, Mat4::rotate({0, 0, 1}, 90)}});
  for (double t : {0.25, 0.5, 0.8}) expect_near(spin.at(t), Mat4::rotate({0, 0, 1}, float(90 * t)));
  const Vec3 x = spin.at(0.5).vector({1, 0, 0});
  EXPECT_NEAR(length(x), 1.0f, 1e-6f);
  // The shorter arc: from +170 to -170 degrees is a 20 degree turn through 180.
  AnimatedTransform wrap(
      {{0.0, Mat4::rotate({0, 1, 0}, 170)}, {1.0, Mat4::rotate({0, 1, 0}, -170)}});
  expect_near(wrap.at(0.5), Mat4::rotate({0, 1, 0}, 180));
  // ... and from 0 to 200 degrees is a 160 degree turn the other way (the two keys' quaternions
  // come out of the decomposition on opposite hemispheres: slerp must flip one).
  AnimatedTransform back({{0.0, Mat4::rotate({0, 0, 1}, 0)}, {1.0, Mat4::rotate({0, 0, 1}, 200)}});
  expect_near(back.at(0.5), Mat4::rotate({0, 0, 1}, -80));
  // Translation, rotation and scale together: each part by its own rule.
  auto trs = [](float tx, float deg, float s) {
    return ((Mat4::translate({tx, 0, 0}) * Mat4::rotate({1, 0, 0}, deg)) * Mat4::scale({s, s, s}));
  };
  AnimatedTransform all({{1.0, trs(0, 0, 1)}, {3.0, trs(10, 60, 2)}});
  expect_near(all.at(2.0), trs(5, 30, 1.5f));
  // Three keys: each segment by its own pair.
  AnimatedTransform path({{0.0, Mat4::translate({0, 0, 0})},
                          {1.0, Mat4::translate({1, 0, 0})},
                          {3.0, Mat4::translate({1, 4, 0})}});
  expect_near(path.at(0.5), Mat4::translate({0.5f, 0, 0}));
  expect_near(path.at(2.0), Mat4::translate({1, 2, 0}));
}

TEST(AnimatedTransform, KeysAreExactAndTheEndsClamp) {
  const Mat4 a = (Mat4::translate({0.1f, 0.2f, 0.3f}) * Mat4::rotate({1, 1, 0}, 33));
  const Mat4 b = (Mat4::translate({7, 0, -1}) * Mat4::rotate({0, 1, 1}, -71));
  AnimatedTransform t({{-1.0, a}, {0.5, b}, {2.0, a}});
  auto same = [](const Mat4& x, const Mat4& y) {
    for (int i = 0; i < 4; ++i)
      for (int j = 0; j < 4; ++j)
        if (x.m[i][j] != y.m[i][j]) return false;
    return true;
  };
  EXPECT_TRUE(same(t.at(-1.0), a));
  EXPECT_TRUE(same(t.at(0.5), b));
  EXPECT_TRUE(same(t.at(2.0), a));
  EXPECT_TRUE(same(t.at(-5.0), a));  // before the first key: the first
  EXPECT_TRUE(same(t.at(9.0), a));   // after the last: the last
  // A track that does not move is one static key.
  AnimatedTransform still({{0.0, b}, {1.0, b}, {4.0, b}});
  EXPECT_FALSE(still.animated());
  EXPECT_EQ(still.keys().size(), 1u);
  EXPECT_TRUE(same(still.at(0.7), b));
  // A held key stays: the transform holds still between equal neighbours, then moves.
  AnimatedTransform hold({{0.0, a}, {1.0, a}, {2.0, b}});
  EXPECT_TRUE(hold.animated());
  EXPECT_TRUE(same(hold.at(0.6), a));
}

TEST(AnimatedTransform, BadKeysAreNamed) {
  auto message = [](std::vector<Keyframe> keys) {
    try {
      AnimatedTransform t(std::move(keys));
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message({{1.0, Mat4{}}, {1.0, Mat4::translate({1, 0, 0})}}).find("key 1 (time 1)"),
            std::string::npos);
  EXPECT_NE(message({{2.0, Mat4{}}, {1.0, Mat4::translate({1, 0, 0})}}).find("must increase"),
            std::string::npos);
  EXPECT_NE(message({{0.0, Mat4{}}, {1.0, Mat4::scale({0, 1, 1})}})
                .find("key 1 (time 1): the "
                      "matrix is singular"),
            std::string::npos);
  EXPECT_NE(message({{0.0, Mat4{}}, {NAN, Mat4{}}}).find("not finite"), std::string::npos);
  EXPECT_NE(message({}).find("at least one key"), std::string::npos);
}

}  // namespace
}  // namespace rf
