// Thin-lens camera: an in-focus plane renders as sharp as through a pinhole; a point off the
// focus plane spreads into a disk of radius R |1/f - 1/z0| on the image plane.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "engine/camera.h"
#include "engine/local_render.h"
#include "engine/sampler.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

// Emission-only scenes (max depth 0): pixel values are pure geometry, no lighting noise.
std::string camera_json(float aperture, float focus, float fov, int res) {
  std::string cam = R"("camera": {"fov_deg": )" + std::to_string(fov) +
                    R"(, "look_at": {"eye": [0,0,0], "target": [0,0,-1], "up": [0,1,0]})";
  if (aperture > 0)
    cam += R"(, "aperture_radius": )" + std::to_string(aperture) + R"(, "focus_distance": )" +
           std::to_string(focus);
  cam += "}";
  return R"({"version": 1, )" + cam + R"(, "film": {"resolution": [)" + std::to_string(res) + ", " +
         std::to_string(res) + R"(]}, "render": {"integrator": {"type": "path", "max_depth": 0},
         "spp": 256, "passes": 4, "seed": 3}, "materials": {"black": {"type": "diffuse", "reflectance": 0}}, )";
}

SampleBuffer render_json(const std::string& text, uint64_t seed = 3) {
  std::string dir = test::make_temp_dir("camera");
  test::write_text(dir + "/scene.json", text);
  SceneOverrides ov;
  ov.seed = seed;
  Scene s = load_scene(dir + "/scene.json", ov);
  Renderer r(s);
  return render_local(r, {}).frame;
}

