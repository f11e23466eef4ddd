// Bidirectional path tracing (issue 5, item 1): agreement with the path tracer on the Cornell
// box and on a scene with a point light and a glass sphere (delta vertices), the per-strategy
// images against the BDPT image, the unweighted strategies of one depth against each other, and
// the determinism contract.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/bdpt_strategies.h"
#include "tests/support/fixtures.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

// A room lit only indirectly by a point light above a diffuse shade, with a glass sphere and a
// mirror plate: delta light and delta BSDF vertices everywhere. The shade hides the sphere from
// the light, so no light -> glass -> diffuse path exists that the path tracer could not find (its
// caustics come from the lit ceiling, a diffuse vertex it reaches by light sampling).
Scene glass_room(const std::string& integrator, int res, uint64_t spp_per_pass, uint32_t passes,
                 uint64_t seed) {
  std::string dir = test::make_temp_dir("bdpt-glass-room");
  test::write_text(dir + "/scene.json", R"({
  "format": "rayfarm-scene", "version": 1,
  "camera": {"fov_deg": 60, "look_at": {"eye": [0, 1.2, 1.8], "target": [0, 0.8, -1], "up": [0, 1, 0]}},
  "film": {"resolution": [32, 32]},
  "render": {"integrator": {"type": "path", "max_depth": 64}, "spp": 32, "passes": 32, "seed": 1},
  "materials": {
    "walls": {"type": "diffuse", "reflectance": 0.75},
    "floor": {"type": "diffuse", "reflectance": [0.6, 0.45, 0.3]},
    "shade": {"type": "diffuse", "reflectance": 0.5},
    "glass": {"type": "dielectric", "ior": 1.5},
    "mirror": {"type": "conductor", "tint": [0.9, 0.9, 0.9]}
  },
  "shapes": [
    {"type": "cube", "name": "room", "material": "walls",
     "transform": [{"scale": [2.2, 1.4, 2.4]}, {"translate": [0, 1.4, 0]}]},
    {"type": "rectangle", "name": "floor", "material": "floor",
     "transform": [{"scale": [2.19, 2.39, 1]}, {"rotate": {"axis": [1, 0, 0], "angle_deg": -90}}, {"translate": [0, 0.001, 0]}]},
    {"type": "cube", "name": "lamp shade", "material": "shade",
     "transform": [{"scale": [0.5, 0.02, 0.5]}, {"translate": [0.3, 1.4, -1.2]}]},
    {"type": "sphere", "name": "glass ball", "material": "glass", "center": [-0.2, 0.4, -0.9], "radius": 0.4},
    {"type": "rectangle", "name": "mirror", "material": "mirror",
     "transform": [{"scale": [0.6, 0.5, 1]}, {"rotate": {"axis": [0, 1, 0], "angle_deg": -30}}, {"translate": [1.3, 0.6, -1.6]}]}
  ],
  "lights": [{"type": "point", "position": [0.3, 1.46, -1.2], "intensity": [6, 6, 6]}]
})");
  SceneOverrides ov;
  ov.integrator = integrator;
  ov.width = ov.height = res;
  ov.spp = spp_per_pass * passes;
  ov.passes = passes;
  ov.seed = seed;
  return load_scene(dir + "/scene.json", ov);
}

