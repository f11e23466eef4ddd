// Integrators I (issue 4): direct, whitted, ao and light tracing against the path tracer, known
// answers and each other, with the statistics harness (tests/support/harness.h).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>

#include "engine/buffer_merge.h"
#include "engine/camera.h"
#include "engine/filter.h"
#include "engine/integrators/common.h"
#include "engine/integrators/drivers.h"
#include "engine/integrators/path/path_tracer.h"
#include "engine/integrators/registry.h"
#include "engine/local_render.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/fixtures.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

Scene scene_from_json(const std::string& text, const std::string& tag) {
  std::string dir = test::make_temp_dir(tag);
  test::write_text(dir + "/scene.json", text);
  return load_scene(dir + "/scene.json");
}

void expect_agree(const test::ImageStats& a, const test::ImageStats& b, const char* what) {
  test::Agreement r = test::compare(a, b);
  std::printf("%s: %s\n", what, r.message.c_str());
  EXPECT_TRUE(r.passed) << what << ": " << r.message;
}

TEST(DirectIntegrator, EqualsPathWithMaxDepthOne) {
  // 256 spp per pass: pixels on the light's edge (radiance 17 or 0) dominate the image mean's
  // noise; this many samples bring its standard error under the harness's 0.3% warning level.
  test::ImageStats direct =
      test::render_stats(test::cornell_box({"direct", 32, 256, 32, 1}), 32, 1);
  test::ImageStats path = test::render_stats(test::cornell_box({"path", 32, 256, 32, 2, 1}), 32, 1);
  expect_agree(direct, path, "direct vs path (max depth 1)");
}

// Glossy plates of rising roughness lit by spheres of falling size (after Veach's MIS scene),
// plus a point light, so both delta and area lights meet every strategy. The lights are large
// and there is no diffuse floor: where BSDF sampling finds a light only rarely (a small light on a
// rough or diffuse surface), 32 batch means underestimate its variance and the t test would flag
// a correct estimator. Lights this size keep every strategy out of that regime.
std::string plates_scene(const std::string& strategy, int bsdf_samples, int spp) {
  std::string plates, lights;
  const float alphas[4] = {0.03f, 0.08f, 0.15f, 0.3f};
  const float radii[4] = {0.3f, 0.5f, 0.8f, 1.2f};
  const char* names[4] = {"p0", "p1", "p2", "p3"};
  std::string materials = R"("black": {"type": "diffuse", "reflectance": 0})";
  for (int i = 0; i < 4; ++i) {
    materials += std::string(R"(, ")") + names[i] +
                 R"(": {"type": "rough_conductor", "tint": 0.8, "roughness": )" +
                 std::to_string(alphas[i]) + "}";
    plates +=
        std::string(R"({"type": "rectangle", "material": ")") + names[i] +
        R"(", "transform": [{"scale": [2.0, 0.3, 1]}, {"rotate": {"axis": [1, 0, 0], "angle_deg": )" +
        std::to_string(-60 + 8 * i) + R"(}}, {"translate": [0, )" + std::to_string(0.2 + 0.7 * i) +
        R"(, )" + std::to_string(-0.6 * i) + R"(]}]},)";
    lights += std::string(R"({"type": "sphere", "material": "black", "radius": )") +
              std::to_string(radii[i]) + R"(, "center": [)" + std::to_string(-1.5 + i) +
              R"(, 3.5, -3], "tessellation": [16, 32],
               "emission": {"radiance": )" +
              std::to_string(1.5 / (radii[i] * radii[i])) + "}},";
  }
  return std::string(R"({"version": 1,
    "camera": {"fov_deg": 50, "look_at": {"eye": [0, 2.5, 6], "target": [0, 1.2, -1], "up": [0, 1, 0]}},
    "film": {"resolution": [40, 30]},
    "render": {"integrator": {"type": "direct", "strategy": ")") +
         strategy + R"(", "bsdf_samples": )" + std::to_string(bsdf_samples) + R"(}, "spp": )" +
         std::to_string(spp) + R"(, "passes": 32, "seed": 9, "sampler": "independent"},
    "materials": {)" +
         materials + R"(},
    "shapes": [)" +
         plates + lights.substr(0, lights.size() - 1) + R"(],
    "lights": [{"type": "point", "position": [2, 4, 2], "intensity": 3}]})";
}

