// Lights (engine/lights/, engine/envmap.h): sampling against pdfs by chi-square, delta lights
// against their analytic irradiance, selection against the documented powers, and the
// environment map's direction <-> texel mapping.
//
// The chi-square tests form one family of kChiSquareTests tests at a Sidak-corrected level, so a
// correct implementation fails the family less than once in 1000 runs (fixed seeds make every
// run repeat the same draws).
#include <OpenImageIO/imageio.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "engine/accel.h"
#include "engine/envmap.h"
#include "engine/lights/light_set.h"
#include "engine/sampler.h"
#include "tests/support/chisq.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

constexpr int kChiSquareTests = 5;  // area, environment, rotated environment, constant, sphere
const double kAlpha = test::sidak_alpha(1e-3, kChiSquareTests);

Material diffuse() { return Material{"m", MaterialType::Diffuse, {RGB(0.5f)}}; }

Mesh triangle(Vec3 a, Vec3 b, Vec3 c, std::optional<Emission> e) {
  Mesh m;
  m.name = "tri";
  m.positions = {a, b, c};
  m.indices = {0, 1, 2};
  m.emission = e;
  return m;
}

Scene scene_of(std::vector<Mesh> meshes, const std::string& tag) {
  return test::make_scene({diffuse()}, std::move(meshes), {0, 0, 10}, {0, 0, 0}, 8, 8, tag);
}

void write_exr(const std::string& path, int w, int h, const std::vector<RGB>& px) {
  auto out = OIIO::ImageOutput::create(path);
  ASSERT_TRUE(out) << OIIO::geterror();
  OIIO::ImageSpec spec(w, h, 3, OIIO::TypeDesc::FLOAT);
  ASSERT_TRUE(out->open(path, spec)) << out->geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::FLOAT, px.data())) << out->geterror();
  out->close();
}

// Texel (i, j) of the test map: a gradient in u and v, a bright 2x2 spot, and a black column
// (radiance 0 there, so the sampler must never go there).
constexpr int kMapW = 32, kMapH = 16;
RGB test_map_texel(int i, int j) {
  if (i == 7) return RGB(0.0f);
  if ((i == 20 || i == 21) && (j == 5 || j == 6)) return RGB(40, 30, 20);
  return RGB(0.2f + 0.8f * i / kMapW, 0.1f + 0.5f * j / kMapH, 0.3f);
}

// An image file in a fresh temporary directory, removed with it (LightSet reads it at once).
struct TempImage {
  std::string dir, path;
  TempImage(const std::string& tag, int w, int h, const std::vector<RGB>& px)
      : dir(test::make_temp_dir(tag)), path(dir + "/env.exr") {
    write_exr(path, w, h, px);
  }
  TempImage(const TempImage&) = delete;
  ~TempImage() { std::filesystem::remove_all(dir); }
};

TempImage write_test_map() {
  std::vector<RGB> px;
  for (int j = 0; j < kMapH; ++j)
    for (int i = 0; i < kMapW; ++i) px.push_back(test_map_texel(i, j));
  return TempImage("lights_env", kMapW, kMapH, px);
}

Environment map_environment(const std::string& path, Mat4 to_world) {
  Environment env;
  env.file = "env.exr";
  env.resolved_path = path;
  env.to_world = to_world;
  return env;
}

// The mapping stated in scene.h, written out independently of envmap.cpp: map-space direction
// of (theta, phi) with u = 0.5 + phi / 2pi.
Vec3 map_direction(double theta, double phi) {
  return Vec3(float(std::sin(theta) * std::sin(phi)), float(std::cos(theta)),
              float(-std::sin(theta) * std::cos(phi)));
}

// A (theta, phi) grid on the sphere: theta from e3, phi = atan2(d.e2, d.e1) in [0, 2pi).
struct SphereGrid {
  Vec3 e1, e2, e3;
  int n_theta, n_phi;

  size_t cell(Vec3 d) const {
    double theta = std::acos(std::clamp(double(dot(d, e3)), -1.0, 1.0));
    double phi = std::atan2(double(dot(d, e2)), double(dot(d, e1)));
    if (phi < 0) phi += 2 * M_PI;
    int t = std::min(int(theta / M_PI * n_theta), n_theta - 1);
    int p = std::min(int(phi / (2 * M_PI) * n_phi), n_phi - 1);
    return size_t(t) * n_phi + p;
  }
  Vec3 direction(double theta, double phi) const {
    return normalize(e1 * float(std::sin(theta) * std::cos(phi)) +
                     e2 * float(std::sin(theta) * std::sin(phi)) + e3 * float(std::cos(theta)));
  }
  // Probability of each cell: the integral of pdf(d) sin(theta) dtheta dphi, midpoint rule on
  // sub x sub points per cell.
  template <class Pdf>
  std::vector<double> integrate(Pdf pdf, int sub) const {
    std::vector<double> p(size_t(n_theta) * n_phi, 0.0);
    double dt = M_PI / n_theta / sub, dp = 2 * M_PI / n_phi / sub;
    for (int t = 0; t < n_theta * sub; ++t) {
      double theta = (t + 0.5) * dt;
      for (int q = 0; q < n_phi * sub; ++q) {
        double phi = (q + 0.5) * dp;
        p[size_t(t / sub) * n_phi + q / sub] +=
            pdf(direction(theta, phi)) * std::sin(theta) * dt * dp;
      }
    }
    return p;
  }
};

