// Tests of engine/film (pass sets, sample buffers, batch-means variance, merge, tile assembly, the
// .rfb format) and engine/image_io (EXR and PNG output).
#include "engine/film.h"

#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "engine/digest.h"
#include "engine/image_io.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

// DESIGN.md's merge tolerance: summation order only.
bool close(double a, double b) {
  return std::fabs(a - b) <= 1e-6 * std::max(std::fabs(a), std::fabs(b)) + 1e-12;
}

BufferHeader make_header(PassSet passes, int width = 8, int height = 6) {
  BufferHeader h;
  h.scene_digest = std::string(64, 'a');
  h.seed = 42;
  h.frame = 7;
  h.integrator = "path";
  h.settings = "max_depth=5 spp=4 filter=box";
  h.width = width;
  h.height = height;
  h.passes = std::move(passes);
  h.build_id = "test-build";
  h.isa = "x86_64-avx2";
  h.core_seconds = 1.5;
  return h;
}

Rect full(const BufferHeader& h) { return Rect{0, 0, h.width, h.height}; }

// One pass of random camera samples (and splats when asked) over `rect`, finished.
SampleBuffer random_pass(uint32_t pass, Rect rect, bool splats, uint64_t seed) {
  BufferHeader h = make_header(PassSet::range(pass, pass + 1));
  SampleBuffer b(h, rect, splats);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 2.0f);
  for (int y = rect.y0; y < rect.y1(); ++y) {
    for (int x = rect.x0; x < rect.x1(); ++x) {
      for (int s = 0; s < 3; ++s) b.add_sample(x, y, RGB(u(rng), u(rng), u(rng)));
    }
  }
  if (splats) {
    for (int i = 0; i < 40; ++i) b.add_splat(int(rng() % 8), int(rng() % 6), RGB(u(rng)));
    b.light_paths = 40;
  }
  b.rays = 1000 + pass;
  b.nonfinite_samples = pass;
  b.finish_pass();
  return b;
}

void expect_planes_close(const SampleBuffer& a, const SampleBuffer& b) {
  ASSERT_EQ(a.count, b.count);
  auto check = [](const std::vector<double>& x, const std::vector<double>& y, const char* name) {
    ASSERT_EQ(x.size(), y.size()) << name;
    for (size_t i = 0; i < x.size(); ++i) {
      EXPECT_TRUE(close(x[i], y[i])) << name << "[" << i << "]: " << x[i] << " vs " << y[i];
    }
  };
  check(a.sum, b.sum, "sum");
  check(a.sum_sq, b.sum_sq, "sum_sq");
  check(a.batch_sum, b.batch_sum, "batch_sum");
  check(a.batch_sum_sq, b.batch_sum_sq, "batch_sum_sq");
  check(a.splat, b.splat, "splat");
  EXPECT_EQ(a.light_paths, b.light_paths);
  EXPECT_EQ(a.nonfinite_samples, b.nonfinite_samples);
  EXPECT_EQ(a.rays, b.rays);
  EXPECT_EQ(a.header.passes, b.header.passes);
  EXPECT_TRUE(close(a.header.core_seconds, b.header.core_seconds));
}

void expect_bit_identical(const SampleBuffer& a, const SampleBuffer& b) {
  auto same = [](const std::vector<double>& x, const std::vector<double>& y) {
    return x.size() == y.size() &&
           (x.empty() || std::memcmp(x.data(), y.data(), 8 * x.size()) == 0);
  };
  EXPECT_EQ(a.header, b.header);
  EXPECT_EQ(a.rect, b.rect);
  EXPECT_EQ(a.count, b.count);
  EXPECT_TRUE(same(a.sum, b.sum));
  EXPECT_TRUE(same(a.sum_sq, b.sum_sq));
  EXPECT_TRUE(same(a.batch_sum, b.batch_sum));
  EXPECT_TRUE(same(a.batch_sum_sq, b.batch_sum_sq));
  EXPECT_TRUE(same(a.splat, b.splat));
  EXPECT_EQ(a.light_paths, b.light_paths);
  EXPECT_EQ(a.nonfinite_samples, b.nonfinite_samples);
  EXPECT_EQ(a.rays, b.rays);
}

template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no exception)";
}

// ------------------------------------------------------------------------------------- PassSet