// A 6x6 checkerboard of emissive squares on the plane z = -depth, 3 units wide.
std::string checkerboard_shapes(float depth) {
  std::string shapes = R"("shapes": [)";
  bool first = true;
  for (int i = 0; i < 6; ++i)
    for (int j = 0; j < 6; ++j) {
      if ((i + j) % 2) continue;
      float cx = -1.25f + 0.5f * float(i), cy = -1.25f + 0.5f * float(j);
      shapes += std::string(first ? "" : ",") +
                R"({"type": "rectangle", "material": "black", "emission": {"radiance": 1},
                "transform": [{"scale": 0.25}, {"translate": [)" +
                std::to_string(cx) + "," + std::to_string(cy) + "," + std::to_string(-depth) + "]}]}";
      first = false;
    }
  return shapes + "]}";
}

double mean_abs_diff(const SampleBuffer& a, const SampleBuffer& b) {
  double d = 0;
  for (int y = 0; y < a.rect.h; ++y)
    for (int x = 0; x < a.rect.w; ++x) d += std::fabs(a.estimate(x, y).x - b.estimate(x, y).x);
  return d / double(a.rect.area());
}

TEST(ThinLens, InFocusPlaneIsAsSharpAsPinhole) {
  const float depth = 5, fov = 35;
  SampleBuffer pinhole = render_json(camera_json(0, 0, fov, 48) + checkerboard_shapes(depth));
  SampleBuffer pinhole2 = render_json(camera_json(0, 0, fov, 48) + checkerboard_shapes(depth), 4);
  SampleBuffer focused = render_json(camera_json(0.4f, depth, fov, 48) + checkerboard_shapes(depth));
  SampleBuffer blurred = render_json(camera_json(0.4f, 2.5f, fov, 48) + checkerboard_shapes(depth));
  double noise = mean_abs_diff(pinhole, pinhole2);  // edge pixels' sampling noise alone
  double in_focus = mean_abs_diff(pinhole, focused);
  double out_of_focus = mean_abs_diff(pinhole, blurred);
  // In focus, every lens ray of a film point meets the same plane point: the images differ only
  // by sampling noise (allow 1.5x the noise between two pinhole seeds); out of focus, the
  // 0.4 aperture blurs each edge over ~8 pixels, far beyond the noise.
  std::printf("mean |diff| vs pinhole: seed noise %.4g, in focus %.4g, out of focus %.4g\n", noise,
              in_focus, out_of_focus);
  EXPECT_LT(in_focus, 1.5 * noise) << "noise " << noise;
  EXPECT_GT(out_of_focus, 5 * noise) << "noise " << noise;
}

TEST(ThinLens, OutOfFocusPointSpreadsIntoPredictedDisk) {
  const float aperture = 0.2f, focus = 4, z0 = 10, fov = 20, emitter = 0.05f;
  const int res = 128;
  std::string text = camera_json(aperture, focus, fov, res) +
                     R"("shapes": [{"type": "disk", "material": "black", "emission": {"radiance": 1},
                      "transform": [{"scale": )" + std::to_string(emitter) +
                     R"(}, {"translate": [0, 0, )" + std::to_string(-z0) + "]}]}]}";
  SampleBuffer img = render_json(text);
  // Second moment about the centroid. The image is the sharp disk (radius a) convolved with the
  // blur disk (radius b) and the box pixel filter; second moments add: <r^2> = a^2/2 + b^2/2 + 1/6.
  double w = 0, mx = 0, my = 0;
  for (int y = 0; y < res; ++y)
    for (int x = 0; x < res; ++x) {
      double v = img.estimate(x, y).x;
      w += v, mx += v * (x + 0.5), my += v * (y + 0.5);
    }
  mx /= w, my /= w;
  double m2 = 0;
  for (int y = 0; y < res; ++y)
    for (int x = 0; x < res; ++x)
      m2 += img.estimate(x, y).x * (sqr(float(x + 0.5 - mx)) + sqr(float(y + 0.5 - my)));
  m2 /= w;
  double px_per_unit = (res / 2.0) / std::tan(0.5 * fov * kPi / 180.0);
  double a = emitter / z0 * px_per_unit;
  double b_predicted = aperture * std::fabs(1.0 / focus - 1.0 / z0) * px_per_unit;
  double b_measured = std::sqrt(std::max(0.0, 2 * (m2 - 1.0 / 6.0) - a * a));
  std::printf("blur radius: predicted %.3f px, measured %.3f px\n", b_predicted, b_measured);
  EXPECT_NEAR(mx, res / 2.0, 0.5);
  EXPECT_NEAR(my, res / 2.0, 0.5);
  // 3%: the disk holds ~370 pixels of 256 spp each, so the moment's noise is well under 1%;
  // the emitter is a 128-gon, not a circle (0.01% in its second moment).
  EXPECT_NEAR(b_measured, b_predicted, 0.03 * b_predicted) << "predicted radius " << b_predicted << " px";
}

TEST(ThinLens, ImportanceIntegratesToOneOverTheFilm) {
  // W_e over the film: sum over raster cells of W_e * cos^4 / ... is checked through pdfs:
  // W_e(w) = pdf_pos * pdf_dir / cos for every direction in the frustum (pbrt-v4's identity
  // W_e = pdf_pos pdf_dir / cos theta), and connect() lands on the raster point it reports.
  Camera c;
  c.camera_to_world = Mat4::look_at({1, 2, 3}, {0, 0, 0}, {0, 1, 0});
  c.fov_deg = 40;
  c.lens_radius = 0.1f;
  c.focus_distance = 3;
  PerspectiveCamera cam(c, 64, 48);
  IndependentSampler s;
  int checked = 0;
  for (int i = 0; i < 500; ++i) {
    s.start_light_path(1, 0, 0, uint64_t(i));
    Vec2 film = s.get_2d();
    Ray r = cam.generate_ray(film.x * 64, film.y * 48, s.get_2d());
    float pdf_pos, pdf_dir;
    cam.pdf_ray(r.d, pdf_pos, pdf_dir);
    Vec2 raster;
    float we = cam.importance(r.o, r.d, &raster);
    float cos_t = dot(r.d, cam.forward());
    ASSERT_GT(we, 0);
    EXPECT_NEAR(we, pdf_pos * pdf_dir / cos_t, 1e-4f * we);
    EXPECT_NEAR(raster.x, film.x * 64, 2e-3f);
    EXPECT_NEAR(raster.y, film.y * 48, 2e-3f);
    ++checked;
  }
  EXPECT_EQ(checked, 500);
}

}  // namespace
}  // namespace rf