// Lights at infinity, which start no light subpaths: a constant environment and a directional
// light, beside a small area light, over a diffuse floor with a glass sphere and a diffuse block.
Scene sky_scene(const std::string& integrator, int res, uint64_t spp_per_pass, uint32_t passes,
                uint64_t seed) {
  std::string dir = test::make_temp_dir("bdpt-sky");
  test::write_text(dir + "/scene.json", R"({
  "format": "rayfarm-scene", "version": 1,
  "camera": {"fov_deg": 50, "look_at": {"eye": [0, 2.2, 3.2], "target": [0, 0.3, 0], "up": [0, 1, 0]}},
  "film": {"resolution": [32, 32]},
  "render": {"integrator": {"type": "path", "max_depth": 64}, "spp": 32, "passes": 32, "seed": 1},
  "materials": {
    "floor": {"type": "diffuse", "reflectance": [0.7, 0.6, 0.5]},
    "block": {"type": "diffuse", "reflectance": [0.3, 0.5, 0.7]},
    "glass": {"type": "dielectric", "ior": 1.5},
    "lamp": {"type": "diffuse", "reflectance": 0}
  },
  "shapes": [
    {"type": "rectangle", "name": "floor", "material": "floor",
     "transform": [{"scale": 3}, {"rotate": {"axis": [1, 0, 0], "angle_deg": -90}}]},
    {"type": "sphere", "name": "ball", "material": "glass", "center": [-0.5, 0.5, 0], "radius": 0.5},
    {"type": "cube", "name": "block", "material": "block",
     "transform": [{"scale": [0.3, 0.4, 0.3]}, {"translate": [0.7, 0.4, -0.3]}]},
    {"type": "rectangle", "name": "lamp", "material": "lamp", "emission": {"radiance": 8},
     "transform": [{"scale": 0.25}, {"rotate": {"axis": [1, 0, 0], "angle_deg": 90}}, {"translate": [0.6, 1.6, 0.6]}]}
  ],
  "lights": [{"type": "directional", "direction": [-0.3, -1, -0.2], "irradiance": [1.5, 1.4, 1.2]}],
  "environment": {"radiance": [0.3, 0.4, 0.6]}
})");
  SceneOverrides ov;
  ov.integrator = integrator;
  ov.width = ov.height = res;
  ov.spp = spp_per_pass * passes;
  ov.passes = passes;
  ov.seed = seed;
  return load_scene(dir + "/scene.json", ov);
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Mean over the harness's cells of Var / (mean^2 + 0.01): relMSE of the block means.
double block_rel_mse(const test::ImageStats& st) {
  double sum = 0;
  for (int by = 0; by < st.blocks_y(); ++by)
    for (int bx = 0; bx < st.blocks_x(); ++bx)
      for (int c = 0; c < 3; ++c)
        sum += st.variance_of_mean(bx, by, c) / (sqr(float(st.mean(bx, by, c))) + 0.01);
  return sum / double(3 * st.blocks());
}

void expect_agree(const test::ImageStats& a, const test::ImageStats& b, const char* what) {
  test::Agreement r = test::compare(a, b);
  std::printf("%s: %s\n", what, r.message.c_str());
  EXPECT_TRUE(r.passed) << what << ": " << r.message;
}

// Agreement at max depth 64 on 4x4 blocks (BDPT splats, so its pixels are correlated within a
// pass), with enough samples that the image means' combined standard error is below 0.3% in every
// channel (blue is the noisiest). Also reports the efficiency against the path tracer: relMSE of
// the block means times render time, lower is better (equal-time relMSE ratio).
TEST(Bdpt, AgreesWithPathOnCornellBox) {
  auto t0 = std::chrono::steady_clock::now();
  test::ImageStats bdpt = test::render_stats(test::cornell_box({"bdpt", 32, 160, 32, 11}), 32, 4);
  double t_bdpt = seconds_since(t0);
  t0 = std::chrono::steady_clock::now();
  test::ImageStats path = test::render_stats(test::cornell_box({"path", 32, 256, 32, 12}), 32, 4);
  double t_path = seconds_since(t0);
  expect_agree(bdpt, path, "bdpt (160 spp/pass) vs path (256 spp/pass), cornell 32x32, 4x4 blocks");
  double e_bdpt = block_rel_mse(bdpt) * t_bdpt, e_path = block_rel_mse(path) * t_path;
  std::printf(
      "cornell: bdpt %.2f s relMSE %.3g; path %.2f s relMSE %.3g; equal-time relMSE "
      "path / bdpt = %.2f\n",
      t_bdpt, block_rel_mse(bdpt), t_path, block_rel_mse(path), e_path / e_bdpt);
}