// Draws n samples from p, bins the directions of successful ones, and tests them against the
// per-cell probabilities `cell_prob`; failed samples form one more cell of expected
// n * (1 - sum of cell_prob).
// snap, if given, maps a sampled direction before it is binned (a tolerance for float error at the
// edge of a support that is a union of cells).
void chi_square_directions(const LightSet& lights, Vec3 p, const SphereGrid& grid,
                           const std::vector<double>& cell_prob, int n, uint64_t seed,
                           const std::function<Vec3(Vec3)>& snap = {}) {
  std::vector<double> observed(cell_prob.size() + 1, 0.0), expected(cell_prob.size() + 1, 0.0);
  IndependentSampler smp;
  for (int i = 0; i < n; ++i) {
    smp.start_light_path(seed, 0, 0, uint64_t(i));
    LightSample ls;
    float u = smp.get_1d();
    if (lights.sample(p, Vec3(0.0f), u, smp.get_2d(), ls))
      observed[grid.cell(snap ? snap(ls.wi) : ls.wi)] += 1;
    else
      observed.back() += 1;
  }
  double total = 0;
  for (size_t k = 0; k < cell_prob.size(); ++k) {
    expected[k] = n * cell_prob[k];
    total += cell_prob[k];
  }
  expected.back() = std::max(0.0, n * (1.0 - total));
  test::ChiSquareResult r = test::chi_square_test(observed, expected, kAlpha);
  EXPECT_TRUE(r.passed) << r.message;
  std::printf("  %s (alpha %.2e)\n", r.message.c_str(), kAlpha);
}

// Three triangle lights whose projections from p0 are exactly octants of the sphere, so the
// light's support is a union of grid cells and the pdf is smooth inside every cell (the
// midpoint rule then integrates it to ~1e-4). The third is one-sided facing away from p0: its
// samples fail and go to the failure cell.
TEST(LightsChiSquare, AreaLightDirectionsFollowPdf) {
  const Vec3 p0{0.3f, -0.2f, 0.1f};
  Mesh t1 = triangle(p0 + Vec3(0, 0, 1), p0 + Vec3(0, 0.5f, 0), p0 + Vec3(2, 0, 0),
                     Emission{RGB(1.0f), false});  // faces p0
  Mesh t2 = triangle(p0 + Vec3(0, 0, 1.5f), p0 + Vec3(-1, 0, 0), p0 + Vec3(0, 1, 0),
                     Emission{RGB(0.2f, 0.8f, 0.3f), true});
  Mesh t3 = triangle(p0 + Vec3(0, 0, -1), p0 + Vec3(0, -0.7f, 0), p0 + Vec3(-1, 0, 0),
                     Emission{RGB(2.0f), false});  // faces away from p0
  ASSERT_GT(dot(cross(t1.positions[1] - t1.positions[0], t1.positions[2] - t1.positions[0]),
                p0 - t1.positions[0]),
            0);
  ASSERT_LT(dot(cross(t3.positions[1] - t3.positions[0], t3.positions[2] - t3.positions[0]),
                p0 - t3.positions[0]),
            0);
  Scene s = scene_of({t1, t2, t3}, "area_chi2");
  Accel accel(s);
  LightSet lights(s);
  SphereGrid grid{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, 36, 72};
  auto pdf = [&](Vec3 d) -> double {
    SurfaceHit hit;
    if (!accel.intersect(Ray{p0, d, kInf}, hit)) return 0.0;
    if (is_black(emitted_radiance(s.meshes[hit.mesh], hit.ng, -d))) return 0.0;
    return lights.pdf_solid_angle(p0, Vec3(0.0f), hit.mesh, hit.prim, hit.p, hit.ng);
  };
  std::vector<double> prob = grid.integrate(pdf, 6);
  // The failure cell's expectation is the facing-away light's selection probability.
  double sum = 0;
  for (double q : prob) sum += q;
  EXPECT_NEAR(1.0 - sum, lights.selection_pmf(2), 1e-3);  // midpoint-rule error ~1e-4
  chi_square_directions(lights, p0, grid, prob, 1000000, 11);
}