TEST(DirectIntegrator, StrategiesAgreeAndMisIsNeverTheWorst) {
  // BSDF sampling alone finds the lights from the rough plates rarely: its per-pixel estimates
  // are heavy-tailed, and 32 batch means of such a pixel underestimate its variance. It gets 16
  // BSDF samples per camera sample and is compared on 4x4 block means (16 pixels each, much
  // closer to normal). Its relMSE is scaled by 16 to compare strategies per sample (the variance
  // of an average of M samples falls as 1/M).
  // The independent sampler, not the default Sobol: light sampling is heavy-tailed too on the
  // sharpest plate, and Sobol makes the typical pass so tight that 32 passes rarely see the tail
  // (measured: pixel (26,8) at t = 10 after 32 passes, within 0.8 standard errors of MIS after
  // 256). The strategies are what is tested here; the samplers have their own tests.
  double rel[3];
  test::ImageStats stats[3] = {test::ImageStats(40, 30, 1), test::ImageStats(40, 30, 4),
                               test::ImageStats(40, 30, 1)};
  test::ImageStats mis_blocks(40, 30, 4);
  const char* names[3] = {"light", "bsdf", "mis"};
  const int bsdf_samples[3] = {1, 16, 1};
  for (int k = 0; k < 3; ++k) {
    Scene s = scene_from_json(plates_scene(names[k], bsdf_samples[k], 32 * 64),
                              std::string("plates-") + names[k]);
    Renderer r(s);
    SampleBuffer acc(r.header(0, PassSet{}), Rect{0, 0, 40, 30}, false);
    for (uint32_t p = 0; p < 32; ++p) {
      SampleBuffer one = r.render(TaskKey{0, Rect{0, 0, 40, 30}, p}, true);
      stats[k].add_pass(one);
      if (k == 2) mis_blocks.add_pass(one);
      merge_into(acc, one);
    }
    rel[k] = acc.rel_mse() * bsdf_samples[k];
  }
  std::printf("relMSE per sample at 64 spp: light %.4g, bsdf %.4g, mis %.4g\n", rel[0], rel[1],
              rel[2]);
  expect_agree(stats[0], stats[2], "light vs mis");
  expect_agree(stats[1], mis_blocks, "bsdf vs mis (4x4 blocks)");
  // Loosely (the issue's words): MIS is clearly better than the worse strategy on this scene.
  EXPECT_LT(rel[2], 0.5 * std::max(rel[0], rel[1]));
}