// The path tracer is the noisy one here (light reflected off the brightly lit shade and ceiling,
// seen through glass): at 32 spp per pass its heavy tail leaves its mean 2-3% low with 32
// passes; 384 spp per pass brings its image-mean standard error to about 0.2%.
TEST(Bdpt, AgreesWithPathWithPointLightAndGlass) {
  auto t0 = std::chrono::steady_clock::now();
  test::ImageStats bdpt = test::render_stats(glass_room("bdpt", 32, 16, 32, 21), 32, 4);
  double t_bdpt = seconds_since(t0);
  t0 = std::chrono::steady_clock::now();
  test::ImageStats path = test::render_stats(glass_room("path", 32, 384, 32, 22), 32, 4);
  double t_path = seconds_since(t0);
  expect_agree(bdpt, path, "bdpt vs path, point light + glass + mirror, 4x4 blocks");
  double e_bdpt = block_rel_mse(bdpt) * t_bdpt, e_path = block_rel_mse(path) * t_path;
  std::printf("glass room: bdpt %.2f s, path %.2f s; equal-time relMSE path / bdpt = %.2f\n",
              t_bdpt, t_path, e_path / e_bdpt);
}

// Environment and directional light: only the s = 0 and s = 1 strategies reach them, weighted
// against each other alone (bdpt.cpp); the area light gets every strategy.
TEST(Bdpt, AgreesWithPathUnderEnvironmentAndDirectionalLight) {
  auto t0 = std::chrono::steady_clock::now();
  test::ImageStats bdpt = test::render_stats(sky_scene("bdpt", 32, 32, 32, 33), 32, 4);
  double t_bdpt = seconds_since(t0);
  t0 = std::chrono::steady_clock::now();
  test::ImageStats path = test::render_stats(sky_scene("path", 32, 64, 32, 34), 32, 4);
  double t_path = seconds_since(t0);
  expect_agree(bdpt, path, "bdpt vs path, environment + directional + area light, 4x4 blocks");
  std::printf("sky: bdpt %.2f s, path %.2f s; equal-time relMSE path / bdpt = %.2f\n", t_bdpt,
              t_path, block_rel_mse(path) * t_path / (block_rel_mse(bdpt) * t_bdpt));
}

// The weighted strategy images (plus the deeper rest) sum to the pass's BDPT image. Not
// bit-for-bit: bdpt_sample adds a sample's t >= 2 strategies in float before SampleBuffer adds
// the sum in double, while the strategy images add each strategy in double; with non-negative
// terms the float sum's relative error is below (strategies) * 2^-24 < 1e-5.
TEST(Bdpt, StrategyImagesSumToTheImage) {
  for (const char* which : {"cornell", "glass room"}) {
    SCOPED_TRACE(which);
    Scene s = std::string(which) == "cornell" ? test::cornell_box({"bdpt", 16, 4, 4, 3})
                                              : glass_room("bdpt", 16, 4, 4, 3);
    Renderer r(s);
    SampleBuffer buf = r.render(TaskKey{0, Rect{0, 0, 16, 16}, 1}, true);
    StrategyImages si = render_bdpt_strategies(s, 1, 3);
    ASSERT_EQ(si.images.size(), 1u + 3u + 4u + 5u);  // depths 0..3, (1, 1) left out
    double max_rel = 0, total = 0;
    for (int y = 0; y < 16; ++y)
      for (int x = 0; x < 16; ++x) {
        RGB e = buf.estimate(x, y);
        for (int c = 0; c < 3; ++c) {
          size_t i = 3 * size_t(y * 16 + x) + size_t(c);
          double sum = si.rest[i];
          for (const StrategyImage& img : si.images) sum += img.weighted[i];
          double a = double(e[c]);
          double diff = std::fabs(sum - a), scale = std::max(std::fabs(sum), std::fabs(a));
          EXPECT_LE(diff, 1e-5 * scale + 1e-12) << "pixel " << x << "," << y << " channel " << c;
          if (scale > 0) max_rel = std::max(max_rel, diff / scale);
          total += a;
        }
      }
    std::printf(
        "%s: strategy images vs BDPT image: max relative difference %.3g (image sum %.4g)\n", which,
        max_rel, total);
    EXPECT_GT(total, 0.0);
  }
}

