// White furnace: a sphere alone under a constant environment of radiance 1. A BSDF that loses
// no energy makes the sphere invisible (every pixel 1, up to max depth); one that loses energy
// shows its loss. This tests each material through the whole renderer: environment light
// sampling and MIS, delta and glossy lobes, refraction, Russian roulette and textures.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "engine/bsdf.h"
#include "engine/local_render.h"
#include "engine/render.h"
#include "engine/sampler.h"
#include "engine/scene.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

struct FurnaceCase {
  const char* name;
  const char* material;  // JSON of the sphere's material
  bool lossless;         // true: the image must be exactly 1
};

std::ostream& operator<<(std::ostream& os, const FurnaceCase& c) { return os << c.name; }

constexpr int kRes = 24;

Scene furnace_scene(const std::string& material, uint64_t spp) {
  std::string dir = test::make_temp_dir("white-furnace");
  test::write_text(dir + "/scene.json", std::string(R"({"version": 1,
    "camera": {"fov_deg": 30, "look_at": {"eye": [0, 0, 4], "target": [0, 0, 0], "up": [0, 1, 0]}},
    "film": {"resolution": [24, 24]},
    "render": {"integrator": {"type": "path", "max_depth": 64}, "spp": )") +
                                            std::to_string(spp) + R"(, "passes": 16, "seed": 5},
    "materials": {"m": )" + material + R"(},
    "shapes": [{"type": "sphere", "material": "m", "radius": 1, "tessellation": [48, 96]}],
    "environment": {"radiance": 1}})");
  return load_scene(dir + "/scene.json");
}

// Cosine-weighted directional albedo of a BSDF on a flat surface, E_avg = int E(mu) 2 mu dmu,
// by Monte Carlo (mu = sqrt(u), one sampled wi per wo). Returns {mean, standard error} (green).
std::pair<double, double> average_albedo(const Material& m) {
  Bsdf b = Bsdf::make(constant_params(m), {0, 0, 1}, {0, 0, 1});
  IndependentSampler rng;
  const int n = 1 << 20;
  double sum = 0, sum2 = 0;
  for (int k = 0; k < n; ++k) {
    rng.start_light_path(77, 0, 0, uint64_t(k));
    float mu = std::sqrt(rng.get_1d()), phi = 2 * kPi * rng.get_1d();
    float st = std::sqrt(std::max(0.0f, 1 - mu * mu));
    Vec3 wo{st * std::cos(phi), st * std::sin(phi), mu};
    BsdfSample s;
    float uc = rng.get_1d();
    double v = 0;
    if (b.sample(wo, uc, rng.get_2d(), TransportMode::Radiance, s))
      v = s.f.y * std::fabs(s.wi.z) / s.pdf_solid_angle;
    sum += v, sum2 += v * v;
  }
  double mean = sum / n;
  return {mean, std::sqrt((sum2 / n - mean * mean) / n)};
}

class WhiteFurnace : public ::testing::TestWithParam<FurnaceCase> {};

TEST_P(WhiteFurnace, SphereShowsOnlyItsEnergyLoss) {
  const FurnaceCase& c = GetParam();
  Scene scene = furnace_scene(c.material, 256);
  Renderer r(scene);
  SampleBuffer img = render_local(r, {}).frame;
  RGB mean = img.mean_estimate();
  double var = 0;
  for (int y = 0; y < kRes; ++y)
    for (int x = 0; x < kRes; ++x) var += img.variance_of_mean(x, y).y;
  double se = std::sqrt(var) / (kRes * kRes);
  // On a convex object every camera ray scatters once and escapes (or, for glass, refracts
  // through and out), so the image is 1 - coverage * (1 - E_avg): the sphere's projected disk
  // (angular radius asin(1/4) in a 30-degree field) is weighted by the cosine exactly as E_avg.
  double coverage = kPi / 4 * sqr(float(std::tan(std::asin(0.25)) / std::tan(15.0 * kPi / 180)));
  double expected = 1, expected_se = 0;
  if (!c.lossless) {
    auto [e_avg, e_se] = average_albedo(scene.materials[0]);
    expected = 1 - coverage * (1 - e_avg);
    expected_se = coverage * e_se;
  }
  std::printf("%s: image mean %.5f (se %.5f), expected %.5f\n", c.name, mean.y, se, expected);
  // Tolerance: 4 combined standard errors (fixed seeds) plus 0.5% for the tessellated sphere:
  // its shading normals differ from the facets' by under a degree.
  double tol = 4 * std::sqrt(se * se + expected_se * expected_se) + 0.005;
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(mean[ch], expected, tol) << "channel " << ch;
  EXPECT_EQ(img.nonfinite_samples, 0u);
}