// An exact sphere light seen from outside is sampled uniformly in the cone it subtends. The grid's
// pole points at the centre and the radius makes the cone's half-angle exactly 6 of the 60 theta
// rows, so the pdf (constant in the cone, 0 outside) is smooth in every cell. A second, one-sided
// sphere light facing p from behind... cannot exist (a sphere shows its outside), so the failure
// cell is exercised by a one-sided triangle facing away. Every sample's pdf must equal
// pdf_solid_angle() at the point it returns (MIS evaluates the light pdf that way), and the point
// must be where the ray along wi first meets the sphere.
TEST(LightsChiSquare, SphereLightDirectionsFollowPdf) {
  const Vec3 p0{0.3f, -0.2f, 0.1f}, axis = normalize(Vec3(1, 2, -0.5f));
  const double dc = 3.0, theta_max = M_PI * 6 / 60;
  Mesh ball;
  ball.sphere = SphereShape{};
  ball.sphere->center = p0 + axis * float(dc);
  ball.sphere->radius = float(dc * std::sin(theta_max));
  ball.emission = Emission{RGB(1.0f, 0.5f, 0.2f), false};
  Mesh away = triangle(p0 - axis * 2.0f + Vec3(0, 0, 1), p0 - axis * 2.0f + Vec3(1, 0, 0),
                       p0 - axis * 2.0f + Vec3(0, 1, 0), Emission{RGB(0.3f), false});
  if (dot(cross(away.positions[1] - away.positions[0], away.positions[2] - away.positions[0]),
          p0 - away.positions[0]) > 0)
    std::swap(away.indices[1], away.indices[2]);
  Scene s = scene_of({ball, away}, "sphere_chi2");
  Accel accel(s);
  LightSet lights(s);
  Frame f = Frame::from_normal(axis);
  SphereGrid grid{f.s, f.t, f.n, 60, 24};
  const double pdf_in_cone = lights.selection_pmf(0) / (2 * M_PI * (1 - std::cos(theta_max)));
  auto pdf = [&](Vec3 d) -> double {
    return std::acos(std::clamp(double(dot(d, axis)), -1.0, 1.0)) < theta_max ? pdf_in_cone : 0.0;
  };
  std::vector<double> prob = grid.integrate(pdf, 4);
  double sum = 0;
  for (double q : prob) sum += q;
  EXPECT_NEAR(sum, lights.selection_pmf(0), 2e-4);
  // A sample at the cone's edge (u_point.x within ~1e-6 of 1) is a direction computed from a
  // point on the sphere, whose float error (~1e-7 rad) can put it a hair outside the cone, into a
  // cell of probability 0 (seed 51 has one such sample in a million): directions within 1e-5 rad
  // outside are binned at the edge, inside. A direction further out still fails the test.
  auto onto_cone = [&](Vec3 d) {
    const double a = std::acos(std::clamp(double(dot(d, axis)), -1.0, 1.0));
    if (a <= theta_max || a > theta_max + 1e-5) return d;
    const Vec3 side = normalize(d - axis * dot(d, axis));
    const double inside = theta_max - 1e-6;
    return axis * float(std::cos(inside)) + side * float(std::sin(inside));
  };
  chi_square_directions(lights, p0, grid, prob, 1000000, 51, onto_cone);

  IndependentSampler smp;
  for (int i = 0; i < 20000; ++i) {
    smp.start_light_path(52, 0, 0, uint64_t(i));
    LightSample ls;
    float u = smp.get_1d();
    if (!lights.sample(p0, Vec3(0.0f), u, smp.get_2d(), ls)) continue;
    ASSERT_EQ(ls.light, 0u);
    SurfaceHit hit;
    ASSERT_TRUE(accel.intersect(Ray{p0, ls.wi, kInf}, hit)) << i;
    ASSERT_EQ(hit.mesh, 0u);
    EXPECT_NEAR(hit.t, ls.distance, 1e-4f * ls.distance) << i;
    EXPECT_NEAR(length(ls.p - ball.sphere->center), ball.sphere->radius, 1e-5f) << i;
    float pdf_eval = lights.pdf_solid_angle(p0, Vec3(0.0f), hit.mesh, hit.prim, hit.p, hit.ng);
    EXPECT_NEAR(pdf_eval, ls.pdf_solid_angle, 1e-5f * ls.pdf_solid_angle) << i;
  }
}

// Irradiance from a sphere light by next-event estimation against the closed forms: outside, at
// distance d facing the centre, E = pi L (r / d)^2 (the cone's projected solid angle); inside a
// two-sided emitter, E = pi L for any normal. 200k samples: the estimator's relative standard
// error is below 0.1% outside (cos varies little over a small cone) and about 0.2% inside
// (uniform area sampling), so 1% is over 5 standard errors.
TEST(Lights, SphereLightIrradianceOutsideAndInside) {
  for (bool inside : {false, true}) {
    Mesh ball;
    ball.sphere = SphereShape{};
    ball.sphere->center = {1, 2, 3};
    ball.sphere->radius = 0.8f;
    ball.emission = Emission{RGB(2.0f, 1.0f, 0.5f), inside};
    Scene s = scene_of({ball}, inside ? "sphere_in" : "sphere_out");
    LightSet l(s);
    Vec3 x = inside ? Vec3(1.2f, 2.1f, 2.8f) : Vec3(1, 2, 3) + normalize(Vec3(1, -1, 2)) * 2.5f;
    Vec3 n = inside ? normalize(Vec3(0.3f, 1, -0.2f)) : normalize(Vec3(1, 2, 3) - x);
    IndependentSampler smp;
    const int n_samples = 200000;
    double sum[3] = {0, 0, 0};
    for (int i = 0; i < n_samples; ++i) {
      smp.start_light_path(inside ? 61 : 62, 0, 0, uint64_t(i));
      LightSample ls;
      float u = smp.get_1d();
      if (!l.sample(x, Vec3(0.0f), u, smp.get_2d(), ls)) continue;
      float w = std::max(0.0f, dot(n, ls.wi)) / ls.pdf_solid_angle;
      for (int c = 0; c < 3; ++c) sum[c] += double(ls.radiance[c]) * w;
    }
    double expected = inside ? M_PI : M_PI * sqr(0.8 / 2.5);
    const double le[3] = {2.0, 1.0, 0.5};
    for (int c = 0; c < 3; ++c)
      EXPECT_NEAR(sum[c] / n_samples, le[c] * expected, 0.01 * le[c] * expected)
          << (inside ? "inside two-sided sphere" : "outside sphere") << " channel " << c;
  }
}

// Map-frame grid (theta from the map's +y, phi from its -z towards +x), two cells per texel
// each way; the world frame vectors are the map axes rotated by to_world. Within a texel the
// solid-angle pdf is c / sin(theta), so pdf * sin(theta) is constant per cell and the midpoint
// rule is exact.
void environment_chi_square(Mat4 to_world, uint64_t seed) {
  TempImage map = write_test_map();
  Scene s = scene_of({}, "env_chi2");
  s.environment = map_environment(map.path, to_world);
  LightSet lights(s);
  SphereGrid grid{normalize(to_world.vector({0, 0, -1})), normalize(to_world.vector({1, 0, 0})),
                  normalize(to_world.vector({0, 1, 0})), 2 * kMapH, 2 * kMapW};
  std::vector<double> prob =
      grid.integrate([&](Vec3 d) { return double(lights.pdf_environment(d)); }, 2);
  double sum = 0;
  for (double q : prob) sum += q;
  EXPECT_NEAR(sum, 1.0, 1e-4);  // exact integration; float pdfs
  chi_square_directions(lights, Vec3(0.0f), grid, prob, 2000000, seed);
}