TEST(PassSet, CountOverlapsAndPrefix) {
  PassSet a = PassSet::range(0, 4);
  EXPECT_EQ(a.count(), 4u);
  EXPECT_TRUE(a.is_prefix());
  EXPECT_TRUE(PassSet{}.is_prefix());
  EXPECT_TRUE(PassSet::range(3, 3).empty());
  EXPECT_FALSE(PassSet::range(1, 4).is_prefix());
  EXPECT_TRUE(a.overlaps(PassSet::range(3, 5)));
  EXPECT_FALSE(a.overlaps(PassSet::range(4, 5)));  // half-open: touching is not overlapping
  EXPECT_FALSE(a.overlaps(PassSet{}));
}

TEST(PassSet, AddKeepsSortedAndCoalesces) {
  PassSet s = PassSet::range(8, 12);
  s.add(PassSet::range(0, 2));
  EXPECT_EQ(s.ranges.size(), 2u);
  EXPECT_EQ(s.ranges[0], std::make_pair(0u, 2u));
  s.add(PassSet::range(2, 8));  // fills the gap: one range
  ASSERT_EQ(s.ranges.size(), 1u);
  EXPECT_EQ(s.ranges[0], std::make_pair(0u, 12u));
  EXPECT_EQ(s.count(), 12u);
  EXPECT_TRUE(s.is_prefix());
  // Adding passes one by one in any order gives the same set as the range.
  PassSet t;
  for (uint32_t p : {5u, 1u, 3u, 0u, 4u, 2u}) t.add(PassSet::range(p, p + 1));
  EXPECT_EQ(t, PassSet::range(0, 6));
}

TEST(PassSet, ToStringAndParseRoundTrip) {
  PassSet s = PassSet::range(0, 4);
  s.add(PassSet::range(8, 12));
  s.add(PassSet::range(20, 21));
  EXPECT_EQ(s.to_string(), "0-3,8-11,20");
  EXPECT_EQ(PassSet::range(5, 6).to_string(), "5");
  EXPECT_EQ(PassSet{}.to_string(), "");
  for (const char* text : {"", "0", "5", "0-3,8-11", "0-3,8-11,20", "4294967293"}) {
    EXPECT_EQ(PassSet::parse(text).to_string(), text);
  }
  EXPECT_EQ(PassSet::parse("8-11,0-3"), PassSet::parse("0-3,8-11"));  // order does not matter
  EXPECT_EQ(PassSet::parse("0-1,2-3"), PassSet::range(0, 4));         // adjacent ranges coalesce
}

TEST(PassSet, ParseRejectsWithClearMessages) {
  for (const char* bad : {"a", "1-", "-1", "3-1", "1,,2", "1,", " 1", "1-2-3", "0-3,2",
                          "4294967295", "99999999999"}) {
    EXPECT_THROW(PassSet::parse(bad), std::invalid_argument) << bad;
  }
  EXPECT_NE(error_of([] { PassSet::parse("3-1"); }).find("ends before it begins"),
            std::string::npos);
  EXPECT_NE(error_of([] { PassSet::parse("0-3,2-5"); }).find("2-3 listed twice"),
            std::string::npos);
  EXPECT_NE(error_of([] { PassSet::parse("x"); }).find("\"x\""), std::string::npos);
}

// -------------------------------------------------------------------------------- SampleBuffer

TEST(SampleBuffer, ConstructorSizesPlanes) {
  BufferHeader h = make_header(PassSet::range(0, 1), 8, 6);
  SampleBuffer tile(h, Rect{2, 1, 4, 3}, false);
  EXPECT_EQ(tile.count.size(), 12u);
  EXPECT_EQ(tile.sum.size(), 36u);
  EXPECT_EQ(tile.batch_sum_sq.size(), 36u);
  EXPECT_TRUE(tile.splat.empty());
  SampleBuffer whole(h, full(h), true);
  EXPECT_EQ(whole.splat.size(), 8u * 6u * 3u);
  EXPECT_THROW(SampleBuffer(h, Rect{6, 0, 4, 2}, false), std::invalid_argument);
}

