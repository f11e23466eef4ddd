// Tests of engine/buffer_merge: merging is commutative and associative, refuses what does not
// belong together naming why, and assembles tiles bit-exactly.
#include "engine/buffer_merge.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "tests/support/fixtures.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

void expect_planes_close(const SampleBuffer& a, const SampleBuffer& b) {
  ASSERT_EQ(a.count, b.count);
  auto check = [](const std::vector<double>& x, const std::vector<double>& y, const char* name) {
    ASSERT_EQ(x.size(), y.size()) << name;
    for (size_t i = 0; i < x.size(); ++i) {
      EXPECT_TRUE(test::within_merge_tolerance(x[i], y[i])) << name << "[" << i << "]: " << x[i] << " vs " << y[i];
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
  EXPECT_TRUE(test::within_merge_tolerance(a.header.core_seconds, b.header.core_seconds));
}

TEST(Merge, CommutativeAndAssociative) {
  for (bool splats : {false, true}) {
    Rect r{0, 0, 8, 6};
    SampleBuffer a = test::random_pass(0, r, splats, 1), b = test::random_pass(1, r, splats, 2),
                 c = test::random_pass(2, r, splats, 3);
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
  SampleBuffer a = test::random_pass(0, r, false, 1);
  auto refusal = [&](auto change) {
    SampleBuffer b = test::random_pass(1, r, false, 2);
    change(b);
    SampleBuffer dst = a;
    std::string msg = test::error_of([&] { merge_into(dst, b); });
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
  m = refusal([](SampleBuffer& b) { b = test::random_pass(1, Rect{0, 0, 4, 6}, false, 2); });
  EXPECT_NE(m.find("rect differs"), std::string::npos) << m;
  m = refusal([](SampleBuffer& b) { b = test::random_pass(1, Rect{0, 0, 8, 6}, true, 2); });
  EXPECT_NE(m.find("splat"), std::string::npos) << m;
}

TEST(Merge, RefusesOverlappingPassesNamingThem) {
  BufferHeader h = test::test_header(PassSet::parse("0-3,8"));
  BufferHeader g = test::test_header(PassSet::parse("2-5"));
  SampleBuffer a(h, test::full_frame(h), false), b(g, test::full_frame(g), false);
  std::string m = test::error_of([&] { merge_into(a, b); });
  EXPECT_NE(m.find("overlap"), std::string::npos) << m;
  EXPECT_NE(m.find("\"0-3,8\" and \"2-5\" share passes 2-3"), std::string::npos) << m;
  EXPECT_THROW(merge_into(a, b), MergeError);
  EXPECT_EQ(merge_incompatibility(h, test::test_header(PassSet::range(4, 8))), "");
}

TEST(Merge, DifferentBuildsCombineAsASet) {
  Rect r{0, 0, 8, 6};
  SampleBuffer a = test::random_pass(0, r, false, 1), b = test::random_pass(1, r, false, 2),
               c = test::random_pass(2, r, false, 3);
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
  SampleBuffer acc(test::test_header(PassSet{}), r, false);
  acc.header.build_id = "";
  merge_into(acc, a);
  EXPECT_EQ(acc.header.build_id, "test-build");
}

// ------------------------------------------------------------------------------ assemble_tile

TEST(AssembleTile, BitExactAgainstWholeFrame) {
  BufferHeader h = test::test_header(PassSet::range(3, 4), 8, 6);
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
  SampleBuffer whole = render(test::full_frame(h));
  SampleBuffer assembled(h, test::full_frame(h), false);
  assembled.header.core_seconds = 0;
  double tile_seconds = 0;
  for (Rect t : {Rect{0, 0, 5, 4}, Rect{5, 0, 3, 4}, Rect{0, 4, 5, 2}, Rect{5, 4, 3, 2}}) {
    SampleBuffer tile = render(t);
    tile_seconds += tile.header.core_seconds;
    assemble_tile(assembled, tile);
  }
  whole.header.core_seconds = tile_seconds;
  test::expect_bit_identical(assembled, whole);
}

TEST(AssembleTile, Refuses) {
  BufferHeader h = test::test_header(PassSet::range(0, 1), 8, 6);
  SampleBuffer dst(h, Rect{0, 0, 4, 4}, false);
  SampleBuffer outside(h, Rect{2, 2, 4, 2}, false);
  std::string m = test::error_of([&] { assemble_tile(dst, outside); });
  EXPECT_NE(m.find("not inside"), std::string::npos) << m;
  SampleBuffer other_pass(test::test_header(PassSet::range(1, 2)), Rect{0, 0, 2, 2}, false);
  m = test::error_of([&] { assemble_tile(dst, other_pass); });
  EXPECT_NE(m.find("passes differ"), std::string::npos) << m;
  BufferHeader g = h;
  g.seed = 1;
  EXPECT_THROW(assemble_tile(dst, SampleBuffer(g, Rect{0, 0, 2, 2}, false)), MergeError);
  SampleBuffer splat_dst(h, test::full_frame(h), true), splat_tile(h, test::full_frame(h), true);
  EXPECT_THROW(assemble_tile(splat_dst, splat_tile), MergeError);
}

}  // namespace
}  // namespace rf
