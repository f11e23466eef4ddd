// The noise figure is honest: the relMSE predicted from the batch-means variance at P passes
// matches the relMSE measured against an independent render 16x longer, within a factor of 1.5.
#include <gtest/gtest.h>

#include "engine/local_render.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

LocalRenderResult render_cornell(uint64_t spp, uint32_t passes, uint64_t seed) {
  SceneOverrides ov;
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

}  // namespace
}  // namespace rf
