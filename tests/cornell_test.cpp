// The shipped Cornell box converges to the per-channel image means of other renderers' converged
// renders of this scene (256x256, max depth 64): R 0.1963, G 0.1275, B 0.0361 (Tungsten's
// reference in ../shared agrees). This checks the scene translation, camera, materials, light
// and path tracer together.
#include <gtest/gtest.h>

#include <cmath>

#include "engine/local_render.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

TEST(CornellBox, ImageMeansMatchReference) {
  SceneOverrides ov;
  ov.spp = 64;
  ov.passes = 16;
  Scene s = load_scene(test::source_dir() + "/scenes/cornell-box/scene.json", ov);
  ASSERT_EQ(s.film.width, 256);
  ASSERT_EQ(s.render.integrator.max_depth, 64);
  Renderer r(s);
  LocalRenderResult res = render_local(r, {});
  RGB mean = res.frame.mean_estimate();
  const double reference[3] = {0.1963, 0.1275, 0.0361};
  double n = double(s.film.width) * s.film.height;
  for (int ch = 0; ch < 3; ++ch) {
    // Pixels are independent: Var(image mean) = sum of pixel variances of the mean / N^2.
    double var = 0;
    for (int y = 0; y < s.film.height; ++y)
      for (int x = 0; x < s.film.width; ++x) var += res.frame.variance_of_mean(x, y)[ch];
    double se = std::sqrt(var) / n;
    SCOPED_TRACE("channel " + std::to_string(ch));
    // The render's own standard error must be below 0.2% so that the 1% check is meaningful:
    // the references are means of converged renders, themselves good to a few 0.1%.
    EXPECT_LT(se, 0.002 * reference[ch]);
    EXPECT_NEAR(mean[ch], reference[ch], 0.01 * reference[ch]);
  }
}

}  // namespace
}  // namespace rf
