// Tests of engine/filter: box, triangle and gaussian filter importance sampling (support,
// weights, exact inverse CDFs, chi-square of the sampled offsets against the filter) and the
// normalised filter_weight that splats use.
#include "engine/filter.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "engine/sampler.h"
#include "tests/support/chisq.h"

namespace rf {
namespace {

FilterSettings make(FilterType type, float radius, float sigma = 0.5f) {
  FilterSettings f;
  f.type = type;
  f.radius = radius;
  f.sigma = sigma;
  return f;
}

std::string describe(const FilterSettings& f) {
  const char* names[] = {"box", "triangle", "gaussian"};
  return std::string(names[int(f.type)]) + " r=" + std::to_string(f.radius) +
         " sigma=" + std::to_string(f.sigma);
}

// The filters under test: default sizes, wide, narrow-in-wide (tails matter), nearly flat.
std::vector<FilterSettings> filters() {
  return {make(FilterType::Box, 0.5f),
          make(FilterType::Box, 1.5f),
          make(FilterType::Triangle, 1.0f),
          make(FilterType::Triangle, 2.0f),
          make(FilterType::Gaussian, 1.5f, 0.5f),
          make(FilterType::Gaussian, 2.0f, 1.0f),
          make(FilterType::Gaussian, 3.0f, 0.3f),
          make(FilterType::Gaussian, 1.0f, 2.0f)};
}

Vec2 uniform_2d(uint64_t i) {
  IndependentSampler s;
  s.start_light_path(0x66696c746572ULL, 0, 0, i);  // fixed seed: repeatable
  return s.get_2d();
}

TEST(FilterTest, ErfInvInvertsErf) {
  for (double y : {-0.999999, -0.9, -0.5, -1e-9, 0.0, 0.3, 0.7, 0.99, 0.999999999})
    EXPECT_NEAR(std::erf(erf_inv(y)), y, 1e-14) << y;
  EXPECT_EQ(erf_inv(1.0), HUGE_VAL);
  EXPECT_EQ(erf_inv(-1.0), -HUGE_VAL);
}

TEST(FilterTest, BoxIsUnchanged) {
  FilterSample s = sample_filter(make(FilterType::Box, 0.5f), {0.25f, 0.75f});
  EXPECT_EQ(s.offset.x, -0.25f);
  EXPECT_EQ(s.offset.y, 0.25f);
  EXPECT_EQ(s.weight, 1.0f);
}

// Offsets stay within the radius, weights are exactly 1 (exact sampling), also at u's extremes.
TEST(FilterTest, SupportAndWeights) {
  const float extremes[] = {0.0f, 0x1p-24f, 0.5f, 1.0f - 0x1p-24f};
  for (const FilterSettings& f : filters()) {
    for (float a : extremes)
      for (float b : extremes) {
        FilterSample s = sample_filter(f, {a, b});
        EXPECT_TRUE(std::isfinite(s.offset.x) && std::isfinite(s.offset.y)) << describe(f);
        EXPECT_LE(std::fabs(s.offset.x), f.radius) << describe(f);
        EXPECT_LE(std::fabs(s.offset.y), f.radius) << describe(f);
      }
    for (uint64_t i = 0; i < 100000; ++i) {
      FilterSample s = sample_filter(f, uniform_2d(i));
      ASSERT_LE(std::fabs(s.offset.x), f.radius) << describe(f);
      ASSERT_LE(std::fabs(s.offset.y), f.radius) << describe(f);
      ASSERT_EQ(s.weight, 1.0f);
    }
    // u = 0.5 is the centre; the map is monotonic.
    EXPECT_NEAR(sample_filter(f, {0.5f, 0.5f}).offset.x, 0.0f, 1e-6f) << describe(f);
    float prev = -f.radius;
    for (int i = 0; i <= 1000; ++i) {
      float x = sample_filter(f, {i / 1000.0f * (1.0f - 0x1p-24f), 0.5f}).offset.x;
      ASSERT_GE(x, prev) << describe(f);
      prev = x;
    }
  }
}

// The inverse CDFs are exact: the CDF (the integral of filter_weight_1d, closed form) of the
// sampled offset is u, to float rounding.
TEST(FilterTest, InverseCdfsAreExact) {
  for (const FilterSettings& f : filters()) {
    if (f.type == FilterType::Box) continue;
    double r = f.radius, s = f.sigma * std::sqrt(2.0);
    auto cdf = [&](double x) {
      if (f.type == FilterType::Triangle)
        return x <= 0 ? (x + r) * (x + r) / (2 * r * r) : 1 - (r - x) * (r - x) / (2 * r * r);
      return 0.5 * (std::erf(x / s) / std::erf(r / s) + 1);
    };
    for (int i = 0; i <= 200; ++i) {
      float u = i / 200.0f * (1.0f - 0x1p-24f);
      float x = sample_filter(f, {u, 0.5f}).offset.x;
      // 2e-6: the float offset's rounding (ulp ~ 2e-7 r) times the pdf (<= 2.7 here).
      EXPECT_NEAR(cdf(x), u, 2e-6) << describe(f) << " u=" << u;
    }
  }
}

// filter_weight integrates to 1 over its support (nested adaptive Simpson to 1e-8; the tent's
// kinks at 0 are nodes) and is 0 outside it.
TEST(FilterTest, WeightIntegratesToOne) {
  for (const FilterSettings& f : filters()) {
    double r = f.radius;
    auto row = [&](double y) {
      return test::adaptive_simpson(
          [&](double x) {
            return double(filter_weight(f, {float(x), float(y)}));
          },
          -r, r, 1e-9, 4, 12);
    };
    double total = test::adaptive_simpson(row, -r, r, 1e-8, 4, 12);
    EXPECT_NEAR(total, 1.0, 1e-5) << describe(f);  // float filter_weight: ~1e-7 relative per node
    EXPECT_EQ(filter_weight(f, {float(r) * 1.01f, 0.0f}), 0.0f);
    EXPECT_EQ(filter_weight(f, {0.0f, -float(r) * 1.01f}), 0.0f);
    EXPECT_GT(filter_weight(f, {0.0f, 0.0f}), 0.0f);
  }
}

// Chi-square: 10^6 sampled offsets on a 16x16 grid over [-r, r]^2 against the integral of
// filter_weight over each cell (nested adaptive Simpson). Sidak-corrected over the family so a
// correct implementation fails it with probability 1e-3.
TEST(FilterTest, SampledOffsetsFollowTheFilter) {
  const int n = 16;
  const uint64_t samples = 1000000;
  std::vector<FilterSettings> fs = filters();
  double level = test::sidak_alpha(1e-3, int(fs.size()));
  for (const FilterSettings& f : fs) {
    double r = f.radius, cell = 2 * r / n;
    std::vector<double> observed(n * n, 0.0), expected(n * n, 0.0);
    for (uint64_t i = 0; i < samples; ++i) {
      Vec2 o = sample_filter(f, uniform_2d(i)).offset;
      int cx = std::min(n - 1, int((o.x + r) / cell)), cy = std::min(n - 1, int((o.y + r) / cell));
      observed[cy * n + cx] += 1;
    }
    for (int cy = 0; cy < n; ++cy)
      for (int cx = 0; cx < n; ++cx) {
        double x0 = -r + cx * cell, y0 = -r + cy * cell;
        auto row = [&](double y) {
          return test::adaptive_simpson(
              [&](double x) {
                return double(filter_weight(f, {float(x), float(y)}));
              },
              x0, x0 + cell, 1e-12, 2, 10);
        };
        expected[cy * n + cx] = samples * test::adaptive_simpson(row, y0, y0 + cell, 1e-12, 2, 10);
      }
    test::ChiSquareResult res = test::chi_square_test(observed, expected, level);
    EXPECT_TRUE(res.passed) << describe(f) << ": " << res.message;
  }
}

}  // namespace
}  // namespace rf