TEST(LightsChiSquare, EnvironmentDirectionsFollowPdf) { environment_chi_square(Mat4(), 21); }

TEST(LightsChiSquare, RotatedEnvironmentDirectionsFollowPdf) {
  environment_chi_square(Mat4::rotate({1, 1, 0}, 40) * Mat4::rotate({0, 1, 0}, 70), 31);
}

TEST(LightsChiSquare, ConstantEnvironmentIsUniform) {
  Scene s = scene_of({}, "env_const_chi2");
  s.environment = Environment{};
  s.environment->scale = RGB(0.5f, 1.0f, 2.0f);
  LightSet lights(s);
  SphereGrid grid{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}, 18, 36};
  std::vector<double> prob =
      grid.integrate([&](Vec3 d) { return double(lights.pdf_environment(d)); }, 4);
  chi_square_directions(lights, Vec3(0.0f), grid, prob, 500000, 41);
}

// Light sampling of the environment estimates the irradiance E(n) = integral of L max(0, n.w):
// the reference sums every texel's radiance (known to the test) over 16 x 16 points per texel.
// Tolerance: 5 standard errors of the mean (false failure ~6e-7) plus 1e-3 for the quadrature.
TEST(Lights, EnvironmentSamplingEstimatesIrradiance) {
  Mat4 to_world = Mat4::rotate({0, 0, 1}, 25) * Mat4::rotate({0, 1, 0}, -60);
  TempImage map = write_test_map();
  Scene s = scene_of({}, "env_irr");
  s.environment = map_environment(map.path, to_world);
  s.environment->scale = RGB(2.0f, 1.0f, 0.5f);
  LightSet lights(s);
  const Vec3 n = normalize(Vec3(0.3f, 0.8f, -0.5f));
  RGB exact(0.0f);
  const int sub = 16;
  const double du = 1.0 / (kMapW * sub), dv = 1.0 / (kMapH * sub);
  for (int j = 0; j < kMapH * sub; ++j) {
    double v = (j + 0.5) * dv, theta = M_PI * v;
    for (int i = 0; i < kMapW * sub; ++i) {
      double u = (i + 0.5) * du, phi = 2 * M_PI * (u - 0.5);
      Vec3 d = normalize(to_world.vector(map_direction(theta, phi)));
      double w = std::max(0.0f, dot(n, d)) * 2 * M_PI * M_PI * std::sin(theta) * du * dv;
      exact += test_map_texel(i / sub, j / sub) * s.environment->scale * float(w);
    }
  }
  const int N = 1000000;
  double sum[3] = {0, 0, 0}, sum2[3] = {0, 0, 0};
  IndependentSampler smp;
  for (int k = 0; k < N; ++k) {
    smp.start_light_path(51, 0, 0, uint64_t(k));
    LightSample ls;
    float u = smp.get_1d();
    if (!lights.sample(Vec3(0.0f), Vec3(0.0f), u, smp.get_2d(), ls)) continue;
    RGB c = ls.radiance * (std::max(0.0f, dot(n, ls.wi)) / ls.pdf_solid_angle);
    for (int ch = 0; ch < 3; ++ch) sum[ch] += c[ch], sum2[ch] += double(c[ch]) * c[ch];
  }
  for (int ch = 0; ch < 3; ++ch) {
    double mean = sum[ch] / N, var = sum2[ch] / N - mean * mean;
    double se = std::sqrt(std::max(var, 0.0) / N);
    EXPECT_NEAR(mean, exact[ch], 5 * se + 1e-3 * exact[ch]) << "channel " << ch;
  }
}

// A 33 x 17 map whose texel (i, j) holds (i, j, 1): odd sizes put the image centre inside texel
// (16, 8). Exact equality: the lookup is nearest, so the result is a stored texel.
class EnvironmentLookup : public ::testing::Test {
 protected:
  static constexpr int W = 33, H = 17;
  static std::vector<RGB> ids() {
    std::vector<RGB> px;
    for (int j = 0; j < H; ++j)
      for (int i = 0; i < W; ++i) px.push_back(RGB(float(i), float(j), 1.0f));
    return px;
  }
  RGB at(const LightSet& l, Vec3 d) { return l.environment_radiance(normalize(d)); }
  TempImage image_{"lights_lookup", W, H, ids()};
  const std::string& path_ = image_.path;
};

