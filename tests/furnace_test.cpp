// Closed furnace: the camera inside a closed diffuse sphere of albedo a that also emits Le
// everywhere. Every path sees Le at each vertex, attenuated by a per bounce, so with max depth D
// the radiance is exactly L = Le (1 - a^(D+1)) / (1 - a) for any closed shape, whatever the
// sampling: a check of emission, NEE + MIS weights, the BSDF, Russian roulette and max depth.
#include <gtest/gtest.h>

#include <cmath>

#include "engine/local_render.h"
#include "engine/render.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

struct FurnaceCase {
  float albedo;
  int max_depth;
};

class Furnace : public ::testing::TestWithParam<FurnaceCase> {};

TEST_P(Furnace, MatchesGeometricSeries) {
  const FurnaceCase c = GetParam();
  const float le = 0.5f;
  Material m{"wall", MaterialType::Diffuse, {RGB(c.albedo)}};
  Mesh sphere = test::make_uv_sphere({0, 0, 0}, 1.0f, 24, 48, 0);
  sphere.emission = Emission{RGB(le), /*two_sided=*/true};
  Scene s = test::make_scene({m}, {sphere}, {0, 0, 0}, {0, 0, -1}, 16, 16, "furnace");
  s.render.integrator.max_depth = c.max_depth;
  s.render.integrator.rr_min_depth = 2;  // Russian roulette on from the second bounce
  s.render.spp = 2048;
  s.render.passes = 32;
  s.render.seed = 7;

  Renderer r(s);
  LocalRenderResult res = render_local(r, {});
  double expected = le * (1.0 - std::pow(double(c.albedo), c.max_depth + 1)) / (1.0 - c.albedo);
  RGB mean = res.frame.mean_estimate();
  // Pixels are independent, so the variance of the image mean is the mean pixel variance / N.
  double var_sum = 0;
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) var_sum += res.frame.variance_of_mean(x, y).x;
  double se = std::sqrt(var_sum) / 256.0;
  // Tolerance: 3 standard errors (the estimator is unbiased, fixed seed) and at most 0.5%.
  for (int ch = 0; ch < 3; ++ch) {
    SCOPED_TRACE("channel " + std::to_string(ch));
    EXPECT_NEAR(mean[ch], expected, 3 * se) << "se " << se;
    EXPECT_NEAR(mean[ch], expected, 0.005 * expected);
  }
  EXPECT_LT(se, 0.0015 * expected) << "too few samples for the 0.5% check to mean anything";
  EXPECT_EQ(res.frame.nonfinite_samples, 0u);
}

INSTANTIATE_TEST_SUITE_P(AlbedoDepth, Furnace,
                         ::testing::Values(FurnaceCase{0.5f, 0}, FurnaceCase{0.5f, 1},
                                           FurnaceCase{0.8f, 5}, FurnaceCase{0.9f, 64},
                                           FurnaceCase{0.3f, 64}));

}  // namespace
}  // namespace rf
