// The determinism contract (DESIGN.md): the image is a function of (scene, settings, set of
// passes) alone. Per pass and tile, renders are bit-identical however they are split or
// threaded; merged results agree within |a-b| <= 1e-6 max(|a|,|b|) + 1e-12 (summation order).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <random>

#include "engine/frame_accumulator.h"
#include "engine/local_render.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "tests/support/fixtures.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

using test::bits_equal;

void expect_close(const std::vector<double>& a, const std::vector<double>& b, const char* what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  size_t bad = 0;
  for (size_t i = 0; i < a.size(); ++i)
    if (std::fabs(a[i] - b[i]) > 1e-6 * std::max(std::fabs(a[i]), std::fabs(b[i])) + 1e-12) ++bad;
  EXPECT_EQ(bad, 0u) << what << ": values beyond DESIGN.md's merge tolerance";
}

TEST(Determinism, WholeFrameEqualsTilesBitForBit) {
  Scene s = test::cornell_box({"", 48, 2, 4});
  Renderer r(s);
  Rect full{0, 0, 48, 48};
  for (uint32_t pass : {0u, 3u}) {
    SampleBuffer whole = r.render(TaskKey{0, full, pass}, /*parallel=*/true);
    SampleBuffer serial = r.render(TaskKey{0, full, pass}, /*parallel=*/false);
    EXPECT_TRUE(bits_equal(whole.sum, serial.sum)) << "threads changed pixels";
    SampleBuffer assembled(r.header(0, PassSet::range(pass, pass + 1)), full, false);
    for (const Rect& t : r.tiles(20))
      assemble_tile(assembled, r.render(TaskKey{0, t, pass}, false));
    EXPECT_TRUE(bits_equal(whole.sum, assembled.sum));
    EXPECT_TRUE(bits_equal(whole.sum_sq, assembled.sum_sq));
    EXPECT_TRUE(bits_equal(whole.batch_sum, assembled.batch_sum));
    EXPECT_EQ(whole.count, assembled.count);
  }
}

TEST(Determinism, PassesInAnyOrderAndGroupingMergeToTheSameImage) {
  Scene s = test::cornell_box({"", 32, 1, 8});
  Renderer r(s);
  Rect full{0, 0, 32, 32};
  std::vector<SampleBuffer> passes;
  for (uint32_t p = 0; p < 8; ++p) passes.push_back(r.render(TaskKey{0, full, p}, false));

  SampleBuffer in_order(r.header(0, PassSet{}), full, false);
  for (auto& b : passes) merge_into(in_order, b);

  // Shuffled order, grouped into pairs first, merged pair-wise.
  std::vector<int> order{5, 2, 7, 0, 3, 6, 1, 4};
  std::vector<SampleBuffer> groups;
  for (size_t i = 0; i < order.size(); i += 2) {
    SampleBuffer g = passes[size_t(order[i])];
    merge_into(g, passes[size_t(order[i + 1])]);
    groups.push_back(std::move(g));
  }
  SampleBuffer grouped = groups[3];
  merge_into(grouped, groups[1]);
  merge_into(grouped, groups[0]);
  merge_into(grouped, groups[2]);
  EXPECT_EQ(grouped.header.passes, PassSet::range(0, 8));
  expect_close(in_order.sum, grouped.sum, "sum");
  expect_close(in_order.sum_sq, grouped.sum_sq, "sum_sq");
  expect_close(in_order.batch_sum, grouped.batch_sum, "batch_sum");
  expect_close(in_order.batch_sum_sq, grouped.batch_sum_sq, "batch_sum_sq");
}

TEST(Determinism, ProgressiveMergerIgnoresArrivalOrder) {
  Scene s = test::cornell_box({"", 40, 1, 6});
  Renderer r(s);
  TileGrid tiles = r.tiles(16);
  std::vector<SampleBuffer> tasks;
  for (uint32_t p = 0; p < 6; ++p)
    for (const Rect& t : tiles) tasks.push_back(r.render(TaskKey{0, t, p}, false));

  auto run = [&](std::vector<SampleBuffer> order) {
    FrameAccumulator acc(r.header(0, PassSet{}), tiles, false, ProgressiveOptions{0, 6, 0});
    for (auto& t : order) acc.add(std::move(t));
    EXPECT_TRUE(acc.done());
    return acc.frame();
  };
  SampleBuffer a = run(tasks);
  std::vector<SampleBuffer> shuffled = tasks;
  std::mt19937 rng(42);
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  shuffled.push_back(tasks[3]);  // a late duplicate is ignored
  SampleBuffer b = run(shuffled);
  // Passes are merged in pass order whatever the arrival order: bit-identical.
  EXPECT_TRUE(bits_equal(a.sum, b.sum));
  EXPECT_TRUE(bits_equal(a.batch_sum_sq, b.batch_sum_sq));
}

TEST(Determinism, LocalRenderEqualsTaskMerge) {
  Scene s = test::cornell_box({"", 32, 1, 4});
  Renderer r(s);
  LocalRenderOptions opt;
  opt.tile_size = 16;
  LocalRenderResult res = render_local(r, opt);
  SampleBuffer manual(r.header(0, PassSet{}), Rect{0, 0, 32, 32}, false);
  for (uint32_t p = 0; p < 4; ++p)
    merge_into(manual, r.render(TaskKey{0, {0, 0, 32, 32}, p}, true));
  EXPECT_TRUE(bits_equal(res.frame.sum, manual.sum));
  EXPECT_EQ(res.passes_merged, 4u);
}

TEST(Determinism, NoiseTargetStopsOnACompletedPrefix) {
  // A target between the relMSE after 4 and after 16 passes: the render stops at some k, and
  // its image is exactly the first k passes, whatever the tiling.
  Scene s = test::cornell_box({"", 32, 2, 16});
  Renderer r(s);
  LocalRenderOptions probe;
  probe.pass_count = 8;
  double target = render_local(r, probe).frame.rel_mse();
  LocalRenderOptions opt;
  opt.noise_target = target;
  opt.tile_size = 8;
  LocalRenderResult stopped = render_local(r, opt);
  EXPECT_TRUE(stopped.stopped_on_target);
  // The target is met after 8 passes at the latest (and not before the 4-pass minimum).
  EXPECT_LE(stopped.passes_merged, 8u);
  EXPECT_GE(stopped.passes_merged, 4u);
  EXPECT_EQ(stopped.frame.header.passes, PassSet::range(0, stopped.passes_merged));
  LocalRenderOptions prefix;
  prefix.pass_count = stopped.passes_merged;
  prefix.tile_size = 32;
  LocalRenderResult again = render_local(r, prefix);
  EXPECT_TRUE(bits_equal(again.frame.sum, stopped.frame.sum));
  EXPECT_TRUE(bits_equal(again.frame.batch_sum_sq, stopped.frame.batch_sum_sq));
}

TEST(Determinism, SeedsAndPassesChangeTheImage) {
  Scene s1 = test::cornell_box({"", 16, 2, 2});
  Scene s2 = s1;
  s2.render.seed += 1;
  Renderer r1(s1), r2(s2);
  SampleBuffer a = r1.render(TaskKey{0, {0, 0, 16, 16}, 0}, false);
  SampleBuffer b = r2.render(TaskKey{0, {0, 0, 16, 16}, 0}, false);
  SampleBuffer c = r1.render(TaskKey{0, {0, 0, 16, 16}, 1}, false);
  EXPECT_FALSE(bits_equal(a.sum, b.sum)) << "seeds must give different streams";
  EXPECT_FALSE(bits_equal(a.sum, c.sum)) << "passes must be independent";
}

}  // namespace
}  // namespace rf