TEST_F(EnvironmentLookup, FollowsTheStatedMapping) {
  Scene s = scene_of({}, "env_lookup");
  s.environment = map_environment(path_, Mat4());
  LightSet l(s);
  EXPECT_EQ(at(l, {0, 0, -1}), RGB(16, 8, 1));     // centre of the image is -z
  EXPECT_EQ(at(l, {0, 1, 0}).y, 0.0f);             // top row is +y
  EXPECT_EQ(at(l, {0, -1, 0}).y, float(H - 1));    // bottom row is -y
  EXPECT_EQ(at(l, {1, 0, 0}), RGB(24, 8, 1));      // u = 0.75: +x, a quarter turn right of centre
  EXPECT_EQ(at(l, {-1, 0, 0}), RGB(8, 8, 1));      // u = 0.25
  EXPECT_EQ(at(l, {0.2f, 0, -1}), RGB(17, 8, 1));  // u grows towards +x: u = 0.531
  EXPECT_EQ(at(l, {0, 0.3f, -1}), RGB(16, 6, 1));  // v = acos(0.287)/pi = 0.407
  EXPECT_EQ(at(l, {0.01f, 0, 1}), RGB(32, 8, 1));  // +z from the +x side: u ~ 0.998
  EXPECT_EQ(at(l, {-0.01f, 0, 1}), RGB(0, 8, 1));  // +z from the -x side: u ~ 0.0016
  // Random directions against the formula written out here.
  IndependentSampler smp;
  for (int k = 0; k < 1000; ++k) {
    smp.start_light_path(61, 0, 0, uint64_t(k));
    double theta = std::acos(1 - 2 * double(smp.get_1d())), phi = M_PI * (2 * smp.get_1d() - 1);
    double u = 0.5 + phi / (2 * M_PI), v = theta / M_PI;
    double fi = u * W, fj = v * H;
    // Skip directions within float rounding of a texel edge.
    if (std::fabs(fi - std::round(fi)) < 1e-4 || std::fabs(fj - std::round(fj)) < 1e-4) continue;
    RGB c = l.environment_radiance(map_direction(theta, phi));
    EXPECT_EQ(c.x, float(std::min(int(fi), W - 1))) << theta << " " << phi;
    EXPECT_EQ(c.y, float(std::min(int(fj), H - 1))) << theta << " " << phi;
  }
}

TEST_F(EnvironmentLookup, AppliesTheRotation) {
  // Rotation by 90 degrees about +y takes map -z to world -x and map +x to world -z.
  Scene s = scene_of({}, "env_lookup_rot");
  s.environment = map_environment(path_, Mat4::rotate({0, 1, 0}, 90));
  s.environment->scale = RGB(2.0f);
  LightSet l(s);
  EXPECT_EQ(at(l, {-1, 0, 0}), RGB(32, 16, 2));  // image centre (16, 8) times scale 2
  EXPECT_EQ(at(l, {0, 0, -1}), RGB(48, 16, 2));  // texel (24, 8)
  EXPECT_EQ(at(l, {0, 1, 0}).y, 0.0f);           // the pole stays up
}

TEST(Lights, ConstantEnvironment) {
  Mesh sphere = test::make_uv_sphere({1, 2, 3}, 2.0f, 8, 16, 0);
  Scene s = scene_of({sphere}, "env_const");
  s.environment = Environment{};
  s.environment->scale = RGB(0.5f, 1.0f, 2.0f);
  LightSet l(s);
  ASSERT_TRUE(l.has_environment());
  ASSERT_EQ(l.size(), 1u);
  EXPECT_EQ(l.kind(0), LightKind::Environment);
  EXPECT_EQ(l.environment_radiance(normalize(Vec3(1, -2, 3))), RGB(0.5f, 1.0f, 2.0f));
  EXPECT_FLOAT_EQ(l.pdf_environment(Vec3(0, 1, 0)), 0.25f * kInvPi);
  // Power 4 pi^2 R^2 luminance; R is half the diagonal of the sphere's bounding box.
  Vec3 lo(kInf), hi(-kInf);
  for (Vec3 q : s.meshes[0].positions) lo = vmin(lo, q), hi = vmax(hi, q);
  double r = 0.5 * length(hi - lo), lum = luminance(RGB(0.5f, 1.0f, 2.0f));
  EXPECT_NEAR(l.scene_radius(), r, 1e-6 * r);
  EXPECT_NEAR(l.selection_power(0), 4 * M_PI * M_PI * r * r * lum, 1e-5 * l.selection_power(0));
  EXPECT_FALSE(LightSet(scene_of({}, "none")).has_environment());
}

TEST(Lights, MissingEnvironmentFileThrowsNamingIt) {
  Scene s = scene_of({}, "env_missing");
  s.environment = map_environment("/nonexistent/dir/sky_missing.exr", Mat4());
  try {
    LightSet l(s);
    ADD_FAILURE() << "no exception";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("sky_missing.exr"), std::string::npos) << e.what();
  }
}

// Scene with every kind: two-sided emissive sphere, a plain sphere, point, spot, directional, a
// black point light and the test map.
Scene all_kinds_scene(const std::string& map_path) {
  Mesh lamp = test::make_uv_sphere({-2, 0, 0}, 0.5f, 6, 12, 0);
  lamp.emission = Emission{RGB(3, 2, 1), true};
  Mesh ball = test::make_uv_sphere({1, 0.5f, 0}, 1.0f, 6, 12, 0);
  Scene s = scene_of({lamp, ball}, "all_kinds");
  Light point{"point", LightType::Point, {0, 3, 0}};
  point.intensity = RGB(10, 10, 10);
  Light spot{"spot", LightType::Spot, {0, 4, 0}, {0, -1, 0}, RGB(50, 20, 5)};
  spot.cone_angle_deg = 30;
  spot.falloff_start_deg = 20;
  Light sun{"sun", LightType::Directional};
  sun.direction = normalize(Vec3(1, -2, 0.5f));
  sun.irradiance = RGB(1, 2, 3);
  Light black{"black", LightType::Point, {0, 1, 0}, {0, -1, 0}, RGB(0.0f)};
  s.lights = {point, spot, sun, black};
  s.environment = map_environment(map_path, Mat4::rotate({1, 0, 0}, 30));
  s.environment->scale = RGB(0.1f);
  return s;
}

double triangle_area(const Mesh& m, size_t t) {
  Vec3 a = m.positions[m.indices[3 * t]], b = m.positions[m.indices[3 * t + 1]],
       c = m.positions[m.indices[3 * t + 2]];
  return 0.5 * length(cross(b - a, c - a));
}

