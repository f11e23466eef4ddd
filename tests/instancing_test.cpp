// Instancing (scene.h SceneObject/Instance, accel.h): an instanced scene is the flattened scene,
// hit for hit and image for image, at the memory of one copy of each object.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <cmath>
#include <cstdio>

#include "engine/accel.h"
#include "engine/lights/light_set.h"
#include "tests/support/fixtures.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

// A placement with rotation, non-uniform scale and translation; mirrored when `mirror`.
Mat4 placement(bool mirror) {
  Mat4 m = Mat4::translate({0.1f, -0.05f, 0.2f}) * Mat4::rotate({0.3f, 1, 0.2f}, 37) *
           Mat4::scale({1.1f, 0.9f, mirror ? -1.05f : 1.05f});
  return m;
}

// The Cornell box with every mesh moved into one object (light included) that a single instance
// places back where it was: in object space the meshes are placed by inverse(to_world).
Scene instanced_cornell(const test::CornellBox& settings, const Mat4& to_world) {
  Scene s = test::cornell_box(settings);
  Scene obj_space = s;
  obj_space.objects = {SceneObject{"box", s.meshes}};
  obj_space.instances = {Instance{0, to_world.inverse()}};
  obj_space.meshes.clear();
  flatten_instances(obj_space);  // the meshes in object space
  s.objects = {SceneObject{"box", obj_space.meshes}};
  s.instances = {Instance{0, to_world}};
  s.meshes.clear();
  prepare_instances(s);
  return s;
}

TEST(Instancing, LightsInsideObjectsBecomeWorldMeshesPerInstance) {
  Scene s = instanced_cornell({}, placement(false));
  // The Cornell box has one emitter: hoisted out of the object into the world meshes.
  ASSERT_EQ(s.meshes.size(), 1u);
  EXPECT_TRUE(s.meshes[0].emission.has_value());
  for (const Mesh& m : s.objects[0].meshes) EXPECT_FALSE(m.emission.has_value()) << m.name;
  Scene two = s;
  two.objects[0].meshes.push_back(two.meshes[0]);  // an emitter inside the object again
  two.meshes.clear();
  two.instances.push_back(Instance{0, Mat4::translate({5, 0, 0})});
  prepare_instances(two);
  EXPECT_EQ(two.meshes.size(), 2u);  // one copy per instance
  LightSet lights(two);
  EXPECT_EQ(lights.area_light_count(), 2 * s.meshes[0].triangle_count());
}

// Rays through the box from random points hit the same surface at the same point in both scenes.
// Tolerances: positions agree to 1e-4 of the box size (float rounding of one extra transform on
// coordinates of size ~1), normals to within 1e-3 rad, uvs to 1e-4.
void expect_same_hits(const Mat4& to_world) {
  SCOPED_TRACE(to_world.det3() < 0 ? "mirrored" : "not mirrored");
  Scene inst = instanced_cornell({}, to_world);
  Scene flat = inst;
  flatten_instances(flat);
  Accel a(inst), b(flat);
  uint64_t state = 7;
  auto u = [&] { return float((state = state * 6364136223846793005ull + 1442695040888963407ull) >> 40) / float(1 << 24); };
  int hits = 0, ambiguous = 0;
  for (int i = 0; i < 20000; ++i) {
    Vec3 o{u() * 0.9f - 0.45f, u() * 1.8f + 0.05f, u() * 0.9f - 0.45f};
    float z = 1 - 2 * u(), phi = 2 * kPi * u(), r = std::sqrt(std::max(0.0f, 1 - z * z));
    Vec3 d{r * std::cos(phi), r * std::sin(phi), z};  // uniform on the sphere
    SurfaceHit ha, hb;
    bool hit_a = a.intersect({o, d}, ha), hit_b = b.intersect({o, d}, hb);
    ASSERT_EQ(hit_a, hit_b) << "ray " << i;
    if (!hit_a) continue;
    // Coincident surfaces (a box's bottom on the floor) or a seam grazed: either answer is right.
    if (std::fabs(ha.t - hb.t) > 1e-4f || a.mesh(ha.mesh).material != b.mesh(hb.mesh).material) {
      ++ambiguous;
      continue;
    }
    ++hits;
    EXPECT_EQ(a.mesh(ha.mesh).emission.has_value(), b.mesh(hb.mesh).emission.has_value());
    EXPECT_LT(length(ha.p - hb.p), 1e-4f) << "ray " << i;
    EXPECT_GT(dot(ha.ng, hb.ng), 0.999999f) << "ray " << i;
    EXPECT_GT(dot(ha.ns, hb.ns), 0.999999f) << "ray " << i;
    if (!a.mesh(ha.mesh).uvs.empty()) {  // without uvs, uv is the barycentric pair (winding order)
      EXPECT_NEAR(ha.uv.x, hb.uv.x, 1e-4f);
      EXPECT_NEAR(ha.uv.y, hb.uv.y, 1e-4f);
    }
    // The error bound covers the point: the spawned ray leaves the surface on the right side.
    for (int c = 0; c < 3; ++c) EXPECT_LE(std::fabs(ha.p[c] - hb.p[c]), 8 * (ha.p_error[c] + hb.p_error[c]) + 1e-6f);
    if (::testing::Test::HasFailure()) return;
  }
  EXPECT_GT(hits, 15000);  // the rest miss (the open front) or start inside a box
  EXPECT_LT(ambiguous, 200);
}