TEST(SampleBuffer, AddSampleAccumulatesAndCountsNonFinite) {
  BufferHeader h = make_header(PassSet::range(0, 1));
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
  BufferHeader h = make_header(PassSet::range(0, 1), 4, 4);
  SampleBuffer b(h, full(h), true);
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
  BufferHeader h = make_header(PassSet::range(0, 2));
  SampleBuffer b(h, full(h), false);
  EXPECT_THROW(b.finish_pass(), std::logic_error);
  SampleBuffer one(make_header(PassSet::range(3, 4)), full(h), false);
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
  SampleBuffer acc(make_header(PassSet{}, int(npix), 1), Rect{0, 0, int(npix), 1}, false);
  for (size_t k = 0; k < n; ++k) {
    SampleBuffer p(make_header(PassSet::range(uint32_t(k), uint32_t(k) + 1), int(npix), 1),
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
  SampleBuffer acc(make_header(PassSet{}, w, h), Rect{0, 0, w, h}, false);
  for (uint32_t k = 0; k < n; ++k) {
    SampleBuffer p(make_header(PassSet::range(k, k + 1), w, h), Rect{0, 0, w, h}, false);
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

// -------------------------------------------------------------------------------------- Merge

TEST(Merge, CommutativeAndAssociative) {
  for (bool splats : {false, true}) {
    Rect r{0, 0, 8, 6};
    SampleBuffer a = random_pass(0, r, splats, 1), b = random_pass(1, r, splats, 2),
                 c = random_pass(2, r, splats, 3);
    auto merged = [](SampleBuffer x, const SampleBuffer& y) {
      merge_into(x, y);
      return x;
    };
    SampleBuffer abc = merged(merged(a, b), c);   // (a+b)+c
    SampleBuffer a_bc = merged(a, merged(b, c));  // a+(b+c)
    SampleBuffer cba = merged(merged(c, b), a);
    SampleBuffer bac = merged(merged(b, a), c);
    expect_planes_close(abc, a_bc);
    expect_planes_close(abc, cba);
    expect_planes_close(abc, bac);
    EXPECT_EQ(abc.header.passes.to_string(), "0-2");
    EXPECT_EQ(abc.rays, 3003u);
    EXPECT_EQ(abc.nonfinite_samples, 3u);
    EXPECT_DOUBLE_EQ(abc.header.core_seconds, 4.5);
    EXPECT_EQ(abc.light_paths, splats ? 120u : 0u);
    EXPECT_EQ(abc.total_samples(), 3u * 3u * 48u);
  }
}

TEST(Merge, RefusesMismatchedHeadersNamingTheField) {
  Rect r{0, 0, 8, 6};
  SampleBuffer a = random_pass(0, r, false, 1);
  auto refusal = [&](auto change) {
    SampleBuffer b = random_pass(1, r, false, 2);
    change(b);
    SampleBuffer dst = a;
    std::string msg = error_of([&] { merge_into(dst, b); });
    EXPECT_TRUE(dst.header == a.header && dst.sum == a.sum) << "a refused merge changed dst";
    EXPECT_NE(msg, "(no exception)");
    return msg;
  };
  std::string m = refusal([](SampleBuffer& b) { b.header.scene_digest = "bbbb"; });
  EXPECT_NE(m.find("scene_digest"), std::string::npos) << m;
  EXPECT_NE(m.find("bbbb"), std::string::npos) << m;
  m = refusal([](SampleBuffer& b) { b.header.seed = 43; });
  EXPECT_NE(m.find("seed differs: 42 vs 43"), std::string::npos) << m;
  m = refusal([](SampleBuffer& b) { b.header.frame = 8; });
  EXPECT_NE(m.find("frame differs: 7 vs 8"), std::string::npos) << m;
  m = refusal([](SampleBuffer& b) { b.header.integrator = "bdpt"; });
  EXPECT_NE(m.find("integrator differs: \"path\" vs \"bdpt\""), std::string::npos) << m;
  m = refusal([](SampleBuffer& b) { b.header.settings = "max_depth=6"; });
  EXPECT_NE(m.find("settings"), std::string::npos) << m;
  m = refusal([](SampleBuffer& b) { b.header.width = 16; });
  EXPECT_NE(m.find("width differs: 8 vs 16"), std::string::npos) << m;
  m = refusal([](SampleBuffer& b) { b.header.height = 5; });
  EXPECT_NE(m.find("height differs: 6 vs 5"), std::string::npos) << m;
  m = refusal([](SampleBuffer& b) { b = random_pass(1, Rect{0, 0, 4, 6}, false, 2); });
  EXPECT_NE(m.find("rect differs"), std::string::npos) << m;
  m = refusal([](SampleBuffer& b) { b = random_pass(1, Rect{0, 0, 8, 6}, true, 2); });
  EXPECT_NE(m.find("splat"), std::string::npos) << m;
}

TEST(Merge, RefusesOverlappingPassesNamingThem) {
  BufferHeader h = make_header(PassSet::parse("0-3,8"));
  BufferHeader g = make_header(PassSet::parse("2-5"));
  SampleBuffer a(h, full(h), false), b(g, full(g), false);
  std::string m = error_of([&] { merge_into(a, b); });
  EXPECT_NE(m.find("overlap"), std::string::npos) << m;
  EXPECT_NE(m.find("\"0-3,8\" and \"2-5\" share passes 2-3"), std::string::npos) << m;
  EXPECT_THROW(merge_into(a, b), MergeError);
  EXPECT_EQ(merge_incompatibility(h, make_header(PassSet::range(4, 8))), "");
}

TEST(Merge, DifferentBuildsCombineAsASet) {
  Rect r{0, 0, 8, 6};
  SampleBuffer a = random_pass(0, r, false, 1), b = random_pass(1, r, false, 2),
               c = random_pass(2, r, false, 3);
  b.header.build_id = "other-build";
  b.header.isa = "x86_64-avx512";
  SampleBuffer ab = a, ba = b;
  merge_into(ab, b);
  merge_into(ba, a);
  EXPECT_EQ(ab.header.build_id, "mixed:other-build,test-build");
  EXPECT_EQ(ba.header.build_id, ab.header.build_id);
  EXPECT_EQ(ab.header.isa, "mixed:x86_64-avx2,x86_64-avx512");
  merge_into(ab, c);  // a third buffer of a known build leaves the set alone
  EXPECT_EQ(ab.header.build_id, "mixed:other-build,test-build");
  // A fresh accumulator with no build id adopts the first buffer's.
  SampleBuffer acc(make_header(PassSet{}), r, false);
  acc.header.build_id = "";
  merge_into(acc, a);
  EXPECT_EQ(acc.header.build_id, "test-build");
}

// ------------------------------------------------------------------------------ assemble_tile

TEST(AssembleTile, BitExactAgainstWholeFrame) {
  BufferHeader h = make_header(PassSet::range(3, 4), 8, 6);
  // The reference renders the whole frame; the tiles render the same samples per pixel.
  auto render = [&](Rect r) {
    SampleBuffer b(h, r, false);
    for (int y = r.y0; y < r.y1(); ++y) {
      for (int x = r.x0; x < r.x1(); ++x) {
        std::mt19937_64 rng(uint64_t(y * 100 + x));  // keyed by pixel, like the samplers
        std::uniform_real_distribution<float> u(0.0f, 3.0f);
        for (int s = 0; s < 5; ++s) b.add_sample(x, y, RGB(u(rng), u(rng), u(rng)));
      }
    }
    b.rays = uint64_t(r.area());
    b.finish_pass();
    return b;
  };
  SampleBuffer whole = render(full(h));
  SampleBuffer assembled(h, full(h), false);
  assembled.header.core_seconds = 0;
  double tile_seconds = 0;
  for (Rect t : {Rect{0, 0, 5, 4}, Rect{5, 0, 3, 4}, Rect{0, 4, 5, 2}, Rect{5, 4, 3, 2}}) {
    SampleBuffer tile = render(t);
    tile_seconds += tile.header.core_seconds;
    assemble_tile(assembled, tile);
  }
  whole.header.core_seconds = tile_seconds;
  expect_bit_identical(assembled, whole);
}

TEST(AssembleTile, Refuses) {
  BufferHeader h = make_header(PassSet::range(0, 1), 8, 6);
  SampleBuffer dst(h, Rect{0, 0, 4, 4}, false);
  SampleBuffer outside(h, Rect{2, 2, 4, 2}, false);
  std::string m = error_of([&] { assemble_tile(dst, outside); });
  EXPECT_NE(m.find("not inside"), std::string::npos) << m;
  SampleBuffer other_pass(make_header(PassSet::range(1, 2)), Rect{0, 0, 2, 2}, false);
  m = error_of([&] { assemble_tile(dst, other_pass); });
  EXPECT_NE(m.find("passes differ"), std::string::npos) << m;
  BufferHeader g = h;
  g.seed = 1;
  EXPECT_THROW(assemble_tile(dst, SampleBuffer(g, Rect{0, 0, 2, 2}, false)), MergeError);
  SampleBuffer splat_dst(h, full(h), true), splat_tile(h, full(h), true);
  EXPECT_THROW(assemble_tile(splat_dst, splat_tile), MergeError);
}

// ------------------------------------------------------------------------------- .rfb format

SampleBuffer small_buffer(bool splats) {
  SampleBuffer a = random_pass(0, Rect{0, 0, 8, 6}, splats, 11);
  merge_into(a, random_pass(1, Rect{0, 0, 8, 6}, splats, 12));
  a.header.core_seconds = 0.1;  // not exactly representable: must still round-trip
  a.header.seed = 0xfedcba9876543210ull;
  return a;
}

SampleBuffer small_tile() {
  SampleBuffer t = random_pass(4, Rect{2, 1, 3, 2}, false, 13);
  t.header.settings = "quote \" backslash \\ unicode \xc3\xa9";
  return t;
}

TEST(BufferFile, EncodeDecodeRoundTripIsBitIdentical) {
  for (const SampleBuffer& b : {small_buffer(false), small_buffer(true), small_tile()}) {
    std::string bytes = encode_buffer(b);
    SampleBuffer d = decode_buffer(bytes, "mem");
    expect_bit_identical(d, b);
    EXPECT_EQ(encode_buffer(d), bytes);
  }
}

TEST(BufferFile, WriteAndReadFile) {
  std::string dir = test::make_temp_dir("film-rfb");
  std::string path = dir + "/pass.rfb";
  SampleBuffer b = small_buffer(true);
  write_buffer_file(path, b);
  expect_bit_identical(read_buffer_file(path), b);
  std::string m = error_of([&] { read_buffer_file(dir + "/missing.rfb"); });
  EXPECT_NE(m.find("missing.rfb"), std::string::npos) << m;
  EXPECT_THROW(read_buffer_file(dir + "/missing.rfb"), BufferFileError);
}

TEST(BufferFile, LayoutIsAsDocumented) {
  SampleBuffer b = small_tile();
  std::string bytes = encode_buffer(b);
  EXPECT_EQ(bytes.substr(0, 8), std::string("\x89RFB\r\n\x1a\n", 8));
  uint32_t version, header_len;
  std::memcpy(&version, bytes.data() + 8, 4);  // the tests run on little-endian hosts
  std::memcpy(&header_len, bytes.data() + 12, 4);
  EXPECT_EQ(version, 1u);
  EXPECT_EQ((16 + header_len) % 8, 0u);  // planes are 8-byte aligned
  EXPECT_EQ(bytes.size(), 16 + header_len + 8 * 13 * 6 + 32);
  uint64_t count0;
  std::memcpy(&count0, bytes.data() + 16 + header_len, 8);
  EXPECT_EQ(count0, b.count[0]);
  std::string checksum_hex;
  for (size_t i = bytes.size() - 32; i < bytes.size(); ++i) {
    checksum_hex += "0123456789abcdef"[uint8_t(bytes[i]) >> 4];
    checksum_hex += "0123456789abcdef"[uint8_t(bytes[i]) & 15];
  }
  EXPECT_EQ(checksum_hex, sha256_hex(bytes.substr(0, bytes.size() - 32)));
  auto j = nlohmann::json::parse(bytes.substr(16, header_len));
  EXPECT_EQ(j["passes"], "4");
  EXPECT_EQ(j["rect"]["x0"], 2);
}

// Replaces the JSON header and recomputes the checksum: a "well-formed lie".
std::string with_header(const std::string& bytes, const nlohmann::json& j) {
  uint32_t header_len;
  std::memcpy(&header_len, bytes.data() + 12, 4);
  std::string header = j.dump();
  std::string out = bytes.substr(0, 12);
  uint32_t len = uint32_t(header.size());
  out.append(reinterpret_cast<const char*>(&len), 4);
  out += header;
  out += bytes.substr(16 + header_len, bytes.size() - 16 - header_len - 32);
  std::string hex = sha256_hex(out);
  for (size_t i = 0; i < 32; ++i) out.push_back(char(std::stoi(hex.substr(2 * i, 2), nullptr, 16)));
  return out;
}

nlohmann::json header_of(const std::string& bytes) {
  uint32_t header_len;
  std::memcpy(&header_len, bytes.data() + 12, 4);
  return nlohmann::json::parse(bytes.substr(16, header_len));
}

TEST(BufferFile, RejectsBadMagicAndVersion) {
  std::string good = encode_buffer(small_tile());
  std::string bad = good;
  bad[1] = 'X';
  std::string m = error_of([&] { decode_buffer(bad, "a.rfb"); });
  EXPECT_EQ(m, "a.rfb: not a rayfarm sample buffer (bad magic)");
  EXPECT_THROW(decode_buffer("hello world, this is not a buffer at all....................", "t"),
               BufferFileError);
  bad = good;
  bad[8] = 2;
  m = error_of([&] { decode_buffer(bad, "a.rfb"); });
  EXPECT_EQ(m, "a.rfb: unsupported format version 2 (this build reads 1)");
}

TEST(BufferFile, EveryTruncationThrows) {
  for (bool splats : {false, true}) {
    std::string good = encode_buffer(splats ? small_buffer(true) : small_tile());
    for (size_t n = 0; n < good.size(); ++n) {
      EXPECT_THROW(decode_buffer(good.substr(0, n), "t.rfb"), BufferFileError) << n;
    }
  }
  std::string good = encode_buffer(small_tile());
  std::string m = error_of([&] { decode_buffer(good.substr(0, good.size() - 1), "a.rfb"); });
  EXPECT_EQ(m, "a.rfb: checksum mismatch (file is corrupt or truncated)");
}

TEST(BufferFile, EveryFlippedByteThrows) {
  std::string good = encode_buffer(small_tile());
  for (size_t i = 0; i < good.size(); ++i) {
    std::string bad = good;
    bad[i] ^= 0x10;
    EXPECT_THROW(decode_buffer(bad, "f.rfb"), BufferFileError) << i;
  }
  std::string bad = good;
  bad[good.size() / 2] ^= 1;
  EXPECT_EQ(error_of([&] { decode_buffer(bad, "a.rfb"); }),
            "a.rfb: checksum mismatch (file is corrupt or truncated)");
}

TEST(BufferFile, RejectsAHeaderThatLiesWithAValidChecksum) {
  std::string good = encode_buffer(small_tile());
  nlohmann::json j = header_of(good);
  EXPECT_NO_THROW(decode_buffer(with_header(good, j), "ok.rfb"));  // the helper itself is sound
  auto rejection = [&](auto change) {
    nlohmann::json k = j;
    change(k);
    std::string m = error_of([&] { decode_buffer(with_header(good, k), "l.rfb"); });
    EXPECT_EQ(m.rfind("l.rfb: ", 0), 0u) << m;
    return m;
  };
  std::string m = rejection([](nlohmann::json& k) { k["rect"]["w"] = 4; });
  EXPECT_NE(m.find("header describes"), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) { k["rect"]["h"] = 1000000; });
  EXPECT_NE(m.find("not inside"), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) {
    k["width"] = 1000000;
    k["height"] = 1000000;
    k["has_splats"] = true;
  });
  EXPECT_NE(m.find("header describes"), std::string::npos) << m;  // would be 24 TB of splats
  m = rejection([](nlohmann::json& k) { k["has_splats"] = true; });
  EXPECT_NE(m.find("header describes"), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) { k["rect"]["x0"] = -1; });
  EXPECT_NE(m.find("\"x0\""), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) { k.erase("seed"); });
  EXPECT_NE(m.find("\"seed\""), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) { k["passes"] = "3-1"; });
  EXPECT_NE(m.find("passes"), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) { k = nlohmann::json::array(); });
  EXPECT_NE(m.find("not a JSON object"), std::string::npos) << m;
  // A header length that runs past the end of the file.
  std::string bad = good;
  bad[13] = char(0x7f);
  EXPECT_THROW(decode_buffer(bad, "l.rfb"), BufferFileError);
}