// The documented powers (lights/light_set.h), computed here from the scene; the pmfs must be them
// normalised (to float rounding: 1e-6 absolute plus 1e-5 relative).
TEST(Lights, SelectionFollowsDocumentedPowersOverAllKinds) {
  TempImage map = write_test_map();
  Scene s = all_kinds_scene(map.path);
  LightSet l(s);
  const Mesh& lamp = s.meshes[0];
  ASSERT_EQ(l.size(), lamp.triangle_count() + 4 + 1);
  ASSERT_EQ(l.area_light_count(), lamp.triangle_count());
  Vec3 lo(kInf), hi(-kInf);
  for (const Mesh& m : s.meshes)
    for (Vec3 q : m.positions) lo = vmin(lo, q), hi = vmax(hi, q);
  const double R = 0.5 * length(hi - lo);
  EXPECT_NEAR(l.scene_radius(), R, 1e-5 * R);

  std::vector<double> power;
  for (size_t t = 0; t < lamp.triangle_count(); ++t)
    power.push_back(M_PI * triangle_area(lamp, t) * luminance(RGB(3, 2, 1)) * 2);
  power.push_back(4 * M_PI * 10);
  double cs = std::cos(20 * M_PI / 180), ce = std::cos(30 * M_PI / 180);
  power.push_back(2 * M_PI * luminance(RGB(50, 20, 5)) * (1 - (cs + ce) / 2));
  power.push_back(M_PI * R * R * luminance(RGB(1, 2, 3)));
  power.push_back(0);
  double env = 0;  // pi R^2 * sum over texels of luminance * texel solid angle
  for (int j = 0; j < kMapH; ++j) {
    double solid =
        2 * M_PI / kMapW * (std::cos(M_PI * j / kMapH) - std::cos(M_PI * (j + 1) / kMapH));
    for (int i = 0; i < kMapW; ++i) env += luminance(test_map_texel(i, j) * 0.1f) * solid;
  }
  power.push_back(M_PI * R * R * env);
  double total = 0;
  for (double p : power) total += p;

  double pmf_sum = 0;
  for (size_t i = 0; i < l.size(); ++i) {
    EXPECT_NEAR(l.selection_power(i), power[i], 1e-5 * power[i]) << "light " << i;
    EXPECT_NEAR(l.selection_pmf(i), power[i] / total, 1e-6 + 1e-5 * power[i] / total) << i;
    pmf_sum += l.selection_pmf(i);
  }
  EXPECT_NEAR(pmf_sum, 1.0, 1e-5);
  EXPECT_EQ(l.kind(l.scene_light_index(0)), LightKind::Point);
  EXPECT_EQ(l.kind(l.scene_light_index(1)), LightKind::Spot);
  EXPECT_EQ(l.kind(l.scene_light_index(2)), LightKind::Directional);
  EXPECT_EQ(l.kind(l.environment_index()), LightKind::Environment);
}

// sample_by_power() picks a group (an emissive mesh or one other light) for u_point.x in its cdf
// interval, then a triangle of the mesh for u_point.x rescaled into that interval. With u_point.x
// the base-2 radical inverse of the sample index (whose every run of consecutive indices is
// spread over [0, 1) with discrepancy O(log n / n), and so is its part inside any interval,
// rescaled), every light is picked M * pmf times, to within 2 (interval ends) plus log2(M) + 1
// (the radical inverse over a run) and float rounding of the cdf. From p every pick succeeds: the
// lamp is two-sided, p is inside the spot's inner cone, and the environment is never sampled where
// it is black.
TEST(Lights, SampleSelectsByPmf) {
  TempImage map = write_test_map();
  Scene s = all_kinds_scene(map.path);
  LightSet l(s);
  const Vec3 p{0, 1.5f, 0.2f};
  const int M = 200000;
  std::vector<int> count(l.size(), 0);
  for (int k = 0; k < M; ++k) {
    LightSample ls;
    float ux = float(reverse_bits32(uint32_t(k)) >> 8) * 0x1p-24f;
    ASSERT_TRUE(l.sample_by_power(p, {ux, 0.61f}, ls)) << k;
    ++count[ls.light];
    EXPECT_EQ(ls.is_delta,
              l.kind(ls.light) != LightKind::Area && l.kind(ls.light) != LightKind::Environment);
    EXPECT_EQ(ls.is_infinite, l.kind(ls.light) == LightKind::Directional ||
                                  l.kind(ls.light) == LightKind::Environment);
  }
  for (size_t i = 0; i < l.size(); ++i)
    EXPECT_NEAR(count[i], M * l.selection_pmf(i), 2 + std::log2(M) + 1 + 1e-5 * M) << "light " << i;
  EXPECT_EQ(count[l.scene_light_index(3)], 0);  // the black point light
}

