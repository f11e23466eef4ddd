// The shipped Cornell box converges to the per-channel image means of other renderers' converged
// renders of this scene (256x256, max depth 64): R 0.1963, G 0.1275, B 0.0361 (Tungsten's
// reference render, published with the scene, agrees). This checks the scene translation,
// camera, materials, light and path tracer together.
#include <gtest/gtest.h>

#include <cmath>

#include "engine/local_render.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/harness.h"
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
  test::expect_cornell_means(test::image_means(res.frame), 0.002, "Cornell box (JSON)");
}

}  // namespace
}  // namespace rf
