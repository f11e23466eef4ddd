// Tests of engine/sample_buffer: accumulation, splats, the batch-means variance and relMSE.
#include "engine/sample_buffer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "engine/buffer_merge.h"
#include "tests/support/fixtures.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

TEST(SampleBuffer, ConstructorSizesPlanes) {
  BufferHeader h = test::test_header(PassSet::range(0, 1), 8, 6);
  SampleBuffer tile(h, Rect{2, 1, 4, 3}, false);
  EXPECT_EQ(tile.count.size(), 12u);
  EXPECT_EQ(tile.sum.size(), 36u);
  EXPECT_EQ(tile.batch_sum_sq.size(), 36u);
  EXPECT_TRUE(tile.splat.empty());
  SampleBuffer whole(h, test::full_frame(h), true);
  EXPECT_EQ(whole.splat.size(), 8u * 6u * 3u);
  EXPECT_THROW(SampleBuffer(h, Rect{6, 0, 4, 2}, false), std::invalid_argument);
}

TEST(SampleBuffer, AddSampleAccumulatesAndCountsNonFinite) {
  BufferHeader h = test::test_header(PassSet::range(0, 1));
  SampleBuffer b(h, Rect{2, 2, 3, 2}, false);
  b.add_sample(3, 3, RGB(1.0f, 2.0f, 3.0f));
  b.add_sample(3, 3, RGB(3.0f, 2.0f, 1.0f));
  b.add_sample(3, 3, RGB(std::nanf(""), 1.0f, 1.0f));
  b.add_sample(3, 3, RGB(1.0f, kInf, 1.0f));
  size_t i = b.pixel_index(3, 3);
  EXPECT_EQ(i, 4u);  // row 1 of the rect, column 1
  EXPECT_EQ(b.count[i], 4u);
  EXPECT_EQ(b.nonfinite_samples, 2u);
  EXPECT_EQ(b.sum[3 * i + 0], 4.0);  // non-finite samples contribute exactly zero
  EXPECT_EQ(b.sum_sq[3 * i + 0], 10.0);
  EXPECT_EQ(b.total_samples(), 4u);
  RGB e = b.estimate(3, 3);  // sums / count, the NaN/Inf samples count as zeros
  EXPECT_FLOAT_EQ(e.x, 1.0f);
  EXPECT_FLOAT_EQ(e.y, 1.0f);
  EXPECT_FLOAT_EQ(e.z, 1.0f);
  EXPECT_EQ(b.estimate(2, 2), RGB(0.0f));  // no samples: 0
}

TEST(SampleBuffer, SplatsAreNormalisedByLightPaths) {
  BufferHeader h = test::test_header(PassSet::range(0, 1), 4, 4);
  SampleBuffer b(h, test::full_frame(h), true);
  b.add_sample(1, 2, RGB(1.0f));
  b.add_splat(1, 2, RGB(6.0f, 3.0f, 0.0f));
  b.add_splat(1, 2, RGB(std::nanf(""), 0.0f, 0.0f));  // counted, dropped
  b.add_splat(-1, 2, RGB(1.0f));                      // outside the frame: ignored
  b.add_splat(4, 0, RGB(1.0f));
  EXPECT_EQ(b.nonfinite_samples, 1u);
  EXPECT_EQ(b.estimate(1, 2), RGB(1.0f));  // light_paths == 0: splats not yet normalisable
  b.light_paths = 3;
  RGB e = b.estimate(1, 2);
  EXPECT_FLOAT_EQ(e.x, 3.0f);
  EXPECT_FLOAT_EQ(e.y, 2.0f);
  EXPECT_FLOAT_EQ(e.z, 1.0f);
  double total = 0;
  for (double v : b.splat) total += v;
  EXPECT_EQ(total, 9.0);
}

TEST(SampleBuffer, FinishPassNeedsExactlyOnePass) {
  BufferHeader h = test::test_header(PassSet::range(0, 2));
  SampleBuffer b(h, test::full_frame(h), false);
  EXPECT_THROW(b.finish_pass(), std::logic_error);
  SampleBuffer one(test::test_header(PassSet::range(3, 4)), test::full_frame(h), false);
  one.add_sample(0, 0, RGB(2.0f, 4.0f, 0.5f));
  one.add_sample(0, 0, RGB(0.0f));
  one.finish_pass();
  EXPECT_EQ(one.batch_sum[0], 1.0);
  EXPECT_EQ(one.batch_sum[1], 2.0);
  EXPECT_EQ(one.batch_sum_sq[1], 4.0);
  EXPECT_EQ(one.batch_sum_sq[2], 0.0625);
}