// Diffuse, mirror and glass lose no energy. The rough conductor (white, alpha 0.5) and the
// plastic (white base, rough coating) lose what single-scattering microfacet models lose;
// their expected image comes from the BSDF's own albedo, so the test checks that the renderer
// (environment sampling, MIS, the lobes' sampling) delivers exactly what the BSDF reflects.
INSTANTIATE_TEST_SUITE_P(
    Materials, WhiteFurnace,
    ::testing::Values(
        FurnaceCase{"diffuse", R"({"type": "diffuse", "reflectance": 1})", true},
        FurnaceCase{"mirror", R"({"type": "conductor", "tint": 1})", true},
        FurnaceCase{"glass", R"({"type": "dielectric", "ior": 1.5})", true},
        FurnaceCase{"rough_conductor", R"({"type": "rough_conductor", "tint": 1, "roughness": 0.5})",
                    false},
        FurnaceCase{"plastic", R"({"type": "plastic", "reflectance": 1, "roughness": 0.3})", false}),
    [](const auto& info) { return std::string(info.param.name); });

TEST(TexturedQuad, RendersTheTextureMean) {
  // A diffuse quad textured with an 8-bit sRGB image, alone under a unit environment: with max
  // depth 1 its radiance is exactly its albedo, so the image mean is the texture's linear mean.
  std::string dir = test::make_temp_dir("textured-quad");
  // 8-bit codes of the two checker colours, given to oiiotool as code/255 so it stores them as is.
  const int a[3] = {230, 128, 26}, b[3] = {51, 77, 179};
  auto unit = [](int code) { return std::to_string(code / 255.0); };
  std::string c1 = unit(a[0]) + "," + unit(a[1]) + "," + unit(a[2]);
  std::string c2 = unit(b[0]) + "," + unit(b[1]) + "," + unit(b[2]);
  ASSERT_EQ(test::run_command("oiiotool --pattern checker:width=8:height=8:color1=" + c1 +
                              ":color2=" + c2 + " 64x64 3 -d uint8 -o " + dir + "/tex.png")
                .exit_code,
            0);
  test::write_text(dir + "/scene.json", R"({"version": 1,
    "camera": {"fov_deg": 40, "look_at": {"eye": [0, 0, 2.7474774], "target": [0, 0, 0], "up": [0, 1, 0]}},
    "film": {"resolution": [32, 32]},
    "render": {"integrator": {"type": "path", "max_depth": 1}, "spp": 64, "passes": 8, "seed": 2},
    "textures": {"t": {"type": "image", "file": "tex.png"}},
    "materials": {"m": {"type": "diffuse", "reflectance": {"texture": "t"}}},
    "shapes": [{"type": "rectangle", "material": "m"}],
    "environment": {"radiance": 1}})");
  Scene s = load_scene(dir + "/scene.json");
  Renderer r(s);
  SampleBuffer img = render_local(r, {}).frame;
  // The camera at distance 1/tan(20 deg) sees exactly the quad [-1, 1]^2. A PNG is sRGB, so
  // the texture system must decode each code with the sRGB curve; half the texels hold each.
  auto decoded = [](int code) {
    double e = code / 255.0;
    return e <= 0.04045 ? e / 12.92 : std::pow((e + 0.055) / 1.055, 2.4);
  };
  RGB mean = img.mean_estimate();
  double expected[3];
  for (int ch = 0; ch < 3; ++ch) expected[ch] = 0.5 * (decoded(a[ch]) + decoded(b[ch]));
  // 1%: pixels straddling the quad's edge and filtered lookups at checker edges (the mean is
  // preserved by symmetric filtering); noise is small since the irradiance is sampled with MIS.
  std::printf("textured quad mean %.5f %.5f %.5f, texture mean %.5f %.5f %.5f\n", mean.x, mean.y,
              mean.z, expected[0], expected[1], expected[2]);
  for (int ch = 0; ch < 3; ++ch) EXPECT_NEAR(mean[ch], expected[ch], 0.01 * expected[ch]) << ch;
}

}  // namespace
}  // namespace rf