// -------------------------------------------------------------------------------- image output

SampleBuffer image_buffer(Rect rect) {
  BufferHeader h = make_header(PassSet{}, 8, 6);
  SampleBuffer acc(h, rect, false);
  for (uint32_t k = 0; k < 4; ++k) {
    SampleBuffer p(make_header(PassSet::range(k, k + 1), 8, 6), rect, false);
    for (int y = rect.y0; y < rect.y1(); ++y) {
      for (int x = rect.x0; x < rect.x1(); ++x) {
        p.add_sample(x, y, RGB(0.1f * x + k, 0.05f * y, 0.3f + 0.01f * k));
        p.add_sample(x, y, RGB(0.1f * x + k, 0.05f * y, 0.3f - 0.01f * k));
      }
    }
    p.finish_pass();
    merge_into(acc, p);
  }
  acc.nonfinite_samples = 3;
  return acc;
}

std::string string_attr(const OIIO::ImageSpec& spec, const char* name) {
  return spec.get_string_attribute(name, "(missing)");
}

TEST(ImageIO, ExrHasChannelsPixelsAndProvenance) {
  std::string dir = test::make_temp_dir("film-exr");
  std::string path = dir + "/frame.exr";
  SampleBuffer b = image_buffer(Rect{0, 0, 8, 6});
  write_exr(path, b, {{"job", "job-17"}, {"spp", "not me"}});
  // Nothing else left in the directory: the temporary file was renamed.
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 1);

  auto in = OIIO::ImageInput::open(path);
  ASSERT_TRUE(in) << OIIO::geterror();
  const OIIO::ImageSpec& spec = in->spec();
  ASSERT_EQ(spec.nchannels, 7);
  EXPECT_EQ(spec.width, 8);
  EXPECT_EQ(spec.height, 6);
  EXPECT_EQ(spec.format, OIIO::TypeDesc::FLOAT);
  std::vector<float> px(size_t(8 * 6 * 7));
  ASSERT_TRUE(in->read_image(0, 0, 0, 7, OIIO::TypeDesc::FLOAT, px.data()));
  auto chan = [&](const char* name) {
    auto it = std::find(spec.channelnames.begin(), spec.channelnames.end(), name);
    EXPECT_NE(it, spec.channelnames.end()) << name;
    return int(it - spec.channelnames.begin());
  };
  int R = chan("R"), G = chan("G"), B = chan("B"), A = chan("A");
  int VR = chan("variance.R"), VB = chan("variance.B");
  for (int y = 0; y < 6; ++y) {
    for (int x = 0; x < 8; ++x) {
      const float* p = &px[size_t(y * 8 + x) * 7];
      RGB e = b.estimate(x, y), v = b.variance_of_mean(x, y);
      // Floats written and read back unchanged: equality up to one float rounding.
      EXPECT_FLOAT_EQ(p[R], e.x);
      EXPECT_FLOAT_EQ(p[G], e.y);
      EXPECT_FLOAT_EQ(p[B], e.z);
      EXPECT_EQ(p[A], 1.0f);
      EXPECT_FLOAT_EQ(p[VR], v.x);
      EXPECT_FLOAT_EQ(p[VB], v.z);
    }
  }
  // Pass estimates of R are base + k, k = 0..3: Var(mean) = (5/3) / 4.
  EXPECT_NEAR(px[size_t(VR)], 5.0 / 12.0, 1e-6);
  EXPECT_EQ(string_attr(spec, "rayfarm:scene_digest"), std::string(64, 'a'));
  EXPECT_EQ(string_attr(spec, "rayfarm:seed"), "42");
  EXPECT_EQ(spec.get_int_attribute("rayfarm:frame", -1), 7);
  EXPECT_EQ(string_attr(spec, "rayfarm:integrator"), "path");
  EXPECT_EQ(string_attr(spec, "rayfarm:settings"), "max_depth=5 spp=4 filter=box");
  EXPECT_EQ(string_attr(spec, "rayfarm:passes"), "0-3");
  EXPECT_EQ(spec.get_int_attribute("rayfarm:spp", -1), 8);  // built-ins win over extras
  EXPECT_EQ(string_attr(spec, "rayfarm:build_id"), "test-build");
  EXPECT_EQ(string_attr(spec, "rayfarm:isa"), "x86_64-avx2");
  EXPECT_NEAR(spec.get_float_attribute("rayfarm:core_seconds", -1), b.header.core_seconds, 1e-6);
  EXPECT_NEAR(spec.get_float_attribute("rayfarm:rel_mse", -1), b.rel_mse(), 1e-6 * b.rel_mse());
  EXPECT_GT(b.rel_mse(), 0.0);
  EXPECT_EQ(string_attr(spec, "rayfarm:variance_estimator"), "batch means over 4 passes");
  EXPECT_EQ(spec.get_int_attribute("rayfarm:nonfinite_samples", -1), 3);
  EXPECT_EQ(string_attr(spec, "rayfarm:job"), "job-17");
}