// pdf_environment (used for MIS when a BSDF ray escapes) equals the pdf sample() reports, with
// the environment's selection probability < 1 here; both evaluate the same float expression, so
// they agree to rounding (1e-6 relative).
TEST(Lights, PdfEnvironmentEqualsSamplePdf) {
  TempImage map = write_test_map();
  Scene s = all_kinds_scene(map.path);
  LightSet l(s);
  const Vec3 p{0.5f, -0.5f, 2};
  const float pmf = l.selection_pmf(l.environment_index());
  ASSERT_GT(pmf, 0.01f);
  ASSERT_LT(pmf, 0.99f);
  double cdf_lo = 0;
  for (size_t i = 0; i < l.environment_index(); ++i) cdf_lo += l.selection_pmf(i);
  IndependentSampler smp;
  int checked = 0;
  for (int k = 0; k < 20000; ++k) {
    smp.start_light_path(71, 0, 0, uint64_t(k));
    float u = float(cdf_lo + (1 - cdf_lo) * smp.get_1d());  // inside the environment's interval
    LightSample ls;
    if (!l.sample(p, Vec3(0.0f), u, smp.get_2d(), ls) || ls.light != l.environment_index()) continue;
    ++checked;
    EXPECT_NEAR(l.pdf_environment(ls.wi), ls.pdf_solid_angle, 1e-6f * ls.pdf_solid_angle);
    EXPECT_EQ(l.environment_radiance(ls.wi), ls.radiance);
    EXPECT_TRUE(ls.is_infinite);
    EXPECT_FALSE(ls.is_delta);
    EXPECT_NEAR(length(ls.p - (p + ls.wi * 2 * l.scene_radius())), 0, 1e-4f);
    EXPECT_EQ(ls.n, -ls.wi);
  }
  EXPECT_GT(checked, 19000);
  // Directions in the black column have pdf 0: theta = pi/2, u in texel 7 (u = 7.5 / 32).
  Mat4 to_world = Mat4::rotate({1, 0, 0}, 30);
  Vec3 black = to_world.vector(map_direction(M_PI / 2, 2 * M_PI * (7.5 / kMapW - 0.5)));
  EXPECT_EQ(l.pdf_environment(normalize(black)), 0.0f);
  EXPECT_EQ(l.environment_radiance(normalize(black)), RGB(0.0f));
}

// Irradiance at x with normal n from one delta light, as next-event estimation computes it:
// radiance * |cos| / pdf (pdf is the selection probability, 1 here).
RGB nee_irradiance(const LightSet& l, Vec3 x, Vec3 n) {
  LightSample ls;
  if (!l.sample(x, Vec3(0.0f), 0.5f, {0.5f, 0.5f}, ls)) return RGB(0.0f);
  EXPECT_TRUE(ls.is_delta);
  EXPECT_EQ(ls.pdf_solid_angle, 1.0f);
  return ls.radiance * (std::max(0.0f, dot(n, ls.wi)) / ls.pdf_solid_angle);
}

void expect_rgb_near(RGB a, RGB b, float rel, const std::string& what) {
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(a[c], b[c], rel * std::fabs(b[c]) + 1e-7f) << what;
}

// Spot at height 2 above the plane y = 0, pointing down; a point at angle t off the axis is at
// distance 2 / cos t and sees the light at cos t, so E = I s(t) cos^3 t / 4, with s = 1 inside
// 20 degrees, 0 outside 30, and smoothstep in cos between. Float arithmetic only: 1e-5.
TEST(Lights, SpotIrradianceInsideFalloffAndOutside) {
  Scene s = scene_of({}, "spot");
  Light spot{"spot", LightType::Spot, {0, 2, 0}, {0, -1, 0}, RGB(5, 4, 3)};
  spot.cone_angle_deg = 30;
  spot.falloff_start_deg = 20;
  s.lights = {spot};
  LightSet l(s);
  const double cs = std::cos(20 * M_PI / 180), ce = std::cos(30 * M_PI / 180);
  for (double deg : {0.0, 10.0, 19.0, 21.0, 25.0, 29.0, 31.0, 35.0, 60.0}) {
    double t = deg * M_PI / 180, c = std::cos(t);
    double x = (c - ce) / (cs - ce), sm = x <= 0 ? 0 : x >= 1 ? 1 : x * x * (3 - 2 * x);
    RGB expect = RGB(5, 4, 3) * float(sm * c * c * c / 4);
    Vec3 at{float(2 * std::tan(t) * std::cos(1.0)), 0, float(2 * std::tan(t) * std::sin(1.0))};
    expect_rgb_near(nee_irradiance(l, at, {0, 1, 0}), expect, 1e-5f,
                    "at " + std::to_string(deg) + " deg");
  }
  // A tilted spot: the axis is its direction, not -y. 25 degrees off a 45-degree axis.
  Light tilted = spot;
  tilted.position = {0, 0, 0};
  tilted.direction = normalize(Vec3(1, -1, 0));
  s.lights = {tilted};
  LightSet lt(s);
  Vec3 axis = tilted.direction;
  Vec3 off = normalize(Mat4::rotate({0, 0, 1}, 25).vector(axis));
  Vec3 x = off * 3.0f;
  double x25 = (std::cos(25 * M_PI / 180) - ce) / (cs - ce);
  double sm = x25 * x25 * (3 - 2 * x25);
  RGB expect = RGB(5, 4, 3) * float(sm / 9);  // normal facing the light: cos 1
  expect_rgb_near(nee_irradiance(lt, x, -off), expect, 1e-5f, "tilted spot");
}

// E = I cos / r^2 at several points and normals; float arithmetic only: 1e-5.
TEST(Lights, PointIrradianceIsInverseSquareCosine) {
  Scene s = scene_of({}, "point");
  Light point{"p", LightType::Point, {1, 2, 3}};
  point.intensity = RGB(2, 3, 4);
  s.lights = {point};
  LightSet l(s);
  struct Case {
    Vec3 x, n;
  };
  for (Case c : {Case{{1, 0, 3}, {0, 1, 0}}, Case{{4, -2, 3}, normalize(Vec3(0, 1, 1))},
                 Case{{-3, 5, 0}, normalize(Vec3(1, -1, 2))}, Case{{1, 2, 13}, {0, 0, 1}}}) {
    Vec3 d = point.position - c.x;
    float r2 = length_sq(d);
    float cosine = std::max(0.0f, dot(c.n, d) / std::sqrt(r2));
    expect_rgb_near(nee_irradiance(l, c.x, c.n), point.intensity * (cosine / r2), 1e-5f, "point");
    LightSample ls;
    ASSERT_TRUE(l.sample(c.x, Vec3(0.0f), 0.1f, {0.2f, 0.3f}, ls));
    EXPECT_FALSE(ls.is_infinite);
    EXPECT_EQ(ls.p, point.position);
    EXPECT_NEAR(ls.distance, std::sqrt(r2), 1e-5f * std::sqrt(r2));
  }
}