// A reference for Whitted built from the engine's pieces, independently of whitted.cpp: the path
// tracer restricted to camera -> specular* -> one non-specular vertex -> light, with MIS (light
// and BSDF sampling) at that vertex instead of Whitted's light sampling.
RGB restricted_path(const RenderContext& ctx, Ray ray, Sampler& sampler) {
  RGB radiance(0.0f), beta(1.0f);
  for (int depth = 0; depth < 64; ++depth) {
    SurfaceHit hit;
    if (!ctx.accel.intersect(ray, hit)) break;
    Vec3 wo = -ray.d;
    radiance += beta * emitted_radiance(ctx.accel.mesh(hit.mesh), hit.ng, wo);
    Bsdf bsdf = bsdf_at(ctx, hit, 0);
    Vec3 ns = bsdf.shading_normal();
    if (bsdf.is_delta()) {
      BsdfSample bs;
      float uc = sampler.get_1d();
      if (!bsdf.sample(wo, uc, sampler.get_2d(), TransportMode::Radiance, bs)) break;
      beta *= bs.f * (std::fabs(dot(bs.wi, ns)) / bs.pdf_solid_angle);
      ray = ctx.accel.spawn(hit, bs.wi);
      continue;
    }
    LightSample ls;
    float ul = sampler.get_1d();
    if (ctx.lights.sample(hit.p, Vec3(0.0f), ul, sampler.get_2d(), ls) &&
        light_visible(ctx, hit, ls)) {
      float w = ls.is_delta ? 1.0f : power_heuristic(ls.pdf_solid_angle, bsdf.pdf(wo, ls.wi));
      radiance += beta * bsdf.eval(wo, ls.wi) * ls.radiance *
                  (std::fabs(dot(ls.wi, ns)) * w / ls.pdf_solid_angle);
    }
    BsdfSample bs;
    float uc = sampler.get_1d();
    if (bsdf.sample(wo, uc, sampler.get_2d(), TransportMode::Radiance, bs)) {
      SurfaceHit lh;
      if (ctx.accel.intersect(ctx.accel.spawn(hit, bs.wi), lh)) {
        RGB le = emitted_radiance(ctx.accel.mesh(lh.mesh), lh.ng, -bs.wi);
        float w = bs.is_delta ? 1.0f
                              : power_heuristic(bs.pdf_solid_angle, ctx.lights.pdf_solid_angle(
                                                                        hit.p, Vec3(0.0f), lh.mesh,
                                                                        lh.prim, lh.p, lh.ng));
        radiance += beta * bs.f * le * (std::fabs(dot(bs.wi, ns)) * w / bs.pdf_solid_angle);
      }
    }
    break;
  }
  return radiance;
}

const char* kWhittedScene = R"({"version": 1,
  "camera": {"fov_deg": 45, "look_at": {"eye": [0, 1, 3.4], "target": [0, 0.8, 0], "up": [0, 1, 0]}},
  "film": {"resolution": [32, 32]},
  "render": {"integrator": {"type": "whitted", "max_depth": 64}, "spp": 256, "passes": 32, "seed": 4},
  "materials": {"white": {"type": "diffuse", "reflectance": 0.7}, "red": {"type": "diffuse", "reflectance": [0.7, 0.1, 0.1]},
                "mirror": {"type": "conductor", "preset": "silver"}, "glass": {"type": "dielectric", "ior": 1.5},
                "lamp": {"type": "diffuse", "reflectance": 0}},
  "shapes": [
    {"type": "rectangle", "material": "white", "transform": [{"scale": 2}, {"rotate": {"axis": [1, 0, 0], "angle_deg": -90}}]},
    {"type": "rectangle", "material": "red", "transform": [{"scale": 2}, {"translate": [0, 1, -1.5]}]},
    {"type": "rectangle", "material": "mirror", "transform": [{"scale": [0.6, 0.8, 1]}, {"rotate": {"axis": [0, 1, 0], "angle_deg": 50}}, {"translate": [-1.1, 0.8, -0.6]}]},
    {"type": "sphere", "material": "glass", "center": [0.3, 0.45, 0.2], "radius": 0.45, "tessellation": [32, 64]},
    {"type": "rectangle", "material": "lamp", "emission": {"radiance": 6}, "transform": [{"scale": 0.3}, {"rotate": {"axis": [1, 0, 0], "angle_deg": 90}}, {"translate": [0, 2.2, 0]}]}],
  "lights": [{"type": "point", "position": [1.2, 1.8, 1.2], "intensity": 2}]})";