TEST(ImageIO, ExrOfATileUsesTheDataWindow) {
  std::string dir = test::make_temp_dir("film-exr-tile");
  std::string path = dir + "/tile.exr";
  SampleBuffer b = image_buffer(Rect{2, 1, 4, 3});
  write_exr(path, b);
  auto in = OIIO::ImageInput::open(path);
  ASSERT_TRUE(in) << OIIO::geterror();
  const OIIO::ImageSpec& spec = in->spec();
  EXPECT_EQ(spec.x, 2);
  EXPECT_EQ(spec.y, 1);
  EXPECT_EQ(spec.width, 4);
  EXPECT_EQ(spec.height, 3);
  EXPECT_EQ(spec.full_width, 8);
  EXPECT_EQ(spec.full_height, 6);
  std::vector<float> px(size_t(4 * 3 * 7));
  ASSERT_TRUE(in->read_image(0, 0, 0, 7, OIIO::TypeDesc::FLOAT, px.data()));
  EXPECT_FLOAT_EQ(px[0], b.estimate(2, 1).x);
}

TEST(ImageIO, ExrErrorNamesThePath) {
  SampleBuffer b = image_buffer(Rect{0, 0, 8, 6});
  std::string m = error_of([&] { write_exr("/nonexistent-dir/x/frame.exr", b); });
  EXPECT_NE(m.find("/nonexistent-dir/x/frame.exr"), std::string::npos) << m;
  EXPECT_THROW(write_exr("/nonexistent-dir/x/frame.exr", b), ImageIOError);
}

