// Light paths from lights at infinity (issue 12): light tracing, instant radiosity and photon
// mapping start paths on the environment and on directional lights from a disk outside the scene
// (LightSet::sample_emission with infinite lights, as pbrt-v4), and agree with the path tracer on
// a scene lit only by them. Every statistical test uses fixed seeds and states its tolerance.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "engine/lights/light_set.h"
#include "engine/render.h"
#include "engine/sampler.h"
#include "engine/scene.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

// A grey floor and a red sphere under the shipped sky map (scenes/materials, 256x128, its sun
// a small bright patch) and a directional sun of irradiance 1.5; the top rows of the image see
// the sky. No specular surfaces, so every integrator here can render all of it. 32x24 pixels.
Scene outdoor(const std::string& integrator, uint64_t spp, uint32_t passes, uint64_t seed,
              const std::string& extra = "") {
  std::string dir = test::make_temp_dir("outdoor-" + integrator);
  std::filesystem::copy_file(test::source_dir() + "/scenes/materials/textures/sky.exr",
                             dir + "/sky.exr");
  test::write_text(dir + "/scene.json", R"({"version": 1,
    "camera": {"fov_deg": 45, "look_at": {"eye": [0, 2.2, 6], "target": [0, 0.6, 0], "up": [0, 1, 0]}},
    "film": {"resolution": [32, 24]},
    "render": {"integrator": {"type": ")" + integrator +
                                            R"(", "max_depth": 6)" + extra + R"(}, "spp": )" +
                                            std::to_string(spp * passes) + R"(, "passes": )" +
                                            std::to_string(passes) + R"(, "seed": )" +
                                            std::to_string(seed) +
                                            R"(, "sampler": "sobol"},
    "materials": {"grey": {"type": "diffuse", "reflectance": [0.5, 0.5, 0.5]},
                  "red": {"type": "diffuse", "reflectance": [0.7, 0.2, 0.15]}},
    "shapes": [
      {"type": "rectangle", "material": "grey",
       "transform": [{"scale": 6}, {"rotate": {"axis": [1, 0, 0], "angle_deg": -90}}]},
      {"type": "sphere", "material": "red", "center": [0, 1, 0], "radius": 1}],
    "lights": [{"type": "directional", "direction": [-0.4, -1, -0.3], "irradiance": [1.5, 1.4, 1.2]}],
    "environment": {"file": "sky.exr", "scale": 1}})");
  return load_scene(dir + "/scene.json");
}

const test::ImageStats& path_reference() {
  static const test::ImageStats stats = test::render_stats(outdoor("path", 64, 32, 11), 32, 4);
  return stats;
}

void expect_agree(const test::ImageStats& a, const test::ImageStats& b, const char* what) {
  test::Agreement r = test::compare(a, b);
  std::printf("%s: %s\n", what, r.message.c_str());
  EXPECT_TRUE(r.passed) << what << ": " << r.message;
}