TEST(WhittedIntegrator, EqualsRestrictedPathTracer) {
  Scene s = scene_from_json(kWhittedScene, "whitted");
  test::ImageStats whitted = test::render_stats(s, 32, 1);
  Renderer r(s);
  const RenderContext& ctx = r.context();
  PerspectiveCamera camera(s.camera, 32, 32);
  test::ImageStats reference(32, 32, 1);
  const uint64_t spp = s.render.spp_per_pass();
  for (uint32_t pass = 0; pass < 32; ++pass) {
    std::vector<double> img(32 * 32 * 3, 0.0);
    Sampler sampler;
    for (int y = 0; y < 32; ++y)
      for (int x = 0; x < 32; ++x)
        for (uint64_t k = 0; k < spp; ++k) {
          sampler.start_camera_sample(1234, 0, pass, x, y, k);  // a seed of its own
          FilterSample fs = sample_filter(s.film.filter, sampler.get_2d());
          Ray ray =
              camera.generate_ray(x + 0.5f + fs.offset.x, y + 0.5f + fs.offset.y, sampler.get_2d());
          RGB l = restricted_path(ctx, ray, sampler);
          for (int c = 0; c < 3; ++c) img[3 * (y * 32 + x) + c] += l[c] / double(spp);
        }
    reference.add_pass_image(img);
  }
  expect_agree(whitted, reference, "whitted vs restricted path tracer");
}

// Ambient occlusion at a floor point, straight below the camera ray's origin.
double ao_at(const Scene& s, Vec3 floor_point, int n, double* variance) {
  Renderer r(s);
  const RenderContext& ctx = r.context();
  const AoIntegrator& ao = s.render.integrator.as<AoIntegrator>();
  Sampler sampler;
  TraceCounters counters;
  double sum = 0, sum_sq = 0;
  for (int k = 0; k < n; ++k) {
    sampler.start_camera_sample(3, 0, 0, 0, 0, uint64_t(k));
    double v = ao.radiance(ctx, Ray{floor_point + Vec3(0, 1, 0) * 0.5f, {0, -1, 0}, kInf}, sampler,
                           counters)
                   .y;
    sum += v, sum_sq += v * v;
  }
  double mean = sum / n;
  *variance = sum_sq / n - mean * mean;
  return mean;
}