TEST(ImageIO, PngIsSrgbEncoded) {
  std::string dir = test::make_temp_dir("film-png");
  BufferHeader h = make_header(PassSet::range(0, 1), 5, 2);
  SampleBuffer b(h, full(h), false);
  // Expected bytes from the piecewise sRGB curve: 0.5 -> 0.7354 * 255 = 187.5 -> 188;
  // 0.001 is on the linear segment: 12.92e-3 * 255 = 3.29 -> 3; 2.0 clamps to 255.
  b.add_sample(0, 0, RGB(0.5f, 0.0f, 1.0f));
  b.add_sample(1, 0, RGB(0.001f, 2.0f, 0.18f));
  b.add_sample(2, 0, RGB(std::nanf(""), 0.0f, 0.0f));  // dropped: counts as 0
  b.add_sample(0, 1, RGB(0.25f));
  std::string path = dir + "/preview.png";
  write_png(path, b);
  auto read = [](const std::string& p, int w, int hh) {
    auto in = OIIO::ImageInput::open(p);
    EXPECT_TRUE(in) << OIIO::geterror();
    EXPECT_EQ(in->spec().width, w);
    EXPECT_EQ(in->spec().height, hh);
    EXPECT_EQ(in->spec().nchannels, 3);
    std::vector<uint8_t> px(size_t(w * hh * 3));
    EXPECT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, px.data()));
    return px;
  };
  std::vector<uint8_t> px = read(path, 5, 2);
  EXPECT_EQ(px[0], 188);
  EXPECT_EQ(px[1], 0);
  EXPECT_EQ(px[2], 255);
  EXPECT_EQ(px[3], 3);
  EXPECT_EQ(px[4], 255);
  EXPECT_EQ(px[5], 118);  // 0.18 -> 0.4614 * 255 = 117.7
  EXPECT_EQ(px[6], 0);
  EXPECT_EQ(px[15], 137);  // 0.25 -> 0.5371 * 255 = 137.0
  // One stop up turns 0.25 into 0.5.
  write_png(path, b, 1.0f);
  px = read(path, 5, 2);
  EXPECT_EQ(px[15], 188);
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 1);
}

}  // namespace
}  // namespace rf