// Builds a one-pixel-per-value buffer of n passes whose pass estimates are `values` (all
// channels alike), through finish_pass and merge as a renderer would.
SampleBuffer passes_with_values(const std::vector<std::vector<float>>& per_pixel_values) {
  size_t npix = per_pixel_values.size(), n = per_pixel_values[0].size();
  SampleBuffer acc(test::test_header(PassSet{}, int(npix), 1), Rect{0, 0, int(npix), 1}, false);
  for (size_t k = 0; k < n; ++k) {
    SampleBuffer p(test::test_header(PassSet::range(uint32_t(k), uint32_t(k) + 1), int(npix), 1),
                   Rect{0, 0, int(npix), 1}, false);
    for (size_t x = 0; x < npix; ++x) p.add_sample(int(x), 0, RGB(per_pixel_values[x][k]));
    p.finish_pass();
    merge_into(acc, p);
  }
  return acc;
}

TEST(SampleBuffer, BatchMeansVarianceHandComputed) {
  // Pass estimates 1, 2, 4: mean 7/3, s^2 = (16/9 + 1/9 + 25/9) / 2 = 7/3, Var(mean) = 7/9.
  SampleBuffer b = passes_with_values({{1.0f, 2.0f, 4.0f}});
  EXPECT_EQ(b.header.passes.to_string(), "0-2");
  RGB v = b.variance_of_mean(0, 0);
  EXPECT_NEAR(v.x, 7.0 / 9.0, 1e-6);  // float result: rounding only
  EXPECT_NEAR(v.z, 7.0 / 9.0, 1e-6);
  // A single pass has no batch-means variance.
  SampleBuffer one = passes_with_values({{5.0f}});
  EXPECT_EQ(one.variance_of_mean(0, 0), RGB(0.0f));
  EXPECT_EQ(one.rel_mse(), 0.0);
  // Identical passes: variance clamps at exactly 0 despite cancellation.
  SampleBuffer same = passes_with_values({{0.1f, 0.1f, 0.1f, 0.1f}});
  EXPECT_GE(same.variance_of_mean(0, 0).x, 0.0f);
  EXPECT_LT(same.variance_of_mean(0, 0).x, 1e-15f);
}

TEST(SampleBuffer, BatchMeansVarianceMatchesKnownVariance) {
  // Gaussian pass estimates N(mu, sigma^2), n passes, P pixels x 3 channels. Each s^2 is
  // sigma^2 chi2(n-1)/(n-1), so the mean over 3P values of Var(mean) = s^2/n has expectation
  // sigma^2/n and relative std sqrt(2/(n-1)/(3P)) = sqrt(2/15/12288) = 0.33%. A 4-sigma band
  // (1.3%, false failure < 1e-4) is the tolerance; the seed is fixed, so the run is repeatable.
  const int w = 64, h = 64;
  const uint32_t n = 16;
  const double mu = 2.0, sigma = 0.5;
  std::mt19937_64 rng(20240601);
  std::normal_distribution<double> g(mu, sigma);
  SampleBuffer acc(test::test_header(PassSet{}, w, h), Rect{0, 0, w, h}, false);
  for (uint32_t k = 0; k < n; ++k) {
    SampleBuffer p(test::test_header(PassSet::range(k, k + 1), w, h), Rect{0, 0, w, h}, false);
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        p.add_sample(x, y, RGB(float(g(rng)), float(g(rng)), float(g(rng))));
      }
    }
    p.finish_pass();
    merge_into(acc, p);
  }
  double mean_var = 0, mean_est = 0;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      RGB v = acc.variance_of_mean(x, y), e = acc.estimate(x, y);
      mean_var += double(v.x) + v.y + v.z;
      mean_est += double(e.x) + e.y + e.z;
    }
  }
  mean_var /= 3.0 * w * h;
  mean_est /= 3.0 * w * h;
  double expected = sigma * sigma / n;
  EXPECT_NEAR(mean_var, expected, 4 * 0.0033 * expected);
  // The grand mean has std sigma / sqrt(3 P n) = 0.0011; 4 sigma.
  EXPECT_NEAR(mean_est, mu, 4 * sigma / std::sqrt(3.0 * w * h * n));
}

TEST(SampleBuffer, RelMseHandComputed) {
  // Pixel 0: passes 1 and 3 -> mean 2, s^2 = 2, Var(mean) = 1, term 1 / (4 + 0.01) per channel.
  // Pixel 1: passes 0.5 and 0.5 -> Var 0. relMSE = (3 / 4.01 + 0) / 6.
  SampleBuffer b = passes_with_values({{1.0f, 3.0f}, {0.5f, 0.5f}});
  EXPECT_NEAR(b.rel_mse(), 0.5 / 4.01, 1e-12);
  RGB m = b.mean_estimate();
  EXPECT_FLOAT_EQ(m.x, 1.25f);
}

}  // namespace
}  // namespace rf