// The start of a light path carries the light's flux: for a directional light of irradiance E,
// the expected beta of the starts whose ray crosses an 8x8 square of the floor plane (occlusion
// ignored), per unit area, is E cos(theta); for the environment it is the irradiance its upper
// hemisphere sends onto the plane, estimated here by the light set's own light sampling (a
// different estimator of the same integral). 2^20 starts each, standard errors about 0.3%;
// tolerance 4 standard errors plus 0.2% (fixed seed), so a wrong disk radius (pdf_pos), a
// missing pdf_dir or a start inside the scene fails by far.
TEST(InfiniteLightPaths, EmissionStartsCarryTheFluxOntoAPatch) {
  Scene s = outdoor("light", 1, 1, 1);
  // The patch: the square [-4, 4]^2 of the floor plane y = 0, seen from above.
  const double half = 4, area = 4 * half * half;
  auto crosses_patch = [&](const EmissionSample& es, float& t) {
    if (!(es.dir.y < 0)) return false;
    t = -es.p.y / es.dir.y;
    Vec3 q = es.p + es.dir * t;
    return std::fabs(q.x) < half && std::fabs(q.z) < half;
  };
  for (const char* which : {"directional", "environment"}) {
    Scene one = s;
    if (std::string(which) == "directional")
      one.environment.reset();
    else
      one.lights.clear();
    LightSet lights(one);
    IndependentSampler rng;
    const int n = 1 << 20;
    double sum = 0, sum2 = 0;
    for (int k = 0; k < n; ++k) {
      rng.start_light_path(3, 0, 0, uint64_t(k));
      Vec2 u_pos = rng.get_2d(), u_dir = rng.get_2d();
      EmissionSample es;
      double v = 0;
      float t;
      if (lights.sample_emission(u_pos, u_dir, es, true) && crosses_patch(es, t)) {
        EXPECT_TRUE(es.is_infinite);
        EXPECT_GT(t, 0) << "a start inside the scene's bounding sphere";
        v = es.beta.y / area;
      }
      sum += v, sum2 += v * v;
    }
    double mean = sum / n, se = std::sqrt((sum2 / n - mean * mean) / (n - 1));
    double expected, expected_se = 0;
    if (std::string(which) == "directional") {
      Vec3 d = normalize(Vec3(-0.4f, -1, -0.3f));
      expected = 1.4 * std::fabs(d.y);  // green irradiance times cos on the patch
    } else {
      // Irradiance on an upward patch: int over the upper hemisphere of L(w) cos, by sampling
      // the map with the light set's own importance sampler (a different estimator).
      IndependentSampler r2;
      double e = 0, e2 = 0;
      const int m = 1 << 20;
      for (int k = 0; k < m; ++k) {
        r2.start_light_path(4, 0, 0, uint64_t(k));
        LightSample ls;
        double v = 0;
        if (lights.sample({0, 0, 0}, {0, 1, 0}, r2.get_1d(), r2.get_2d(), ls) && ls.wi.y > 0)
          v = ls.radiance.y * ls.wi.y / ls.pdf_solid_angle;
        e += v, e2 += v * v;
      }
      expected = e / m;
      expected_se = std::sqrt((e2 / m - expected * expected) / (m - 1));
    }
    std::printf("%s: flux per unit area onto the patch %.5f (se %.5f), expected %.5f (se %.5f)\n",
                which, mean, se, expected, expected_se);
    EXPECT_NEAR(mean, expected, 4 * std::hypot(se, expected_se) + 0.002 * expected) << which;
  }
}

// Light tracing agrees with path per 4x4 block (the harness: a t-test per block and channel at
// level 0.001, outliers within the binomial bound). The sky seen directly comes from the light
// integrator's camera samples; the floor and sphere from light paths of the sky and the sun.
TEST(InfiniteLightPaths, LightTracingAgreesWithPath) {
  test::ImageStats light = test::render_stats(outdoor("light", 64, 32, 12), 32, 4);
  expect_agree(light, path_reference(), "light vs path, sky and sun (4x4 blocks)");
}

// Instant radiosity at its defaults: VPLs from the sky's and the sun's light paths.
TEST(InfiniteLightPaths, InstantRadiosityAgreesWithPath) {
  test::ImageStats ir = test::render_stats(outdoor("ir", 16, 32, 13), 32, 4);
  expect_agree(ir, path_reference(), "ir vs path, sky and sun (4x4 blocks)");
}

// Photon mapping is consistent, not unbiased: after 64 passes of 20000 photons its image means
// are within 0.5% of path's (measured 0.03% to 0.08%; most of this open scene's light is direct
// or the sky, so the photons' bias is small here; on the Cornell box the bound is 2%,
// tests/ir_ppm_test.cpp). Infinite lights' photons carrying 20% too much (a wrong disk) moved the
// red mean by 0.9%.
TEST(InfiniteLightPaths, PhotonMappingConvergesToPath) {
  const uint32_t passes = 64;
  Scene s = outdoor("ppm", 4, passes, 14, R"(, "photons": 20000)");
  test::ImageStats ppm = test::render_stats(s, passes, 4);
  for (int c = 0; c < 3; ++c) {
    double m = ppm.image_mean(c), mr = path_reference().image_mean(c);
    std::printf("ppm vs path, channel %d: %.5f vs %.5f (%.2f%%)\n", c, m, mr, 100 * (m - mr) / mr);
    EXPECT_NEAR(m, mr, 0.005 * mr) << "channel " << c;
  }
}

}  // namespace
}  // namespace rf
