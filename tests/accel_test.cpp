// Tests of engine/accel: robust ray spawning.
#include "engine/accel.h"

#include <gtest/gtest.h>

#include <cmath>

#include "engine/sampler.h"
#include "engine/sampling.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

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