// E = E0 max(0, n . -direction) anywhere; the sample point is 2R beyond p (R = sqrt 3 for the
// unit sphere's bounding box). Float arithmetic only: 1e-5.
TEST(Lights, DirectionalIrradiance) {
  Scene s = scene_of({test::make_uv_sphere({0, 0, 0}, 1.0f, 8, 16, 0)}, "directional");
  Light sun{"sun", LightType::Directional};
  sun.direction = normalize(Vec3(1, -2, 0.5f));
  sun.irradiance = RGB(1, 0.5f, 0.25f);
  s.lights = {sun};
  LightSet l(s);
  EXPECT_NEAR(l.scene_radius(), std::sqrt(3.0f), 1e-5f);
  for (Vec3 n :
       {Vec3(0, 1, 0), normalize(Vec3(-1, 2, -0.5f)), normalize(Vec3(1, 1, 1)), Vec3(0, -1, 0)}) {
    float cosine = std::max(0.0f, dot(n, -sun.direction));
    expect_rgb_near(nee_irradiance(l, {0.3f, 0.2f, -0.1f}, n), sun.irradiance * cosine, 1e-5f,
                    "directional");
  }
  LightSample ls;
  Vec3 p{0.3f, 0.2f, -0.1f};
  ASSERT_TRUE(l.sample(p, Vec3(0.0f), 0.5f, {0.5f, 0.5f}, ls));
  EXPECT_TRUE(ls.is_infinite);
  EXPECT_NEAR(length(ls.wi + sun.direction), 0.0f, 1e-6f);
  EXPECT_NEAR(length(ls.p - (p - sun.direction * (2 * std::sqrt(3.0f)))), 0.0f, 1e-5f);
  double power = M_PI * 3 * luminance(sun.irradiance);
  EXPECT_NEAR(l.selection_power(0), power, 1e-5 * power);
}

// When no light has power (a black point light alone), selection is uniform, pmfs still sum to
// 1, and sampling never returns a light that emits nothing.
TEST(Lights, LightsWithoutPowerAreNeverReturned) {
  Scene s = scene_of({}, "no_power");
  Light black{"black", LightType::Point, {0, 1, 0}, {0, -1, 0}, RGB(0.0f)};
  s.lights = {black};
  LightSet l(s);
  EXPECT_EQ(l.selection_pmf(0), 1.0f);
  LightSample ls;
  EXPECT_FALSE(l.sample({0, 0, 0}, Vec3(0.0f), 0.5f, {0.5f, 0.5f}, ls));
  EXPECT_TRUE(LightSet(scene_of({}, "empty")).empty());
}

Scene two_light_scene() {
  Material m{"m", MaterialType::Diffuse, {RGB(0.5f)}};
  Mesh a = test::make_uv_sphere({-2, 0, 0}, 0.5f, 6, 12, 0);
  a.emission = Emission{RGB(4, 1, 1), false};
  Mesh b = test::make_uv_sphere({2, 0, 0}, 1.0f, 6, 12, 0);
  b.emission = Emission{RGB(1, 1, 1), true};
  Mesh c = test::make_uv_sphere({0, 3, 0}, 1.0f, 4, 8, 0);  // not a light
  return test::make_scene({m}, {a, b, c}, {0, 0, 8}, {0, 0, 0}, 8, 8, "lights");
}

TEST(Lights, SelectionProbabilitiesSumToOneAndFollowPower) {
  Scene s = two_light_scene();
  LightSet lights(s);
  ASSERT_EQ(lights.size(), s.meshes[0].triangle_count() + s.meshes[1].triangle_count());
  double total = 0;
  for (size_t i = 0; i < lights.size(); ++i) total += lights.selection_pmf(i);
  EXPECT_NEAR(total, 1.0, 1e-5);  // float pmfs of ~130 lights: rounding only
}

TEST(Lights, SampledPdfEqualsPdfQuery) {
  Scene s = two_light_scene();
  Accel accel(s);
  LightSet lights(s);
  IndependentSampler smp;
  Vec3 p{0, 0, 0};
  int checked = 0;
  for (int i = 0; i < 2000; ++i) {
    smp.start_light_path(1, 0, 0, uint64_t(i));
    LightSample ls;
    if (!lights.sample(p, Vec3(0.0f), smp.get_1d(), smp.get_2d(), ls)) continue;
    // Find which triangle the sample lies on by tracing towards it.
    SurfaceHit hit;
    ASSERT_TRUE(accel.intersect(Ray{p, ls.wi, kInf}, hit));
    if (std::fabs(hit.t - ls.distance) > 1e-3f * ls.distance) continue;  // occluded by the sphere itself
    // A sample on a triangle's edge may be hit on its neighbour, whose normal (so pdf) differs.
    if (std::fabs(dot(hit.ng, ls.n)) < 1 - 1e-5f) continue;
    float q = lights.pdf_solid_angle(p, Vec3(0.0f), hit.mesh, hit.prim, hit.p, hit.ng);
    EXPECT_NEAR(q, ls.pdf_solid_angle, 1e-3f * ls.pdf_solid_angle);
    ++checked;
  }
  EXPECT_GT(checked, 500);
}

}  // namespace
}  // namespace rf
