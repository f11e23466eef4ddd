// The noise figure is honest: the relMSE predicted from the batch-means variance at P passes
// matches the relMSE measured against an independent render 16x longer, within a factor of 1.5.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "engine/local_render.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

LocalRenderResult render_cornell(uint64_t spp, uint32_t passes, uint64_t seed,
                                 const std::string& sampler = "sobol") {
  SceneOverrides ov;
  ov.sampler = sampler;
  ov.width = ov.height = 64;
  ov.spp = spp;
  ov.passes = passes;
  ov.seed = seed;
  Scene s = load_scene(test::source_dir() + "/scenes/cornell-box/scene.json", ov);
  Renderer r(s);
  return render_local(r, {});
}

TEST(RelMse, PredictedMatchesMeasuredAgainstLongerRender) {
  LocalRenderResult short_run = render_cornell(32, 16, 1);
  LocalRenderResult ref = render_cornell(512, 16, 2);  // 16x the samples, independent seed
  double predicted = short_run.frame.rel_mse();
  double measured = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      RGB a = short_run.frame.estimate(x, y), b = ref.frame.estimate(x, y);
      for (int c = 0; c < 3; ++c) measured += sqr(a[c] - b[c]) / (sqr(b[c]) + 0.01);
    }
  measured /= 64.0 * 64.0 * 3.0;
  // The reference's own error adds about 1/16 of the short render's to the measurement.
  double ratio = measured / predicted;
  EXPECT_GT(ratio, 1.0 / 1.5) << "predicted " << predicted << " measured " << measured;
  EXPECT_LT(ratio, 1.5) << "predicted " << predicted << " measured " << measured;
  // And relMSE falls as 1/passes: the reference's is about 16x lower.
  EXPECT_NEAR(ref.frame.rel_mse() / predicted, 1.0 / 16.0, 0.5 / 16.0);
}

// sobol-sequence: passes are blocks of one scrambled sequence per pixel, so the merged image does
// not depend on how its samples are split into passes (to float rounding of the sums: 1e-5
// relative per pixel), and the noise figure, computed as if passes were independent, is
// conservative: the spread of negatively correlated blocks overstates the error of their mean.
// Measured against a 16x longer independent render: at most 1.15x the prediction (the
// reference's own error adds ~1/16), and not above it by more than the metric's noise.
TEST(RelMse, SobolSequenceImageIgnoresThePassSplitAndItsNoiseFigureIsConservative) {
  LocalRenderResult one = render_cornell(64, 1, 3, "sobol-sequence");
  LocalRenderResult four = render_cornell(64, 4, 3, "sobol-sequence");
  LocalRenderResult sixteen = render_cornell(64, 16, 3, "sobol-sequence");
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      RGB a = one.frame.estimate(x, y), b = four.frame.estimate(x, y), c = sixteen.frame.estimate(x, y);
      for (int k = 0; k < 3; ++k) {
        ASSERT_NEAR(a[k], b[k], 1e-5 * std::fabs(a[k]) + 1e-9) << x << "," << y;
        ASSERT_NEAR(a[k], c[k], 1e-5 * std::fabs(a[k]) + 1e-9) << x << "," << y;
      }
    }
  LocalRenderResult ref = render_cornell(1024, 16, 4, "sobol");
  double predicted = sixteen.frame.rel_mse(), measured = 0;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      RGB a = sixteen.frame.estimate(x, y), b = ref.frame.estimate(x, y);
      for (int c = 0; c < 3; ++c) measured += sqr(a[c] - b[c]) / (sqr(b[c]) + 0.01);
    }
  measured /= 64.0 * 64.0 * 3.0;
  std::printf("sobol-sequence 64 spp in 16 passes: predicted relMSE %.4g, measured %.4g\n", predicted,
              measured);
  EXPECT_LT(measured, 1.15 * predicted) << "the noise figure must not understate the error";
}

}  // namespace
}  // namespace rf
