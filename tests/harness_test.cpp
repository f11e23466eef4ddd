// The statistics harness (tests/support/harness.h) checked against exact values, against
// synthetic images with known answers, and on real renders of the Cornell box: it must pass two
// seeds of the same render and fail renders biased by an albedo x0.98 and by one bounce fewer.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <random>

#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/fixtures.h"
#include "tests/support/harness.h"
#include "tests/support/test_support.h"

namespace rf::test {
namespace {

// ---------------------------------------------------------------------------------------------
// Special functions against closed forms and tables

TEST(HarnessMath, IncompleteBetaMatchesClosedForms) {
  // I_x(a, 1) = x^a, I_x(1, b) = 1 - (1-x)^b, I_{1/2}(a, a) = 1/2, I_x(a, b) = 1 - I_{1-x}(b, a).
  for (double x : {1e-6, 0.01, 0.3, 0.5, 0.77, 0.999}) {
    for (double a : {0.5, 1.0, 2.5, 40.0}) {
      EXPECT_NEAR(incomplete_beta(a, 1, x), std::pow(x, a), 1e-13 + 1e-12 * std::pow(x, a));
      EXPECT_NEAR(incomplete_beta(1, a, x), 1 - std::pow(1 - x, a), 1e-12);
      EXPECT_NEAR(incomplete_beta(a, 3.5, x) + incomplete_beta(3.5, a, 1 - x), 1.0, 1e-12);
    }
  }
  // Both parameters large is not the t test's case (b = 1/2): there lgamma(a) ~ 1e7 leaves ~1e-9.
  for (double a : {0.5, 3.0, 1e3}) EXPECT_NEAR(incomplete_beta(a, a, 0.5), 0.5, 1e-12);
  EXPECT_NEAR(incomplete_beta(1e6, 1e6, 0.5), 0.5, 1e-8);
}

// Two-sided p of Student's t by Abramowitz & Stegun 26.7.3 (even dof) and 26.7.4 (odd dof):
// with theta = atan(t / sqrt(dof)), A(t|dof) = P(|T| < t) is a finite trigonometric sum.
double student_p_closed_form(double t, int dof) {
  double th = std::atan(std::fabs(t) / std::sqrt(double(dof))), s = std::sin(th), c = std::cos(th);
  double a;
  if (dof % 2 == 0) {
    double term = 1, sum = 1;
    for (int k = 2; k <= dof - 2; k += 2) sum += (term *= c * c * double(k - 1) / k);
    a = s * sum;
  } else {
    double inner = 0;
    if (dof > 1) {
      double term = c;
      inner = c;
      for (int k = 3; k <= dof - 2; k += 2) inner += (term *= c * c * double(k - 1) / k);
    }
    a = 2 / M_PI * (th + s * inner);
  }
  return 1 - a;
}

TEST(HarnessMath, StudentTPValueMatchesClosedForms) {
  for (int dof : {1, 2, 3, 5, 10, 31, 62}) {
    for (double t : {0.0, 0.3, 1.0, 2.0, 3.5, 6.0}) {
      double p = student_t_two_sided_p(t, dof), ref = student_p_closed_form(t, dof);
      // 1e-10 relative, plus 1e-14 absolute for the closed form's 1 - A cancellation at small p.
      EXPECT_NEAR(p, ref, 1e-10 * ref + 1e-14) << "t " << t << " dof " << dof;
      EXPECT_EQ(p, student_t_two_sided_p(-t, dof));
    }
  }
}

TEST(HarnessMath, StudentTTwoSidedCriticalValuesGiveOnePerMille) {
  // Tables of Student's t (two-sided 0.001, e.g. NIST/SEMATECH e-Handbook 1.3.6.7.2), printed to
  // three decimals: t = 4.587 at dof 10, 3.646 at dof 30, 3.291 at dof infinity (here 1e6). The
  // rounding of t moves p by at most (dof+1) t / (dof + t^2) * 5e-4 relative: < 0.2%.
  EXPECT_NEAR(student_t_two_sided_p(4.587, 10), 0.001, 0.002 * 0.001);
  EXPECT_NEAR(student_t_two_sided_p(3.646, 30), 0.001, 0.002 * 0.001);
  EXPECT_NEAR(student_t_two_sided_p(3.291, 1e6), 0.001, 0.002 * 0.001);
  // Large dof: the normal tail plus its first-order correction (Cornish-Fisher / Abramowitz &
  // Stegun 26.7.5), 2 Q(t) + 2 phi(t) (t^3 + t) / (4 dof); the next term is O(t^7 / dof^2) relative
  // to phi(t): 1.6e-8 relative at t = 5, dof 1e6, so 1e-7 relative is the tolerance.
  for (double dof : {1e6, 1e7}) {
    for (double t : {1.0, 3.2905267, 5.0}) {
      double phi = std::exp(-0.5 * t * t) / std::sqrt(2 * M_PI);
      double ref = std::erfc(t / std::sqrt(2.0)) + 2 * phi * (t * t * t + t) / (4 * dof);
      EXPECT_NEAR(student_t_two_sided_p(t, dof), ref, 1e-7 * ref) << "t " << t << " dof " << dof;
    }
  }
  EXPECT_EQ(student_t_two_sided_p(2.0, 0.0), 1.0);  // no dof: no evidence
}

TEST(HarnessMath, BinomialQuantileMatchesExactSums) {
  // References: smallest k with P(X <= k) >= q, summed in exact rational arithmetic (Python's
  // fractions and math.comb). Binomial(1000, 0.001): P(X <= 4) = 0.996363 < 0.999 <=
  // P(X <= 5) = 0.999412, so the quantile is 5 (Poisson(1) gives the same).
  EXPECT_EQ(binomial_quantile(1000, 0.001, 0.999), 5u);
  EXPECT_EQ(binomial_quantile(3072, 0.001, 0.999), 10u);   // P(<=9) 0.998698, P(<=10) 0.999648
  EXPECT_EQ(binomial_quantile(12288, 0.001, 0.999), 24u);  // P(<=23) 0.998020, P(<=24) 0.999058
  EXPECT_EQ(binomial_quantile(10000, 0.001, 0.999), 21u);
  EXPECT_EQ(binomial_quantile(100, 0.001, 0.999), 2u);
  EXPECT_EQ(binomial_quantile(10, 0.001, 0.999), 1u);
  EXPECT_EQ(binomial_quantile(1, 0.001, 0.999), 0u);  // P(X = 0) = 0.999 exactly
  EXPECT_EQ(binomial_quantile(0, 0.001, 0.999), 0u);
  EXPECT_EQ(binomial_quantile(10, 0.5, 0.5), 5u);  // P(<=4) 0.377, P(<=5) 0.623
}

// ---------------------------------------------------------------------------------------------
// ImageStats bookkeeping

SampleBuffer one_pass_buffer(int w, int h, uint32_t pass, const std::vector<double>& rgb) {
  BufferHeader hd;
  hd.width = w;
  hd.height = h;
  hd.passes = PassSet::range(pass, pass + 1);
  SampleBuffer b(hd, Rect{0, 0, w, h}, false);
  for (size_t i = 0; i < b.count.size(); ++i) {
    b.count[i] = 1;
    for (int c = 0; c < 3; ++c) b.sum[3 * i + size_t(c)] = rgb[3 * i + size_t(c)];
  }
  b.finish_pass();
  return b;
}

TEST(HarnessStats, BlockMeansVariancesAndPartialBlocks) {
  const int w = 10, h = 6;  // block 4: 3x2 blocks, the last column 2 wide, the last row 2 high
  ImageStats s(w, h, 4);
  EXPECT_EQ(s.blocks_x(), 3);
  EXPECT_EQ(s.blocks_y(), 2);
  // Pass k: pixel value (x + 10 y) * (1 + k) in R, constant 0.25 in G, k in B (all exact in float).
  for (uint32_t k = 0; k < 3; ++k) {
    std::vector<double> rgb(size_t(w) * h * 3);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        size_t i = 3 * size_t(y * w + x);
        rgb[i] = (x + 10.0 * y) * (1 + k);
        rgb[i + 1] = 0.25;
        rgb[i + 2] = k;
      }
    s.add_pass(one_pass_buffer(w, h, k, rgb));
  }
  EXPECT_EQ(s.passes(), 3u);
  // Block (2, 1) holds x 8..9, y 4..5: mean of x + 10 y = 8.5 + 45 = 53.5; passes scale 1, 2, 3.
  EXPECT_DOUBLE_EQ(s.mean(2, 1, 0), 53.5 * 2);
  // Per-pass block values 53.5 * {1, 2, 3}: s^2 = 53.5^2, variance of the mean s^2 / 3.
  EXPECT_NEAR(s.variance_of_mean(2, 1, 0), 53.5 * 53.5 / 3, 1e-9);
  EXPECT_TRUE(s.zero_variance(2, 1, 1));
  EXPECT_EQ(s.variance_of_mean(2, 1, 1), 0.0);
  EXPECT_DOUBLE_EQ(s.mean(0, 0, 2), 1.0);
  EXPECT_NEAR(s.variance_of_mean(0, 0, 2), 1.0 / 3, 1e-12);  // values 0,1,2: s^2 = 1
  // Image mean is pixel-weighted: mean of x + 10 y over 10x6 = 4.5 + 25 = 29.5, times mean scale 2.
  EXPECT_NEAR(s.image_mean(0), 29.5 * 2, 1e-12);
  EXPECT_NEAR(s.image_mean(1), 0.25, 1e-15);
  EXPECT_NEAR(s.image_mean_std_error(2), std::sqrt(1.0 / 3), 1e-12);
}

TEST(HarnessStats, VarianceHasNoCancellationOnLargeMeans) {
  // Values 1e4 + k * 1e-6, k = 0..31: s^2 = 1e-12 * 32 * 33 / 12 exactly. Unshifted sums of
  // squares (~3.2e9, rounding ~5e-7) would lose it entirely; 1e-6 relative is the tolerance.
  ImageStats s(1, 1, 1);
  for (int k = 0; k < 32; ++k) s.add_pass_image({1e4 + k * 1e-6, 1.0, 1.0});
  EXPECT_NEAR(s.variance_of_mean(0, 0, 0), 1e-12 * 32 * 33 / 12 / 32, 1e-6 * 1e-12 * 33 / 12);
  EXPECT_NEAR(s.mean(0, 0, 0), 1e4 + 15.5e-6, 1e-10);
}

TEST(HarnessStats, RejectsWhatItCannotCompare) {
  ImageStats s(8, 8, 1);
  BufferHeader hd;
  hd.width = 8;
  hd.height = 8;
  hd.passes = PassSet::range(0, 1);
  EXPECT_THROW(s.add_pass(SampleBuffer(hd, Rect{0, 0, 4, 8}, false)), std::invalid_argument);
  hd.passes = PassSet::range(0, 2);
  EXPECT_THROW(s.add_pass(SampleBuffer(hd, Rect{0, 0, 8, 8}, false)), std::invalid_argument);
  ImageStats a(8, 8, 1), b(8, 8, 4);
  std::vector<double> img(8 * 8 * 3, 1.0);
  for (int k = 0; k < 2; ++k) a.add_pass_image(img), b.add_pass_image(img);
  EXPECT_THROW(compare(a, b), std::invalid_argument);
  ImageStats one(8, 8, 1);
  one.add_pass_image(img);
  EXPECT_THROW(compare(a, one), std::invalid_argument);
  Scene scene = make_scene({Material{}}, {make_uv_sphere(Vec3(0.0f), 1, 8, 16, 0)}, Vec3(0, 0, 5),
                           Vec3(0.0f), 8, 8, "harness-reject");
  EXPECT_THROW(render_stats(scene, 31, 1), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// Synthetic images: Gaussian pass images with known means

// passes images of w x h, pixel (x, y) channel c ~ N(mu(x, y, c), sigma(x, y, c)^2).
using PixelFn = std::function<double(int, int, int)>;
ImageStats gaussian_stats(int w, int h, int block, uint32_t passes, const PixelFn& mu,
                          const PixelFn& sigma, uint64_t seed) {
  ImageStats s(w, h, block);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  std::vector<double> rgb(size_t(w) * h * 3);
  for (uint32_t k = 0; k < passes; ++k) {
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        for (int c = 0; c < 3; ++c)
          rgb[3 * size_t(y * w + x) + size_t(c)] = mu(x, y, c) + sigma(x, y, c) * normal(rng);
    s.add_pass(one_pass_buffer(w, h, k, rgb));
  }
  return s;
}

// A smooth image around 1 with channel-dependent levels.
double base_mu(int x, int y, int c) { return (1.0 + 0.5 * std::sin(0.2 * x + 0.3 * y)) * (1 + c); }

TEST(HarnessSynthetic, IdenticalDistributionsAgree) {
  // Noisy (sigma 0.3 per pass against means ~1) and with unequal noise between the two (Welch).
  auto sigma_a = [](int, int, int c) { return 0.3 * (1 + c); };
  auto sigma_b = [](int x, int, int c) { return (0.2 + 0.004 * x) * (1 + c); };
  ImageStats a = gaussian_stats(64, 64, 1, 32, base_mu, sigma_a, 1);
  ImageStats b = gaussian_stats(64, 64, 1, 48, base_mu, sigma_b, 2);
  Agreement r = compare(a, b);
  EXPECT_TRUE(r.passed) << r.message;
  EXPECT_EQ(r.cells, 64u * 64u * 3u);
  EXPECT_EQ(r.allowed_outliers, 24u);  // Binomial(12288, 0.001) at 0.999
  std::printf("identical: %s\n", r.message.c_str());
}

TEST(HarnessSynthetic, TwoPercentShiftFails) {
  auto shifted = [](int x, int y, int c) { return 1.02 * base_mu(x, y, c); };
  {
    // Noisy pixels: each pixel's t is ~0.3, invisible per pixel; the image mean catches it.
    auto sigma = [](int, int, int c) { return 0.3 * (1 + c); };
    Agreement r = compare(gaussian_stats(64, 64, 1, 32, base_mu, sigma, 3),
                          gaussian_stats(64, 64, 1, 32, shifted, sigma, 4));
    std::printf("2%% shift, noisy: %s\n", r.message.c_str());
    EXPECT_FALSE(r.passed) << r.message;
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(r.mean_rel_diff[c], 0.02 / 1.02, 0.002);
  }
  {
    // Quiet pixels (sigma 0.02: the 2% shift is ~4 standard errors per pixel): outliers too.
    auto sigma = [](int, int, int c) { return 0.02 * (1 + c); };
    Agreement r = compare(gaussian_stats(64, 64, 1, 32, base_mu, sigma, 5),
                          gaussian_stats(64, 64, 1, 32, shifted, sigma, 6));
    std::printf("2%% shift, quiet: %s\n", r.message.c_str());
    EXPECT_FALSE(r.passed) << r.message;
    EXPECT_GT(r.outliers, 10 * r.allowed_outliers) << r.message;
  }
}

TEST(HarnessSynthetic, LocalBiasFailsByOutliersAlone) {
  // 40 pixels off by 6 standard errors of the difference: the image means still agree (< 0.1%).
  auto sigma = [](int, int, int) { return 0.3; };
  double se_diff = 0.3 * std::sqrt(2.0 / 32);
  auto biased = [&](int x, int y, int c) {
    return base_mu(x, y, c) + ((y == 10 && x < 40) ? 6 * se_diff : 0.0);
  };
  Agreement r = compare(gaussian_stats(64, 64, 1, 32, base_mu, sigma, 7),
                        gaussian_stats(64, 64, 1, 32, biased, sigma, 8));
  std::printf("local bias: %s\n", r.message.c_str());
  EXPECT_FALSE(r.passed) << r.message;
  EXPECT_GT(r.outliers, r.allowed_outliers) << r.message;
  for (int c = 0; c < 3; ++c) EXPECT_LT(r.mean_rel_diff[c], 0.01);
}

TEST(HarnessSynthetic, ZeroVarianceCellsMustBeEqual) {
  // The left 8 columns are constant in every pass (an emitter seen directly).
  auto sigma = [](int x, int, int) { return x < 8 ? 0.0 : 0.3; };
  auto mu_b = [](int x, int y, int c) {
    return x == 3 && y == 5 ? 1.001 * base_mu(x, y, c) : base_mu(x, y, c);
  };
  ImageStats a = gaussian_stats(32, 32, 1, 32, base_mu, sigma, 9);
  Agreement same = compare(a, gaussian_stats(32, 32, 1, 32, base_mu, sigma, 10));
  EXPECT_TRUE(same.passed) << same.message;
  EXPECT_EQ(same.zero_variance_cells, 8u * 32u * 3u);
  EXPECT_EQ(same.zero_variance_mismatches, 0u);
  Agreement differ = compare(a, gaussian_stats(32, 32, 1, 32, mu_b, sigma, 10));
  std::printf("zero variance mismatch: %s\n", differ.message.c_str());
  EXPECT_FALSE(differ.passed) << differ.message;
  EXPECT_EQ(differ.zero_variance_mismatches, 3u);
}

TEST(HarnessSynthetic, FalseAlarmRateIsTheLevel) {
  // Same distribution, 20 comparisons of 64x64x3 cells at 32 vs 32 passes: with Gaussian passes
  // Welch's t is nearly exact, so the outlier fraction is 0.001. Over N = 245760 cells the count
  // has sd sqrt(N 0.001) = 15.7; the bound is 4 sd (a false failure ~1 in 10^4 runs).
  size_t cells = 0, outliers = 0;
  auto sigma = [](int x, int, int c) { return (0.1 + 0.01 * x) * (1 + c); };
  for (uint64_t i = 0; i < 20; ++i) {
    Agreement r = compare(gaussian_stats(64, 64, 1, 32, base_mu, sigma, 100 + 2 * i),
                          gaussian_stats(64, 64, 1, 32, base_mu, sigma, 101 + 2 * i));
    cells += r.cells;
    outliers += r.outliers;
  }
  double expected = 0.001 * double(cells), sd = std::sqrt(expected * 0.999);
  std::printf("false alarms: %zu of %zu cells (expected %.1f, sd %.1f)\n", outliers, cells,
              expected, sd);
  EXPECT_NEAR(double(outliers), expected, 4 * sd);
}

// ---------------------------------------------------------------------------------------------
// Real renders: the shipped Cornell box (max depth 64) at 64x64, 64 spp per pass, 32 passes.
//
// Why not 4 spp per pass at 32x32: there each render's image mean has a standard error of ~1%
// (measured: R 0.8%, B 1.0%), so two seeds differ by more than the 1% mean tolerance about half
// the time (measured: 1.8% R, 2.3% B between seeds 1 and 2). At 64 spp per pass and 64x64 it
// is ~0.1% (measured R 0.09%, B 0.12%; the difference of two renders 0.18% in B), so the 1%
// tolerance is over 5 standard errors of the difference, and a render takes ~4 s (2 cores). 64x64
// also leaves 12 pixels wholly inside the light: constant in every pass, so the zero-variance
// branch is exercised on a real render.

class HarnessCornell : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { reference_ = new ImageStats(render_stats(cornell_box({"", 64, 64, 32, 1, 64}), 32, 1)); }
  static void TearDownTestSuite() {
    delete reference_;
    reference_ = nullptr;
  }
  static ImageStats* reference_;
};
ImageStats* HarnessCornell::reference_ = nullptr;

TEST_F(HarnessCornell, TwoSeedsAgree) {
  Agreement r = compare(*reference_, render_stats(cornell_box({"", 64, 64, 32, 2, 64}), 32, 1));
  std::printf("two seeds: %s\n", r.message.c_str());
  EXPECT_TRUE(r.passed) << r.message;
  EXPECT_GT(r.zero_variance_cells, 0u) << "pixels wholly inside the light should be constant";
}

// Every reflectance x0.98: direct light drops 2%, k-bounce light by 0.98^k, the visible light
// not at all; measured, the image means drop 1.5-2.3% (z 8.5-16) and 481 of 12252 cells are
// outliers (24 allowed).
// Both the outlier count and the mean check must catch it on their own.
TEST_F(HarnessCornell, AlbedoTimes098Fails) {
  Scene s = cornell_box({"", 64, 64, 32, 3, 64});
  for (Material& m : s.materials) m.reflectance.value = m.reflectance.value * 0.98f;
  Agreement r = compare(*reference_, render_stats(s, 32, 1));
  std::printf("albedo x0.98: %s\n", r.message.c_str());
  EXPECT_FALSE(r.passed) << r.message;
  EXPECT_GT(r.outliers, r.allowed_outliers) << r.message;
  EXPECT_GT(r.mean_rel_diff[0], 0.01) << r.message;
}

// One bounce fewer. At depth 64 vs 63 the missing light is that of 64-bounce paths, ~0.6^64 of
// the image (~1e-14), far below any noise (measured: the two agree, image means within 0.07%):
// not a test of anything. At depth 4 vs 3 the fourth bounce carries 3.7% of R (measured: 2962
// outlier cells of 12252, 24 allowed; means 3.7% R, 2.9% G, 1.4% B apart).
TEST(HarnessCornellDepth, OneBounceFewerFails) {  // no reference render needed
  Agreement r = compare(render_stats(cornell_box({"", 64, 64, 32, 4, 4}), 32, 1), render_stats(cornell_box({"", 64, 64, 32, 5, 3}), 32, 1));
  std::printf("depth 4 vs 3: %s\n", r.message.c_str());
  EXPECT_FALSE(r.passed) << r.message;
  EXPECT_GT(r.outliers, r.allowed_outliers) << r.message;
  EXPECT_GT(r.mean_rel_diff[0], 0.01) << r.message;
}

}  // namespace
}  // namespace rf::test