TEST(Instancing, HitsEqualTheFlattenedScene) { expect_same_hits(placement(false)); }
TEST(Instancing, MirroredHitsEqualTheFlattenedScene) { expect_same_hits(placement(true)); }

// The statistics harness (tests/support/harness.h): 32 passes of the instanced and the flattened
// box estimate the same image, per pixel, for a camera-path and a light-path integrator.
void expect_same_image(const std::string& integrator, const Mat4& to_world) {
  SCOPED_TRACE(integrator);
  test::CornellBox settings;
  settings.integrator = integrator;
  settings.res = 16;
  settings.max_depth = 8;
  settings.spp_per_pass = 4;
  settings.passes = 32;
  Scene inst = instanced_cornell(settings, to_world);
  Scene flat = inst;
  flatten_instances(flat);
  test::Agreement r = test::compare(test::render_stats(inst, 32, 0), test::render_stats(flat, 32, 0));
  EXPECT_TRUE(r.passed) << r.message;
}

TEST(Instancing, RendersTheFlattenedImage) {
  expect_same_image("path", placement(true));
  expect_same_image("light", placement(false));
}

// Ten thousand instances of a 20k-triangle sphere: 2e8 triangles if flattened (about 7 GB of
// vertices and indices alone, plus Embree's BVH), one copy when instanced. The peak RSS may grow
// by at most 200 MB (measured: about 15 MB), and rays find the right instances.
TEST(Instancing, TenThousandPlacementsCostOneCopy) {
  rusage before{};
  getrusage(RUSAGE_SELF, &before);
  Scene s = test::make_scene({Material{}}, {}, {0, 0, 250}, {0, 0, 0}, 16, 16, "instances");
  s.objects.push_back(SceneObject{"ball", {test::make_uv_sphere({0, 0, 0}, 1, 72, 144, 0)}});
  ASSERT_GT(s.objects[0].meshes[0].triangle_count(), 20000u);
  for (int y = 0; y < 100; ++y)
    for (int x = 0; x < 100; ++x)
      s.instances.push_back(Instance{0, Mat4::translate({3.0f * x - 148.5f, 3.0f * y - 148.5f, 0})});
  prepare_instances(s);
  Accel accel(s);
  rusage after{};
  getrusage(RUSAGE_SELF, &after);
  EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 200 * 1024) << "kB";
  std::printf("peak RSS grew by %ld kB for 10000 instances\n", after.ru_maxrss - before.ru_maxrss);
  for (int k = 0; k < 10000; k += 997) {
    Vec3 c{3.0f * (k % 100) - 148.5f, 3.0f * (k / 100) - 148.5f, 0};
    SurfaceHit h;
    ASSERT_TRUE(accel.intersect({c + Vec3{0, 0, 10}, {0, 0, -1}}, h)) << k;
    EXPECT_NEAR(h.t, 9.0f, 1e-3f);  // the sphere's top at z = 1
    EXPECT_NEAR(h.p.x, c.x, 1e-3f);
    EXPECT_GT(h.ng.z, 0.99f);
  }
}

std::string write_scene(const std::string& objects_and_instances) {
  std::string dir = test::make_temp_dir("instancing");
  std::string path = dir + "/scene.json";
  test::write_text(path, R"({"version": 1,
  "camera": {"look_at": {"eye": [0, 0, 5], "target": [0, 0, 0], "up": [0, 1, 0]}, "fov_deg": 40},
  "film": {"resolution": [8, 8]},
  "materials": {"white": {"type": "diffuse", "reflectance": 0.5}},
  "shapes": [], )" + objects_and_instances + "}");
  return path;
}

TEST(InstancingJson, ObjectsAndInstancesAreRead) {
  Scene s = load_scene(write_scene(R"("objects": [{"name": "quad", "shapes": [
      {"type": "rectangle", "material": "white"},
      {"type": "rectangle", "material": "white", "emission": {"radiance": 2}}]}],
    "instances": [{"object": "quad"}, {"object": "quad", "transform": {"translate": [3, 0, 0]}}])"));
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(s.objects[0].meshes.size(), 1u);  // the emitter moved out, once per instance
  EXPECT_EQ(s.meshes.size(), 2u);
  ASSERT_EQ(s.instances.size(), 2u);
  EXPECT_FLOAT_EQ(s.instances[1].to_world.m[0][3], 3.0f);
  EXPECT_FLOAT_EQ(s.meshes[1].positions[0].x, 2.0f);  // (-1, -1, 0) moved by +3
}

TEST(InstancingJson, BadReferencesNameTheirPath) {
  auto error = [](const std::string& body) {
    return test::error_of([&] { load_scene(write_scene(body)); });
  };
  EXPECT_NE(error(R"("objects": [{"name": "a", "shapes": []}], "instances": [{"object": "b"}])")
                .find("instances[0].object: unknown object 'b' (known: a)"),
            std::string::npos);
  EXPECT_NE(error(R"("objects": [{"name": "a", "shapes": []}, {"name": "a", "shapes": []}])")
                .find("objects[1].name: duplicate object name 'a'"),
            std::string::npos);
  EXPECT_NE(error(R"("objects": [{"name": "a", "shapes": [{"type": "cube", "material": "grey"}]}])")
                .find("objects[0].shapes[0].material: unknown material 'grey'"),
            std::string::npos);
  EXPECT_NE(error(R"("instances": [{"object": "a"}])").find("instances[0].object: unknown object 'a' (known: none)"),
            std::string::npos);
}

}  // namespace
}  // namespace rf
