// Tests of engine/accel: robust ray spawning.
#include "engine/accel.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <limits>
#include <string>

#include "engine/build_info.h"
#include "engine/sampler.h"
#include "engine/sampling.h"
#include "engine/shapes.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

TEST(Accel, SpawnedRaysDoNotHitTheirOwnSurfaceFarFromTheOrigin) {
  // A big tilted quad far from the origin: with a fixed epsilon, rounding error at |p| ~ 1e4
  // makes spawned rays re-hit the surface; the error-bound offset must not.
  Material m{"m", MaterialType::Diffuse, {RGB(0.5f)}};
  Mesh quad;
  quad.material = 0;
  Mat4 xf =
      Mat4::translate({1e4f, 2e4f, -3e4f}) * Mat4::rotate({1, 1, 0}, 37) * Mat4::scale(Vec3(500));
  for (Vec3 p : {Vec3(-1, -1, 0), Vec3(1, -1, 0), Vec3(1, 1, 0), Vec3(-1, 1, 0)})
    quad.positions.push_back(xf.point(p));
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

// Exact spheres (Embree's sphere primitive): hits at the analytic distance with the outward
// normal, make_sphere's uv, and rays spawned from either side (reflection outside, transmission
// inside) never re-hit their own surface at the origin of the next ray, also far from the origin
// and under an instance.
SphereShape test_sphere(Vec3 c, float r) {
  SphereShape s;
  s.center = c;
  s.radius = r;
  return s;
}

void check_sphere_hits(const Accel& accel, const SphereShape& s, uint64_t seed) {
  IndependentSampler smp;
  int hits = 0, self_hits = 0;
  for (int i = 0; i < 20000; ++i) {
    smp.start_light_path(seed, 0, 0, uint64_t(i));
    Vec3 target_n = sample_uniform_sphere(smp.get_2d());
    Vec3 o =
        s.center + target_n * (s.radius * 3.0f) + sample_uniform_sphere(smp.get_2d()) * s.radius;
    Vec3 d = normalize(s.center + target_n * s.radius * 0.5f - o);
    SurfaceHit hit;
    ASSERT_TRUE(accel.intersect(Ray{o, d, kInf}, hit)) << i;
    ++hits;
    // Analytic nearest root of |o + t d - c| = r.
    Vec3 oc = o - s.center;
    double b = dot(oc, d), c = double(dot(oc, oc)) - double(s.radius) * s.radius;
    double t = -b - std::sqrt(b * b - c);
    EXPECT_NEAR(hit.t, t, 1e-4 * (t + s.radius)) << i;
    EXPECT_NEAR(length(hit.p - s.center), s.radius, 1e-5f * (s.radius + length(s.center)));
    EXPECT_GT(dot(hit.ng, hit.p - s.center), 0.999f * s.radius);
    EXPECT_LT(dot(hit.ng, d), 0);
    // Reflected: leaves outwards; transmitted: goes inside and must hit the far side.
    Frame f = Frame::from_normal(hit.ng);
    Vec3 out = f.to_world(sample_cosine_hemisphere(smp.get_2d()));
    SurfaceHit again;
    if (accel.intersect(accel.spawn(hit, out), again)) ++self_hits;
    Vec3 in = -f.to_world(sample_cosine_hemisphere(smp.get_2d()));
    ASSERT_TRUE(accel.intersect(accel.spawn(hit, in), again)) << i;
    EXPECT_GT(again.t, 1e-3f * s.radius) << i;
  }
  EXPECT_EQ(hits, 20000);
  EXPECT_EQ(self_hits, 0);
}

// The benchmark's packet query (Accel::cast8) answers like the single-ray one, for full and
// partial packets (lanes past n unused), hits and misses: a triangle quad and an exact sphere.
// The square [-1, 1]^2 at z = -3, material 0: what rays from the origin towards -z hit.
Mesh quad_facing_origin() {
  Mesh quad;
  quad.material = 0;
  quad.positions = {{-1, -1, -3}, {1, -1, -3}, {1, 1, -3}, {-1, 1, -3}};
  quad.indices = {0, 1, 2, 0, 2, 3};
  return quad;
}

// Hit or miss must agree exactly; t within 1e-5 relative, because Embree's packet kernel for
// spheres rounds differently from its single-ray one (about 1 in 8 sphere hits differ in the
// last bits here; triangles agree bit for bit), while a wrong lane or component is off by far
// more. The counts of exact differences are printed, not asserted: they depend on Embree's ISA.
TEST(Accel, PacketCastsEqualSingleCasts) {
  Material m{"m", MaterialType::Diffuse, {RGB(0.5f)}};
  const Mesh quad = quad_facing_origin();
  Mesh sphere;
  sphere.sphere = test_sphere({0.5f, 0.2f, -2.0f}, 0.4f);
  Scene s = test::make_scene({m}, {quad, sphere}, {0, 0, 0}, {0, 0, -1}, 4, 4, "packets");
  Accel accel(s);
  IndependentSampler smp;
  int hits = 0, misses = 0, quad_hits = 0, sphere_hits = 0, quad_differ = 0, sphere_differ = 0;
  for (int packet = 0; packet < 2000; ++packet) {
    Ray rays[8];
    const int n = 1 + packet % 8;
    for (int i = 0; i < n; ++i) {
      smp.start_light_path(5, 0, 0, uint64_t(packet * 8 + i));
      Vec2 u = smp.get_2d();
      rays[i] = Ray{{0, 0, 0}, normalize(Vec3(1.6f * u.x - 0.8f, 1.6f * u.y - 0.8f, -1.0f)), kInf};
    }
    float t[8];
    accel.cast8(rays, n, t);
    for (int i = 0; i < n; ++i) {
      float single = accel.cast(rays[i].o, rays[i].d);
      ASSERT_EQ(t[i] < kInf, single < kInf) << "packet " << packet << " lane " << i;
      if (single < kInf) {
        EXPECT_NEAR(t[i], single, 1e-5f * single) << "packet " << packet << " lane " << i;
        (single > 2.9f ? quad_hits : sphere_hits) += 1;
        if (t[i] != single) (single > 2.9f ? quad_differ : sphere_differ) += 1;
      }
      (t[i] < kInf ? hits : misses) += 1;
    }
  }
  EXPECT_GT(hits, 1000);
  EXPECT_GT(misses, 1000);
  std::printf("quad: %d of %d hits differ in t; sphere: %d of %d\n", quad_differ, quad_hits,
              sphere_differ, sphere_hits);
}

// A 16-wide query on a device without 16-wide kernels (an AVX2 CPU; here Embree is told to use its
// AVX2 kernels) goes through Embree's ray-stream path, which ignores the valid mask: it traces
// every lane whose tnear <= tfar and asserts each traced ray finite. The packet queries must leave
// the inactive lanes as empty rays (RayPacket::quiet_inactive); here they hold NaNs, as the path
// tracer's lane loops leave in unused slots, which aborted the process before. The active lanes
// must answer as single rays do.
TEST(Accel, PacketQueriesOnEmbreesAvx2Kernels) {
  __builtin_cpu_init();
  if (!__builtin_cpu_supports("avx2")) GTEST_SKIP() << "this CPU has no AVX2";
  const char* old = std::getenv("RAYFARM_EMBREE_CONFIG");
  const std::string saved = old ? old : "";
  ::setenv("RAYFARM_EMBREE_CONFIG", "isa=avx2", 1);
  struct Restore {
    bool had;
    std::string value;
    ~Restore() {
      if (had)
        ::setenv("RAYFARM_EMBREE_CONFIG", value.c_str(), 1);
      else
        ::unsetenv("RAYFARM_EMBREE_CONFIG");
    }
  } restore{old != nullptr, saved};
  EXPECT_NE(cpu_isa().find("embree:isa=avx2"), std::string::npos) << cpu_isa();

  Material m{"m", MaterialType::Diffuse, {RGB(0.5f)}};
  const Mesh quad = quad_facing_origin();
  Scene s = test::make_scene({m}, {quad}, {0, 0, 0}, {0, 0, -1}, 4, 4, "avx2");
  Accel accel(s);
  ASSERT_TRUE(accel.quiets_inactive_lanes()) << "Embree kept 16-wide kernels with isa=avx2";
  IndependentSampler smp;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  constexpr unsigned kUntouched = 12345;
  int hits = 0, misses = 0, blocked_lanes = 0;
  for (int packet = 0; packet < 500; ++packet) {
    Accel::RayPacket rays, shadow;
    Ray ray[Accel::kPacket];
    float tmax[Accel::kPacket];
    for (int i = 0; i < Accel::kPacket; ++i) {
      smp.start_light_path(7, 0, 0, uint64_t(packet * Accel::kPacket + i));
      const Vec2 u = smp.get_2d();
      ray[i] = Ray{{0, 0, 0}, normalize(Vec3(1.2f * u.x - 0.6f, 1.2f * u.y - 0.6f, -1.0f)), kInf};
      rays.set(i, ray[i]);
      tmax[i] = 2.0f + 2.0f * smp.get_1d();  // the quad is 3 to 3.5 away
      shadow.set(i, Ray{ray[i].o, ray[i].d, tmax[i]});
      if ((i + packet) % 3 == 0) {  // inactive, with what a lane loop may leave there
        rays.rh.hit.geomID[i] = kUntouched;  // and a hit no query may write
        for (Accel::RayPacket* p : {&rays, &shadow}) {
          p->rh.ray.org_x[i] = p->rh.ray.dir_y[i] = nan;  // tfar left: Embree traces tnear <= tfar
          p->clear(i);
        }
      }
    }
    Accel::PacketHits out;
    accel.intersect_packet(rays, Accel::kPacket, out);
    int blocked[Accel::kPacket];
    accel.occluded_packet(shadow, Accel::kPacket, blocked);
    for (int i = 0; i < Accel::kPacket; ++i) {
      if (!rays.active(i)) {  // not traced: Embree left its hit as it was
        EXPECT_EQ(rays.rh.hit.geomID[i], kUntouched) << "packet " << packet << " lane " << i;
        continue;
      }
      SurfaceHit single;
      const bool found = accel.intersect(ray[i], single);
      ASSERT_EQ(out.found[i] != 0, found) << "packet " << packet << " lane " << i;
      if (found) {
        EXPECT_NEAR(out.t[i], single.t, 1e-5f * single.t);
      }
      const bool occluded = accel.occluded(Ray{ray[i].o, ray[i].d, tmax[i]});
      EXPECT_EQ(blocked[i] != 0, occluded) << "packet " << packet << " lane " << i;
      (found ? hits : misses) += 1;
      blocked_lanes += blocked[i] != 0;
    }
  }
  EXPECT_GT(hits, 1000);
  EXPECT_GT(misses, 1000);
  EXPECT_GT(blocked_lanes, 400);
}

// RAYFARM_EMBREE_CONFIG takes isa=NAME only (Embree's other settings, its thread count among them,
// are not an operator's to change through it): anything else is refused by name.
TEST(Accel, EmbreeConfigOtherThanIsaIsRefused) {
  Material m{"m", MaterialType::Diffuse, {RGB(0.5f)}};
  Mesh quad;
  quad.material = 0;
  quad.positions = {{-1, -1, -3}, {1, -1, -3}, {1, 1, -3}};
  quad.indices = {0, 1, 2};
  Scene s = test::make_scene({m}, {quad}, {0, 0, 0}, {0, 0, -1}, 4, 4, "config");
  const char* old = std::getenv("RAYFARM_EMBREE_CONFIG");
  const std::string saved = old ? old : "";
  for (const char* bad : {"threads=1", "isa=avx2,threads=1", "verbose=3", "isa="}) {
    ::setenv("RAYFARM_EMBREE_CONFIG", bad, 1);
    try {
      Accel accel(s);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const std::runtime_error& e) {
      EXPECT_NE(std::string(e.what()).find("RAYFARM_EMBREE_CONFIG"), std::string::npos) << e.what();
    }
  }
  if (old)
    ::setenv("RAYFARM_EMBREE_CONFIG", saved.c_str(), 1);
  else
    ::unsetenv("RAYFARM_EMBREE_CONFIG");
}

TEST(AccelSphere, HitsAreAnalyticAndSpawnedRaysAreRobust) {
  Material m{"m", MaterialType::Diffuse, {RGB(0.5f)}};
  for (SphereShape s : {test_sphere({0.3f, -0.2f, 0.1f}, 0.7f),
                        test_sphere({1e4f, -2e4f, 3e4f}, 50.0f), test_sphere({2, 0, 0}, 1e-3f)}) {
    Mesh sphere;
    sphere.sphere = s;
    Scene sc = test::make_scene({m}, {sphere}, {0, 0, 0}, {0, 0, -1}, 4, 4, "sphere");
    Accel accel(sc);
    check_sphere_hits(accel, s, 5);
  }
}

TEST(AccelSphere, UvFollowsTheUvSphereParametrisation) {
  Material m{"m", MaterialType::Diffuse, {RGB(0.5f)}};
  SphereShape s = test_sphere({0.5f, 1, -2}, 2.0f);
  // Turned axes: the pole along (1, 1, 0) / sqrt 2.
  Mat4 rot = Mat4::rotate({0, 0, 1}, -45);
  SphereShape turned;
  const Vec3 axes[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  ASSERT_TRUE(place_sphere(Vec3(0.0f), 2.0f, axes, Mat4::translate(s.center) * rot, turned));
  Mesh exact, tess;
  exact.sphere = turned;
  MeshData d = tessellate_sphere(turned, 64, 128);
  tess.positions = d.positions, tess.normals = d.normals, tess.uvs = d.uvs,
  tess.indices = d.indices;
  Scene a = test::make_scene({m}, {exact}, {0, 0, 0}, {0, 0, -1}, 4, 4, "uv_exact");
  Scene b = test::make_scene({m}, {tess}, {0, 0, 0}, {0, 0, -1}, 4, 4, "uv_tess");
  Accel ea(a), eb(b);
  IndependentSampler smp;
  for (int i = 0; i < 2000; ++i) {
    smp.start_light_path(9, 0, 0, uint64_t(i));
    Vec3 n = sample_uniform_sphere(smp.get_2d());
    Vec3 o = turned.center + n * 10.0f;
    SurfaceHit ha, hb;
    ASSERT_TRUE(ea.intersect(Ray{o, -n, kInf}, ha));
    ASSERT_TRUE(eb.intersect(Ray{o, -n, kInf}, hb));
    // The tessellation is within 3e-4 r of the sphere; uvs agree to a fraction of a cell (away
    // from the seam at u = 0 / 1 and the poles, where u is undefined).
    if (std::fabs(ha.uv.x - 0.5f) > 0.49f || std::fabs(ha.uv.y - 0.5f) > 0.48f) continue;
    EXPECT_NEAR(ha.uv.x, hb.uv.x, 2e-3f) << i;
    EXPECT_NEAR(ha.uv.y, hb.uv.y, 2e-3f) << i;
  }
}

TEST(AccelSphere, InstancedSphereHitsLikeThePlacedOne) {
  Material m{"m", MaterialType::Diffuse, {RGB(0.5f)}};
  Mesh unit;
  unit.sphere = test_sphere({0, 0, 0}, 1.0f);
  Scene sc = test::make_scene({m}, {}, {0, 0, 0}, {0, 0, -1}, 4, 4, "inst_sphere");
  sc.objects.push_back({"ball", {unit}});
  Mat4 xf = Mat4::translate({3, -1, 2}) * Mat4::rotate({1, 2, 3}, 50) *
            Mat4::scale(Vec3(-0.5f, 0.5f, 0.5f));
  sc.instances.push_back({0, xf});
  Accel accel(sc);
  check_sphere_hits(accel, test_sphere({3, -1, 2}, 0.5f), 7);
}

}  // namespace
}  // namespace rf