// Every strategy of one depth, unweighted, estimates the same image (that depth's light):
// compared by image means over 64 independent passes with the light-sampling strategy (1, t),
// within 4.5 combined standard errors (the passes are independent, so a correct estimator fails
// this far less than once in a thousand runs).
TEST(Bdpt, UnweightedStrategiesOfOneDepthAgree) {
  constexpr uint32_t kPasses = 64;
  Scene s = test::cornell_box({"bdpt", 16, 16, kPasses, 5});
  std::vector<std::vector<double>> means;  // per pass, per shown strategy: image mean (RGB sum)
  StrategyImages layout;
  for (uint32_t p = 0; p < kPasses; ++p) {
    StrategyImages si = render_bdpt_strategies(s, p, 2);
    std::vector<double> m;
    for (const StrategyImage& img : si.images) {
      double sum = 0;
      for (double v : img.unweighted) sum += v;
      m.push_back(sum / double(img.unweighted.size()));
    }
    means.push_back(m);
    if (p == 0) layout = std::move(si);
  }
  auto stats = [&](size_t k, double& mean, double& se) {
    double sum = 0, sum_sq = 0;
    for (const auto& m : means) sum += m[k], sum_sq += m[k] * m[k];
    mean = sum / kPasses;
    se = std::sqrt(std::max(0.0, (sum_sq / kPasses - mean * mean) / (kPasses - 1)));
  };
  for (int depth = 1; depth <= 2; ++depth) {
    // The reference: (1, depth + 1), light sampling, the least noisy here.
    double ref_mean = 0, ref_se = 0;
    for (size_t k = 0; k < layout.images.size(); ++k)
      if (layout.images[k].s == 1 && layout.images[k].t == depth + 1) stats(k, ref_mean, ref_se);
    ASSERT_GT(ref_mean, 0.0);
    for (size_t k = 0; k < layout.images.size(); ++k) {
      const StrategyImage& img = layout.images[k];
      if (img.s + img.t - 2 != depth) continue;
      double m, se;
      stats(k, m, se);
      std::printf("depth %d, unweighted (s=%d, t=%d): image mean %.5f +- %.5f (%+.2f%%)\n", depth,
                  img.s, img.t, m, se, 100 * (m / ref_mean - 1));
      EXPECT_NEAR(m, ref_mean, 4.5 * std::sqrt(se * se + ref_se * ref_se))
          << "strategy (" << img.s << ", " << img.t << ")";
    }
  }
}

// The determinism contract: a pass is the same threaded or not, and twice.
TEST(Bdpt, PassesAreBitIdentical) {
  const auto same = &test::bits_equal;
  for (const char* which : {"cornell", "cornell sobol", "glass room"}) {
    SCOPED_TRACE(which);
    Scene s = std::string(which) == "glass room" ? glass_room("bdpt", 24, 4, 4, 3)
                                                 : test::cornell_box({"bdpt", 24, 4, 4, 3});
    if (std::string(which) == "cornell sobol") s.render.sampler = "sobol";
    Renderer r(s);
    Rect full{0, 0, 24, 24};
    SampleBuffer a = r.render(TaskKey{0, full, 2}, true);
    SampleBuffer b = r.render(TaskKey{0, full, 2}, false);
    SampleBuffer c = r.render(TaskKey{0, full, 2}, true);
    EXPECT_TRUE(same(a.sum, b.sum));
    EXPECT_TRUE(same(a.splat, b.splat));
    EXPECT_TRUE(same(a.sum, c.sum));
    EXPECT_TRUE(same(a.splat, c.splat));
    EXPECT_EQ(a.light_paths, 24u * 24u * 4u);
    EXPECT_EQ(a.nonfinite_samples, 0u);
    EXPECT_EQ(r.tiles(10).size(), 1u) << "BDPT renders whole frames";
  }
}

}  // namespace
}  // namespace rf
