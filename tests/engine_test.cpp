// Unit checks of the engine's building blocks: sampler, light selection, robust ray spawning.
#include <gtest/gtest.h>

#include <cmath>

#include "engine/accel.h"
#include "engine/lights.h"
#include "engine/sampler.h"
#include "engine/sampling.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

TEST(Sampler, IsAPureFunctionOfItsKey) {
  IndependentSampler a, b;
  a.start_camera_sample(1, 2, 3, 4, 5, 6);
  b.start_camera_sample(1, 2, 3, 4, 5, 6);
  for (int i = 0; i < 32; ++i) EXPECT_EQ(a.get_1d(), b.get_1d());
  // Any key component changes the stream.
  b.start_camera_sample(1, 2, 3, 5, 4, 6);
  a.start_camera_sample(1, 2, 3, 4, 5, 6);
  EXPECT_NE(a.get_1d(), b.get_1d());
}

TEST(Sampler, UniformAndUncorrelatedAcrossDimensionsAndPixels) {
  // n = 2^20 values: the mean of U(0,1) has sd 1/sqrt(12 n) = 2.8e-4; allow 5 sd (false failure
  // ~6e-7). Correlation between consecutive dimensions / neighbouring pixels: sd 1/sqrt(n)
  // ~ 1e-3; allow 5e-3.
  const int n = 1 << 20;
  double sum = 0, sum_xy = 0, sum_pix = 0;
  IndependentSampler s, t;
  for (int i = 0; i < n; ++i) {
    s.start_camera_sample(9, 0, 0, i % 1024, i / 1024, 0);
    t.start_camera_sample(9, 0, 0, i % 1024 + 1, i / 1024, 0);
    double x = s.get_1d(), y = s.get_1d(), z = t.get_1d();
    sum += x;
    sum_xy += (x - 0.5) * (y - 0.5);
    sum_pix += (x - 0.5) * (z - 0.5);
  }
  EXPECT_NEAR(sum / n, 0.5, 5 * std::sqrt(1.0 / 12 / n));
  EXPECT_NEAR(12 * sum_xy / n, 0.0, 5e-3);
  EXPECT_NEAR(12 * sum_pix / n, 0.0, 5e-3);
}

Scene two_light_scene() {
  Material m{"m", MaterialType::Diffuse, {RGB(0.5f)}};
  Mesh a = test::make_uv_sphere({-2, 0, 0}, 0.5f, 6, 12, 0);
  a.emission = Emission{RGB(4, 1, 1), false};
  Mesh b = test::make_uv_sphere({2, 0, 0}, 1.0f, 6, 12, 0);
  b.emission = Emission{RGB(1, 1, 1), true};
  Mesh c = test::make_uv_sphere({0, 3, 0}, 1.0f, 4, 8, 0);  // not a light
  return test::make_scene({m}, {a, b, c}, {0, 0, 8}, {0, 0, 0}, 8, 8, "lights");
}

TEST(Lights, SelectionProbabilitiesSumToOneAndFollowPower) {
  Scene s = two_light_scene();
  LightSet lights(s);
  ASSERT_EQ(lights.size(), s.meshes[0].triangle_count() + s.meshes[1].triangle_count());
  double total = 0;
  for (size_t i = 0; i < lights.size(); ++i) total += lights.selection_pmf(i);
  EXPECT_NEAR(total, 1.0, 1e-5);  // float pmfs of ~130 lights: rounding only
}

TEST(Lights, SampledPdfEqualsPdfQuery) {
  Scene s = two_light_scene();
  Accel accel(s);
  LightSet lights(s);
  IndependentSampler smp;
  Vec3 p{0, 0, 0};
  int checked = 0;
  for (int i = 0; i < 2000; ++i) {
    smp.start_light_path(1, 0, 0, uint64_t(i));
    LightSample ls;
    if (!lights.sample(p, smp.get_1d(), smp.get_2d(), ls)) continue;
    // Find which triangle the sample lies on by tracing towards it.
    SurfaceHit hit;
    ASSERT_TRUE(accel.intersect(Ray{p, ls.wi, kInf}, hit));
    if (std::fabs(hit.t - ls.distance) > 1e-3f * ls.distance) continue;  // occluded by the sphere itself
    float q = lights.pdf_solid_angle(p, hit.mesh, hit.prim, hit.p, hit.ng);
    EXPECT_NEAR(q, ls.pdf_solid_angle, 1e-3f * ls.pdf_solid_angle);
    ++checked;
  }
  EXPECT_GT(checked, 500);
}

TEST(Accel, SpawnedRaysDoNotHitTheirOwnSurfaceFarFromTheOrigin) {
  // A big tilted quad far from the origin: with a fixed epsilon, rounding error at |p| ~ 1e4
  // makes spawned rays re-hit the surface; the error-bound offset must not.
  Material m{"m", MaterialType::Diffuse, {RGB(0.5f)}};
  Mesh quad;
  quad.material = 0;
  Mat4 xf = Mat4::translate({1e4f, 2e4f, -3e4f}) * Mat4::rotate({1, 1, 0}, 37) * Mat4::scale(Vec3(500));
  for (Vec3 p : {Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(-1, 1, 0)}) quad.positions.push_back(xf.point(p));
  quad.indices = {0, 1, 2, 0, 2, 3};
  Scene s = test::make_scene({m}, {quad}, {0, 0, 0}, {0, 0, -1}, 4, 4, "far");
  Accel accel(s);
  Vec3 n = normalize(xf.normal({0, 0, 1}));
  IndependentSampler smp;
  int self_hits = 0, hits = 0;
  for (int i = 0; i < 20000; ++i) {
    smp.start_light_path(3, 0, 0, uint64_t(i));
    Vec2 u = smp.get_2d();
    Vec3 target = xf.point({1.6f * u.x - 0.8f, 1.6f * u.y - 0.8f, 0});
    Vec3 o = target + n * 100.0f;
    SurfaceHit hit;
    if (!accel.intersect(Ray{o, normalize(target - o), kInf}, hit)) continue;
    ++hits;
    Frame f = Frame::from_normal(dot(hit.ng, n) > 0 ? hit.ng : -hit.ng);
    Vec3 w = f.to_world(sample_cosine_hemisphere(smp.get_2d()));
    SurfaceHit again;
    if (accel.intersect(accel.spawn(hit, w), again)) ++self_hits;
  }
  EXPECT_GT(hits, 19000);
  EXPECT_EQ(self_hits, 0);
}

}  // namespace
}  // namespace rf