std::string ao_scene(bool wall, bool cosine, float max_distance) {
  std::string wall_shape =
      wall
          ? R"(, {"type": "rectangle", "material": "m", "transform": [{"scale": 200}, {"rotate": {"axis": [0, 1, 0], "angle_deg": 90}}, {"translate": [0.5, 0, 0]}]})"
          : "";
  return std::string(
             R"({"version": 1, "camera": {"fov_deg": 30, "look_at": {"eye": [0, 1, 0], "target": [0, 0, 0], "up": [0, 0, -1]}},
    "film": {"resolution": [4, 4]},
    "render": {"integrator": {"type": "ao", "sampling": ")") +
         (cosine ? "cosine" : "uniform") + R"(", "max_distance": )" + std::to_string(max_distance) +
         R"(}, "spp": 1, "passes": 1},
    "materials": {"m": {"type": "diffuse"}},
    "shapes": [{"type": "rectangle", "material": "m", "transform": [{"scale": 200}, {"rotate": {"axis": [1, 0, 0], "angle_deg": -90}}]})" +
         wall_shape + "]}";
}

TEST(AmbientOcclusion, MatchesClosedForms) {
  const int n = 200000;
  double var_cos, var_uni;
  // An open plane: nothing occludes, AO = 1 exactly (cosine sampling: every ray contributes 1).
  EXPECT_EQ(ao_at(scene_from_json(ao_scene(false, true, 1), "ao-open"), {0, 0, 0}, 1000, &var_cos),
            1.0);
  // A tall wall (the plane x = 0.5, 400 units across: infinite within the max distance r = 1) at
  // distance d = 0.5: the occluded directions are those with w.x >= c = d / r, whose projected
  // (cosine-weighted) measure is the disk segment (acos c - c sqrt(1 - c^2)) / pi.
  double c = 0.5;
  double expected = 1 - (std::acos(c) - c * std::sqrt(1 - c * c)) / kPi;
  double ao_cos =
      ao_at(scene_from_json(ao_scene(true, true, 1), "ao-wall-cos"), {0, 0, 0}, n, &var_cos);
  double ao_uni =
      ao_at(scene_from_json(ao_scene(true, false, 1), "ao-wall-uni"), {0, 0, 0}, n, &var_uni);
  std::printf("AO at d/r = 0.5: expected %.5f, cosine %.5f (var %.4f), uniform %.5f (var %.4f)\n",
              expected, ao_cos, var_cos, ao_uni, var_uni);
  // 4 standard errors (fixed seed).
  EXPECT_NEAR(ao_cos, expected, 4 * std::sqrt(var_cos / n));
  EXPECT_NEAR(ao_uni, expected, 4 * std::sqrt(var_uni / n));
  EXPECT_LT(var_cos, var_uni) << "cosine-weighted sampling must have the lower variance";
}

TEST(LightTracing, AgreesWithPathOnCornellBox) {
  test::ImageStats light = test::render_stats(test::cornell_box({"light", 32, 8, 32, 5}), 32, 4);
  test::ImageStats path = test::render_stats(test::cornell_box({"path", 32, 8, 32, 6}), 32, 4);
  expect_agree(light, path, "light vs path (4x4 blocks)");
}

// Splatting integrators carry a whole-frame splat plane in every task, so their frames cannot be
// kept in tiles: above 4096x4096 they are refused with the reason; the others are not.
TEST(LightTracing, SplattingIntegratorsRefuseFramesTheyCannotTile) {
  for (const char* name : {"light", "bdpt"}) {
    Scene s = test::cornell_box({name, 8, 1, 1});
    s.film.width = 4097;
    s.film.height = 4096;
    try {
      check_renderable(s);
      ADD_FAILURE() << name << " accepted a 4097x4096 film";
    } catch (const SceneError& e) {
      EXPECT_NE(std::string(e.what()).find("4097x4096"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("whole frame"), std::string::npos) << e.what();
    }
    s.film.width = 4096;
    EXPECT_NO_THROW(check_renderable(s)) << name << " at the bound";
  }
  Scene path = test::cornell_box({"path", 8, 1, 1});
  path.film.width = path.film.height = kMaxResolution;
  EXPECT_NO_THROW(check_renderable(path));
}

// The determinism contract for every integrator of the registry: a pass is the same whole or in
// tiles, serial or threaded, and the same twice.
TEST(IntegratorDeterminism, PassesAreReproducibleAndTileIndependent) {
  for (const std::string& name : known_integrators()) {
    SCOPED_TRACE(name);
    Scene s = test::cornell_box({name, 24, 4, 4, 3});
    Renderer r(s);
    Rect full{0, 0, 24, 24};
    SampleBuffer a = r.render(TaskKey{0, full, 2}, true);
    SampleBuffer b = r.render(TaskKey{0, full, 2}, false);
    const auto same = &test::bits_equal;
    EXPECT_TRUE(same(a.sum, b.sum));
    EXPECT_TRUE(same(a.splat, b.splat));
    if (!r.splats()) {
      SampleBuffer tiled(r.header(0, PassSet::range(2, 3)), full, false);
      for (const Rect& t : r.tiles(10)) assemble_tile(tiled, r.render(TaskKey{0, t, 2}, false));
      EXPECT_TRUE(same(a.sum, tiled.sum));
    } else {
      EXPECT_EQ(r.tiles(10).size(), 1u) << "splatting integrators render whole frames";
      EXPECT_GT(a.light_paths, 0u);
    }
  }
}

// The path tracer traces the samples of a pixel in lockstep with Embree's packet queries
// (integrators/path/packets.h); each lane must get the bits it gets traced alone with single-ray
// queries: the same numbers drawn in the same order, the same terms added in the same order. Exact
// equality, no tolerance: any lane mix-up, a number drawn out of turn or a NEE term added at the
// wrong depth changes bits. Scenes: triangles only (the Cornell boxes, JSON and the benchmark's
// Mitsuba XML: their diffuse vertices are shaded in the vectorised lanes, whose loops must give the
// one-lane bits too; broken once by scaling the lanes' BSDF pdf by 1.0001, and once by leaving out
// the independent sampler's lobe-choice skip: 1,001 of 1,800 lanes differ; and, for the packet's
// triangle-hit loop (Accel::intersect_packet), by scaling its point by 1 + 1e-7: 898 and 867 of
// 1,800 lanes differ), Embree's sphere primitive as lights with
// rough conductors (veach-mis), and spheres of every material under an environment map with a
// textured floor (delta BSDFs, lanes escaping while others go on). Groups of 16, 7 and 2 lanes
// (partial packets). Broken once by reading lane 0's shadow test for every lane: 171 to 460 of
// 1800 lanes differ, on every scene and sampler. The diffuse lanes with other lights: broken by
// scaling the sphere cones' pdf by 1.0001 (veach-mis: 1,338 to 1,340 of 1,800 lanes differ), and
// the pdf of the samples taken one by one (many-lights: 448 to 466; materials: 1 to 4), and by
// weighting a point light's sample by MIS (the JSON Cornell box with a point light added: 873 to
// 888 of 1,800 lanes differ). Before sphere hits took rayfarm's own distance
// (Accel::hit_from_embree), the materials scene failed here too: 61 lanes.
TEST(PathIntegrator, PacketsGiveEachSampleTheBitsOfSingleRays) {
  const std::string root = test::source_dir() + "/scenes/";
  // "+point": the scene with a point light added (a delta light among area lights).
  for (std::string file :
       {"cornell-box/scene.json", "cornell-box/scene_v3.xml", "veach-mis/scene.xml",
        "materials/scene.json", "many-lights/scene.json", "cornell-box/scene.json+point",
        "veach-mis/scene.xml+point", "cornell-box/scene.json+sphere", "veach-mis/scene.xml+sphere",
        "veach-mis/scene.xml+one", "veach-mis/scene.xml+plastic"}) {
    SCOPED_TRACE(file);
    const bool add_point = file.size() > 6 && file.substr(file.size() - 6) == "+point";
    const bool add_sphere = file.size() > 7 && file.substr(file.size() - 7) == "+sphere";
    // "+one": veach-mis with only its first sphere light (one selection group).
    const bool one_light = file.size() > 4 && file.substr(file.size() - 4) == "+one";
    // "+plastic": veach-mis's grey diffuse surfaces rough plastic, shaded one by one among the
    // plates' lanes (generic vertices whose light is a sphere picked with the lanes' numbers).
    const bool plastic = file.size() > 8 && file.substr(file.size() - 8) == "+plastic";
    if (plastic) file.resize(file.size() - 8);
    if (add_point) file.resize(file.size() - 6);
    if (add_sphere) file.resize(file.size() - 7);
    if (one_light) file.resize(file.size() - 4);
    SceneOverrides ov;
    ov.width = 24, ov.height = 16, ov.spp = 16, ov.passes = 1;
    for (const char* sampler : {"sobol-sequence", "sobol", "independent"}) {
      SCOPED_TRACE(sampler);
      ov.sampler = sampler;
      Scene s = load_scene(root + file, ov);
      if (add_point) {
        Light point;
        point.name = "point", point.type = LightType::Point, point.position = {0.3f, 1.2f, 0.5f};
        s.lights.push_back(point);
      }
      if (add_sphere) {  // a dim two-sided sphere light around the whole box: seen from inside
        Mesh ball;
        ball.name = "inside";
        ball.sphere = SphereShape{};
        ball.sphere->center = s.camera.camera_to_world.point(Vec3(0.0f));
        ball.sphere->radius = 100.0f;
        ball.emission = Emission{RGB(0.002f), true};
        s.meshes.push_back(ball);
      }
      if (plastic)
        for (Material& m : s.materials)
          if (m.type == MaterialType::Diffuse && !is_black(m.reflectance.value))
            m.type = MaterialType::Plastic, m.roughness.value = 0.3f;
      if (one_light) {
        bool first = true;
        for (Mesh& m : s.meshes)
          if (m.emission && m.sphere) {
            if (!first) m.emission.reset();
            first = false;
          }
      }
      Renderer r(s);
      const RenderContext& ctx = r.context();
      const PathTracer tracer(ctx);
      const LaneLights lane_lights(ctx.lights);
      if (one_light) EXPECT_EQ(lane_lights.sphere_table().count, 1);
      // Only spheres, by power: picked and their cones computed in the lanes (veach-mis; with the
      // dim sphere around it, the points inside that one sampled one by one after the lanes;
      // with one sphere light, one selection group).
      EXPECT_EQ(lane_lights.spheres_in_lanes(), file == "veach-mis/scene.xml" && !add_point);
      const TaskKey task{0, Rect{0, 0, 24, 16}, 0};
      TraceCounters packet_rays, single_rays;
      int lanes = 0, differing = 0, nonzero = 0;
      for (int y = 0; y < 16; y += 3)
        for (int x = 0; x < 24; x += 2)
          for (int n : {16, 7, 2}) {
            std::vector<Sampler> a(16, Sampler(kind_from_name(sampler), 16)), b = a;
            Ray rays[16];
            float w;
            for (int i = 0; i < n; ++i) {
              rays[i] = start_camera_sample(ctx, a[size_t(i)], task, x, y, uint64_t(i), w);
              start_camera_sample(ctx, b[size_t(i)], task, x, y, uint64_t(i), w);
            }
            RGB packed[16], single[16];
            tracer.radiance(rays, a.data(), n, packed, packet_rays, true);
            tracer.radiance(rays, b.data(), n, single, single_rays, false);
            for (int i = 0; i < n; ++i, ++lanes) {
              differing += std::memcmp(&packed[i], &single[i], sizeof(RGB)) != 0;
              nonzero += !is_black(single[i]);
            }
          }
      EXPECT_EQ(differing, 0) << "of " << lanes << " lanes";
      EXPECT_EQ(packet_rays.rays, single_rays.rays);
      // (The many-lights scene is dark between its small lights: 46% of its samples are lit.)
      EXPECT_GT(nonzero, lanes / 3) << "too few lit samples to compare";
      // Every scene has plain diffuse surfaces, shaded in the vectorised diffuse lanes: with their
      // light samples in the lanes on the Cornell boxes (triangle lights by power); the spheres'
      // cones in the lanes and the other samples taken one by one on the others (veach-mis:
      // spheres by power; materials: an environment map; many-lights: 128 spheres and 128 quads
      // picked by the light BVH; the Cornell box with a point light; the Cornell box inside a dim
      // two-sided sphere light, which has no cone from inside and is sampled one by one: broken
      // by scaling that sample's selection probability by 1.0001, 1,275 to 1,330 of 1,800 lanes
      // differ). veach-mis's spheres are picked in the lanes too (LaneLights::spheres_in_lanes):
      // broken by scaling the sphere table's selection probability by 1.0001 (1,531 to 1,604 of
      // 1,800 lanes differ, with three, four and one sphere lights), and, with the dim sphere
      // around veach-mis, the one-by-one sample of a point inside its sphere by scaling its
      // probability likewise (1,025 to 1,062 lanes differ). With the grey surfaces plastic, the
      // generic vertices take the point sample's x unrescaled by the lanes' sphere pick: rescaled
      // there too (their pick then rescales it again), 512 to 529 of 1,800 lanes differ with the
      // Sobol kinds (the independent sampler draws lane by lane). Not covered: spot and directional
      // lights (no scene here has them).
      EXPECT_GT(packet_rays.lane_vertices, 0u);
      EXPECT_EQ(single_rays.lane_vertices, 0u);
      // Rough conductors with constant parameters are shaded in the lanes too (conductor_lanes):
      // veach-mis's plates (Mitsuba's separable masking; with a point light added, the delta
      // light's weight), the materials scene's gold and copper (height-correlated masking,
      // complex IOR) and the many-lights scene's metal (Schlick's Fresnel with a tint).
      if (file == "veach-mis/scene.xml" || file == "materials/scene.json" ||
          file == "many-lights/scene.json") {
        EXPECT_GT(packet_rays.conductor_lane_vertices, 0u);
      }
      EXPECT_EQ(single_rays.conductor_lane_vertices, 0u);
    }
  }
}

// The drivers start a packet's camera samples together (start_camera_samples: the pixel's hashes
// once, the filter and lens numbers drawn in lockstep for the Sobol kinds). Each sample must get
// the ray, weight and sampler state start_camera_sample gives it alone: compared here bit for bit,
// with the draws that follow, for every sampler and filter, a pinhole and a thin lens, packets of
// 16, 7 and 1 samples, and sample numbers that cross 2^32 (where Sobol's key changes). Broken
// once by drawing the lens numbers of the lockstep lanes from the filter's dimension: 3,312 of
// 10,368 samples differ; and by keying every lane with the first's high index bits: 624 differ.
TEST(PathIntegrator, PacketCameraSamplesStartAsSingleOnes) {
  const std::string root = test::source_dir() + "/scenes/";
  int samples = 0, differing = 0;
  for (const char* filter : {"box", "gaussian"})
    for (float lens : {0.0f, 0.05f})
      for (const char* sampler : {"sobol-sequence", "sobol", "independent"}) {
        SCOPED_TRACE(std::string(filter) + " " + sampler + " lens " + std::to_string(lens));
        SceneOverrides ov;
        ov.width = 16, ov.height = 8, ov.spp = 32, ov.passes = 2, ov.sampler = sampler;
        ov.filter = filter;
        Scene s = load_scene(root + "cornell-box/scene_v3.xml", ov);
        s.camera.lens_radius = lens, s.camera.focus_distance = 4;
        Renderer r(s);
        const RenderContext& ctx = r.context();
        const TaskKey task{0, Rect{0, 0, 16, 8}, 1};
        for (int y = 0; y < 8; y += 3)
          for (int x = 0; x < 16; x += 5)
            // (Pass 1 of 16 samples: sobol-sequence numbers from 16 + first, so the last value
            // crosses 2^32 for it, the one before for sobol.)
            for (uint64_t first :
                 {uint64_t(0), uint64_t(16), (uint64_t(1) << 32) - 5, (uint64_t(1) << 32) - 21})
              for (int n : {16, 7, 1}) {
                std::vector<Sampler> a(16, Sampler(kind_from_name(sampler), 16)), b = a;
                Ray packed[16];
                float packed_w[16];
                start_camera_samples(ctx, a.data(), n, task, x, y, first, packed, packed_w);
                for (int i = 0; i < n; ++i, ++samples) {
                  float w;
                  const Ray single =
                      start_camera_sample(ctx, b[size_t(i)], task, x, y, first + uint64_t(i), w);
                  bool same = std::memcmp(&packed[i].o, &single.o, sizeof(Vec3)) == 0 &&
                              std::memcmp(&packed[i].d, &single.d, sizeof(Vec3)) == 0 &&
                              std::memcmp(&packed_w[i], &w, sizeof(float)) == 0;
                  for (int k = 0; k < 3; ++k) {
                    const Vec2 ua = a[size_t(i)].get_2d(), ub = b[size_t(i)].get_2d();
                    same = same && std::memcmp(&ua, &ub, sizeof(Vec2)) == 0;
                  }
                  differing += !same;
                }
              }
      }
  EXPECT_EQ(differing, 0) << "of " << samples << " samples";
}

}  // namespace
}  // namespace rf
