// Tests of engine/frame_accumulator resumed from a checkpointed prefix: bit-identical to an
// uninterrupted merge, the same stop on a noise target, and refusals of what is not its prefix.
#include "engine/frame_accumulator.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <string>
#include <vector>

#include "engine/buffer_file.h"
#include "engine/buffer_merge.h"
#include "engine/digest.h"
#include "tests/support/fixtures.h"

namespace rf {
namespace {

// Synthetic buffers of an 8x8 frame (tests/support/fixtures.h).
BufferHeader make_header(PassSet passes) { return test::test_header(std::move(passes), 8, 8); }
SampleBuffer random_pass(uint32_t pass, Rect rect, uint64_t seed) {
  return test::random_pass(pass, rect, false, seed, 8, 8);
}
using test::expect_bit_identical;

const TileGrid kTiles(8, 8, 4);  // {0,0,4,4}, {4,0,4,4}, {0,4,4,4}, {4,4,4,4}

// Feeds passes [from, to) tile by tile (tiles in reverse order) until the accumulator is done.
void feed(FrameAccumulator& acc, uint32_t from, uint32_t to) {
  for (uint32_t p = from; p < to && !acc.done(); ++p)
    for (size_t t = kTiles.size(); t-- > 0;) acc.add(random_pass(p, kTiles[t], 1000 * p + t));
}

// The grid is the splitter's rects, row-major and clipped at the border (the loop work_units ran
// before it was a TileGrid), and index_of finds each of them and nothing else.
TEST(TileGrid, RectsAreTheSplittersAndIndexOfFindsEachAndNothingElse) {
  struct Case {
    int w, h, tile;
  };
  for (Case c : {Case{37, 21, 8}, Case{32, 32, 16}, Case{5, 7, 0}, Case{5, 7, 8}, Case{1, 1, 1},
                 Case{64, 3, 16}}) {
    TileGrid grid(c.w, c.h, c.tile);
    std::vector<Rect> want;
    if (c.tile <= 0 || (c.tile >= c.w && c.tile >= c.h)) {
      want = {{0, 0, c.w, c.h}};
    } else {
      for (int y = 0; y < c.h; y += c.tile)
        for (int x = 0; x < c.w; x += c.tile)
          want.push_back({x, y, std::min(c.tile, c.w - x), std::min(c.tile, c.h - y)});
    }
    ASSERT_EQ(grid.size(), want.size()) << c.w << "x" << c.h << " in " << c.tile;
    size_t i = 0;
    for (Rect r : grid) {
      EXPECT_TRUE(r == want[i]) << i << ": " << to_string(r) << " vs " << to_string(want[i]);
      EXPECT_EQ(grid.index_of(r), std::optional<size_t>(i)) << to_string(r);
      ++i;
    }
  }
  TileGrid grid(37, 21, 8);
  EXPECT_FALSE(grid.index_of({0, 0, 8, 7})) << "a part of a tile";
  EXPECT_FALSE(grid.index_of({4, 0, 8, 8})) << "off the grid";
  EXPECT_FALSE(grid.index_of({32, 16, 8, 8})) << "past the border (the tile there is 5x5)";
  EXPECT_FALSE(grid.index_of({40, 0, 8, 8}));
  EXPECT_FALSE(grid.index_of({-8, 0, 8, 8}));
  TileGrid big(16384, 16384, 8);  // 4 million tiles, three numbers
  EXPECT_EQ(big.size(), 4194304u);
  EXPECT_TRUE(big[big.size() - 1] == (Rect{16376, 16376, 8, 8}));
  EXPECT_EQ(big.index_of({16376, 16376, 8, 8}), std::optional<size_t>(big.size() - 1));
}

// A frame of many tiles: the accumulator keeps the tiles of a pass that arrived, not a slot per
// tile (512x512 in 1-pixel tiles: 262,144 of them).
TEST(FrameAccumulator, APassOfManyTilesHoldsOnlyTheTilesThatArrived) {
  BufferHeader h = test::test_header({}, 512, 512);
  TileGrid grid(512, 512, 1);
  FrameAccumulator acc(h, grid, false, ProgressiveOptions{0, 2, 0});
  Rect last = grid[grid.size() - 1];
  EXPECT_TRUE(acc.task_needed(last, 0));
  EXPECT_EQ(acc.add(test::random_pass(0, last, false, 7, 512, 512)),
            FrameAccumulator::AddResult::Pending);
  EXPECT_FALSE(acc.task_needed(last, 0));
  EXPECT_TRUE(acc.task_needed(grid[0], 0));
  EXPECT_EQ(acc.tile_index(last), grid.size() - 1);
  EXPECT_THROW(acc.tile_index(Rect{0, 0, 2, 1}), MergeError);
  EXPECT_THROW(FrameAccumulator(h, TileGrid(256, 512, 1), false, ProgressiveOptions{0, 2, 0}),
               MergeError)
      << "a grid of another size than the frame";
}

TEST(FrameAccumulator, ResumedFromEncodedPrefixIsBitIdentical) {
  ProgressiveOptions opt;
  opt.pass_count = 6;
  FrameAccumulator whole(make_header({}), kTiles, false, opt);
  feed(whole, 0, 6);
  ASSERT_TRUE(whole.done());
  ASSERT_EQ(whole.passes_merged(), 6u);

  for (uint32_t k : {0u, 1u, 3u, 5u}) {
    SCOPED_TRACE("resumed after " + std::to_string(k) + " passes");
    FrameAccumulator first(make_header({}), kTiles, false, opt);
    feed(first, 0, k);
    SampleBuffer saved = decode_buffer(encode_buffer(first.frame()), "prefix");
    FrameAccumulator resumed(make_header({}), kTiles, false, opt);
    resumed.resume_from(std::move(saved));
    EXPECT_EQ(resumed.passes_merged(), k);
    EXPECT_FALSE(resumed.done());
    if (k > 0) {
      EXPECT_EQ(resumed.add(random_pass(k - 1, kTiles[0], 1000 * (k - 1))),
                FrameAccumulator::AddResult::Duplicate) << "inside the restored prefix";
    }
    feed(resumed, k, 6);
    ASSERT_TRUE(resumed.done());
    expect_bit_identical(resumed.frame(), whole.frame());
  }
}

TEST(FrameAccumulator, ResumedStopsOnNoiseTargetAtTheSamePass) {
  ProgressiveOptions opt;
  opt.pass_count = 32;
  // relMSE after n passes is about (1/12) / 1.01 / n for these samples: 0.01 stops near pass 9.
  opt.noise_target = 0.01;
  FrameAccumulator whole(make_header({}), kTiles, false, opt);
  feed(whole, 0, 32);
  ASSERT_TRUE(whole.stopped_on_target());
  uint32_t stop = whole.passes_merged();
  ASSERT_GT(stop, opt.min_passes);
  ASSERT_LT(stop, 32u);

  for (uint32_t k : {2u, stop - 1, stop}) {
    SCOPED_TRACE("resumed after " + std::to_string(k) + " passes");
    FrameAccumulator first(make_header({}), kTiles, false, opt);
    feed(first, 0, k);
    FrameAccumulator resumed(make_header({}), kTiles, false, opt);
    resumed.resume_from(decode_buffer(encode_buffer(first.frame()), "prefix"));
    EXPECT_EQ(resumed.done(), k == stop) << "the stop decision is taken again on the prefix";
    feed(resumed, k, 32);
    EXPECT_TRUE(resumed.stopped_on_target());
    EXPECT_EQ(resumed.passes_merged(), stop);
    expect_bit_identical(resumed.frame(), whole.frame());
  }
}

TEST(FrameAccumulator, ResumeRefusesAnotherImageOrANonPrefix) {
  ProgressiveOptions opt;
  opt.pass_count = 6;
  FrameAccumulator first(make_header({}), kTiles, false, opt);
  feed(first, 0, 3);
  SampleBuffer prefix = first.frame();

  SampleBuffer other_seed = prefix;
  other_seed.header.seed = 8;
  FrameAccumulator a(make_header({}), kTiles, false, opt);
  EXPECT_THROW(a.resume_from(other_seed), MergeError);

  SampleBuffer not_prefix = prefix;
  not_prefix.header.passes = PassSet::range(1, 3);
  FrameAccumulator b(make_header({}), kTiles, false, opt);
  EXPECT_THROW(b.resume_from(not_prefix), MergeError);

  SampleBuffer too_long = prefix;
  too_long.header.passes = PassSet::range(0, 7);
  EXPECT_THROW(b.resume_from(too_long), MergeError);

  EXPECT_THROW(first.resume_from(prefix), MergeError) << "not a fresh accumulator";
  EXPECT_EQ(b.passes_merged(), 0u) << "a refused resume leaves the accumulator as it was";
}

// Tasks held encoded (as the coordinator receives them) or owned (as the local render makes
// them), in any arrival order, give the frame that whole passes merged in order give: each pass's
// tiles are added where they lie, and each pixel sums its passes in pass order.
TEST(FrameAccumulator, EncodedAndOwnedTasksInAnyOrderGiveThePassOrderFrame) {
  ProgressiveOptions opt;
  opt.pass_count = 4;
  SampleBuffer expected(make_header({}), Rect{0, 0, 8, 8}, false);
  for (uint32_t p = 0; p < 4; ++p) {
    SampleBuffer pass(make_header(PassSet::range(p, p + 1)), Rect{0, 0, 8, 8}, false);
    for (size_t t = 0; t < kTiles.size(); ++t)
      assemble_tile(pass, random_pass(p, kTiles[t], 1000 * p + t));
    merge_into(expected, pass);
  }
  std::vector<std::pair<uint32_t, size_t>> order;
  for (uint32_t p = 0; p < 4; ++p)
    for (size_t t = 0; t < kTiles.size(); ++t) order.push_back({p, t});
  for (int variant = 0; variant < 3; ++variant) {
    SCOPED_TRACE("variant " + std::to_string(variant));
    if (variant == 1) std::reverse(order.begin(), order.end());  // the last pass first
    if (variant == 2) std::rotate(order.begin(), order.begin() + 5, order.end());
    FrameAccumulator acc(make_header({}), kTiles, false, opt);
    for (size_t i = 0; i < order.size(); ++i) {
      auto [p, t] = order[i];
      SampleBuffer task = random_pass(p, kTiles[t], 1000 * p + t);
      if (i % 2)
        acc.add(EncodedBuffer(encode_buffer(task), "task"));
      else
        acc.add(std::move(task));
    }
    ASSERT_TRUE(acc.done());
    EXPECT_TRUE(same_samples(acc.frame(), expected));
    EXPECT_EQ(acc.frame().rays, expected.rays);
    EXPECT_EQ(acc.frame().header.passes, expected.header.passes);
    // The published figures, kept as passes merged, are the frame's.
    EXPECT_NEAR(acc.rel_mse(), expected.rel_mse(), 1e-12 * expected.rel_mse());
    EXPECT_DOUBLE_EQ(acc.samples_per_pixel(), 12.0);  // 3 samples a pass
  }
}

// A frame kept in tiles on disk (ProgressiveOptions::memory_budget) is the frame held whole, bit
// for bit: the same tasks in any order, with AOVs, tiles clipped at the border, results parked
// in spill files, a stop on a noise target, and a resume; read back a band at a time and
// written as .rfb band by band, the same bytes. Its memory stays within the budget plus a tile.
TEST(FrameAccumulator, AFrameKeptInTilesOnDiskIsTheFrameHeldWhole) {
  const int W = 37, H = 21;
  const TileGrid grid(W, H, 5);  // 8 x 5 tiles, the last column and row clipped
  AovSet aovs;
  aovs.albedo = aovs.depth = true;
  BufferHeader base = test::test_header({}, W, H);
  base.aovs = aovs;
  const size_t na = size_t(aovs.channels());
  auto task = [&](uint32_t p, size_t t) {
    SampleBuffer b = test::random_pass(p, grid[t], false, 1000 * p + t, W, H);
    b.header.aovs = aovs;
    b.aov.resize(size_t(b.rect.area()) * na);
    for (size_t i = 0; i < b.aov.size(); ++i) b.aov[i] = double((i * 7919 + p * 31 + t) % 97) / 8;
    return b;
  };
  std::vector<std::pair<uint32_t, size_t>> order;
  for (uint32_t p = 0; p < 8; ++p)
    for (size_t t = 0; t < grid.size(); ++t) order.push_back({p, t});
  std::mt19937 rng(5);
  std::shuffle(order.begin(), order.end(), rng);

  const uint64_t tile_bytes = 25 * FrameAccumulator::bytes_per_pixel(aovs);
  // Budgets of 6 tiles (bands of 1 row) and 24 (bands of 2 rows, crossing the tiles' rows); the
  // frame needs 31 tiles' worth.
  uint64_t budget = 0;
  const std::string dir = ::testing::TempDir();
  auto feed_all = [&](FrameAccumulator& acc, uint32_t from) {
    for (size_t i = 0; i < order.size(); ++i) {
      auto [p, t] = order[i];
      if (p < from) continue;
      SampleBuffer b = task(p, t);
      if (i % 2)
        acc.add(EncodedBuffer(encode_buffer(b), "task"));
      else
        acc.add(std::move(b));
    }
  };
  auto bands_of = [&](const FrameAccumulator& acc) {
    SampleBuffer out(acc.info().header, Rect{0, 0, W, H}, false);
    out.light_paths = acc.info().light_paths;
    out.nonfinite_samples = acc.info().nonfinite_samples;
    out.rays = acc.info().rays;
    for (int y0 = 0; y0 < H; y0 += acc.band_height()) {
      const SampleBuffer& band = acc.band(y0);
      EXPECT_EQ(band.rect, (Rect{0, y0, W, std::min(acc.band_height(), H - y0)}));
      for (int y = band.rect.y0; y < band.rect.y1(); ++y)
        for (int x = 0; x < W; ++x) {
          size_t s = band.pixel_index(x, y), d = out.pixel_index(x, y);
          out.count[d] = band.count[s];
          for (int c = 0; c < 3; ++c) {
            out.sum[3 * d + c] = band.sum[3 * s + c];
            out.sum_sq[3 * d + c] = band.sum_sq[3 * s + c];
            out.batch_sum[3 * d + c] = band.batch_sum[3 * s + c];
            out.batch_sum_sq[3 * d + c] = band.batch_sum_sq[3 * s + c];
          }
          for (size_t c = 0; c < na; ++c) out.aov[na * d + c] = band.aov[na * s + c];
        }
    }
    return out;
  };
  auto check_same = [&](const FrameAccumulator& tiled, const FrameAccumulator& whole) {
    ASSERT_TRUE(tiled.tiled());
    ASSERT_FALSE(whole.tiled());
    EXPECT_EQ(tiled.passes_merged(), whole.passes_merged());
    EXPECT_EQ(tiled.rel_mse_history(), whole.rel_mse_history()) << "the same sums, same order";
    EXPECT_EQ(tiled.stopped_on_target(), whole.stopped_on_target());
    EXPECT_EQ(tiled.total_samples(), whole.total_samples());
    EXPECT_EQ(tiled.samples_per_pixel(), whole.samples_per_pixel());
    SampleBuffer read = bands_of(tiled);
    expect_bit_identical(read, whole.frame());
    EXPECT_TRUE(test::bits_equal(read.aov, whole.frame().aov));
    EXPECT_THROW(tiled.frame(), std::logic_error);
    // Written band by band, the bytes of the whole frame's file.
    write_buffer_file(dir + "/tiled.rfb", tiled);
    write_buffer_file(dir + "/whole.rfb", whole.frame());
    EXPECT_EQ(read_file_bytes(dir + "/tiled.rfb"), read_file_bytes(dir + "/whole.rfb"));
    // Within the budget: half for tiles (plus the one being read), half for waiting results;
    // the rest of the waiting results were parked on disk.
    FrameAccumulator::SpillUse use = tiled.spill_use();
    EXPECT_LE(use.peak_tile_bytes, budget / 2 + tile_bytes);
    EXPECT_GE(use.peak_tile_bytes, budget / 2) << "the cache is used";
    EXPECT_LE(use.peak_waiting_bytes, budget / 2);
    EXPECT_EQ(tiled.band_height(), budget == 6 * tile_bytes ? 1 : 2);
    EXPECT_GT(use.parked_results, 0u);
  };

  for (double target : {0.0, -1.0, 0.5}) {
    SCOPED_TRACE(target == 0 ? "all passes" : "stopped on a noise target");
    budget = (target == 0.5 ? 24 : 6) * tile_bytes;
    if (target > 0) target = 0;
    ProgressiveOptions whole_opt;
    whole_opt.pass_count = 8;
    FrameAccumulator probe(base, grid, false, whole_opt);
    feed_all(probe, 0);
    ASSERT_EQ(probe.passes_merged(), 8u);
    // A target the prefix of 5 passes meets (or the smallest after 4: the stop needs 4 passes).
    if (target < 0)
      whole_opt.noise_target = *std::min_element(probe.rel_mse_history().begin() + 3,
                                                 probe.rel_mse_history().begin() + 6);
    ProgressiveOptions tiled_opt = whole_opt;
    tiled_opt.memory_budget = budget;
    tiled_opt.spill_dir = dir;
    FrameAccumulator whole(base, grid, false, whole_opt), tiled(base, grid, false, tiled_opt);
    feed_all(whole, 0);
    feed_all(tiled, 0);
    ASSERT_TRUE(whole.done() && tiled.done());
    if (target < 0) ASSERT_TRUE(whole.stopped_on_target());
    check_same(tiled, whole);
  }

  // Resumed from a prefix of 3 passes, in tiles.
  ProgressiveOptions opt;
  opt.pass_count = 8;
  FrameAccumulator first(base, grid, false, opt), whole(base, grid, false, opt);
  feed_all(whole, 0);
  for (auto [p, t] : order)
    if (p < 3) first.add(task(p, t));
  ASSERT_EQ(first.passes_merged(), 3u);
  opt.memory_budget = 6 * tile_bytes;
  opt.spill_dir = dir;
  FrameAccumulator resumed(base, grid, false, opt);
  resumed.resume_from(decode_buffer(encode_buffer(first.frame()), "prefix"));
  feed_all(resumed, 3);
  ASSERT_TRUE(resumed.done());
  EXPECT_TRUE(same_samples(bands_of(resumed), whole.frame()));
  // And from the checkpoint file read 3 rows at a time (bands crossing the tiles' rows), into
  // tiles and whole.
  write_buffer_file(dir + "/prefix.rfb", first.frame());
  const uint64_t row = uint64_t(W) * FrameAccumulator::bytes_per_pixel(aovs);
  for (uint64_t budget_now : {opt.memory_budget, uint64_t(0)}) {
    BufferFileBands file(dir + "/prefix.rfb", 3 * row);
    ASSERT_EQ(file.band_height(), 3);
    EXPECT_EQ(file.total_samples(), first.frame().total_samples());
    opt.memory_budget = budget_now;
    FrameAccumulator from_file(base, grid, false, opt);
    from_file.resume_from(file);
    EXPECT_EQ(from_file.tiled(), budget_now > 0);
    EXPECT_EQ(from_file.passes_merged(), 3u);
    feed_all(from_file, 3);
    ASSERT_TRUE(from_file.done());
    EXPECT_TRUE(
        same_samples(from_file.tiled() ? bands_of(from_file) : from_file.frame(), whole.frame()));
  }
}

// An .rfb file read in bands is the file read whole: the rows, the samples, the relMSE (summed
// in the same order), and the EXR written from it has the same pixels and noise figure.
TEST(BufferFileBands, ReadsAFileABandAtATimeAsItReadsWhole) {
  BufferHeader h = test::test_header(PassSet::range(0, 3), 37, 21);
  SampleBuffer frame(h, Rect{0, 0, 37, 21}, false);
  for (uint32_t p = 0; p < 3; ++p) {
    SampleBuffer pass = test::random_pass(p, Rect{0, 0, 37, 21}, false, 77 + p, 37, 21);
    pass.header.passes = PassSet{};
    add_tile(frame, pass);
  }
  const std::string dir = ::testing::TempDir();
  write_buffer_file(dir + "/f.rfb", frame);
  for (uint64_t band_bytes : {uint64_t(1), uint64_t(4 * 37 * 104), uint64_t(1) << 30}) {
    BufferFileBands file(dir + "/f.rfb", band_bytes);
    EXPECT_EQ(file.band_height(), band_bytes == 1 ? 1 : band_bytes < 1000000 ? 4 : 21);
    EXPECT_EQ(file.total_samples(), frame.total_samples());
    EXPECT_EQ(file.rel_mse(), frame.rel_mse()) << "the same sum in the same order";
    for (int y0 = 0; y0 < 21; y0 += file.band_height()) {
      const SampleBuffer& b = file.band(y0);
      for (int y = b.rect.y0; y < b.rect.y1(); ++y)
        for (int x = 0; x < 37; ++x) {
          ASSERT_EQ(b.count[b.pixel_index(x, y)], frame.count[frame.pixel_index(x, y)]);
          for (int c = 0; c < 3; ++c)
            ASSERT_EQ(b.batch_sum_sq[3 * b.pixel_index(x, y) + c],
                      frame.batch_sum_sq[3 * frame.pixel_index(x, y) + c]);
        }
    }
  }
  // A damaged file is refused before a band is read.
  std::string bytes = read_file_bytes(dir + "/f.rfb");
  bytes[bytes.size() / 2] ^= 1;
  write_file_atomic(dir + "/bad.rfb", bytes);
  try {
    BufferFileBands bad(dir + "/bad.rfb", 1 << 20);
    ADD_FAILURE() << "a damaged file was opened";
  } catch (const BufferFileError& e) {
    EXPECT_NE(std::string(e.what()).find("checksum"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("bad.rfb"), std::string::npos) << e.what();
  }
}

// A frame that fits the budget, one tile, or a splat plane is held whole.
TEST(FrameAccumulator, IsHeldWholeWhenItFitsOrCannotBeCut) {
  ProgressiveOptions opt;
  opt.pass_count = 2;
  opt.memory_budget = 64 * 104;
  opt.spill_dir = ::testing::TempDir();
  EXPECT_FALSE(FrameAccumulator(make_header({}), kTiles, false, opt).tiled()) << "64 pixels fit";
  BufferHeader big = test::test_header({}, 64, 64);
  EXPECT_TRUE(FrameAccumulator(big, TileGrid(64, 64, 16), false, opt).tiled());
  EXPECT_FALSE(FrameAccumulator(big, TileGrid(64, 64, 0), false, opt).tiled()) << "one tile";
  EXPECT_FALSE(FrameAccumulator(big, TileGrid(64, 64, 16), true, opt).tiled()) << "splats";
  opt.spill_dir = "/nonexistent-rayfarm-dir";
  try {
    FrameAccumulator(big, TileGrid(64, 64, 16), false, opt);
    ADD_FAILURE() << "a spill directory that does not exist";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent-rayfarm-dir"), std::string::npos)
        << e.what();
  }
}

// Partial results merged a band at a time from their files (rayfarm merge): the bytes the inputs
// merged whole in the same order give, over bands of 2 rows; a bad input named.
TEST(MergedBands, FilesMergedABandAtATimeAreTheFilesMergedWhole) {
  const int W = 37, H = 21;
  const std::string dir = ::testing::TempDir();
  std::vector<SampleBuffer> parts;
  // (merge checks each pixel's samples against the header's spp_per_pass: 3 in random_pass)
  BufferHeader h = test::test_header({}, W, H);
  h.settings += ";spp_per_pass=3";
  for (uint32_t p0 : {0u, 2u, 5u}) {  // passes 0-1, 2-4, 5
    SampleBuffer part(h, Rect{0, 0, W, H}, false);
    for (uint32_t p = p0; p < (p0 == 0 ? 2u : p0 == 2 ? 5u : 6u); ++p) {
      SampleBuffer pass = test::random_pass(p, Rect{0, 0, W, H}, false, 500 + p, W, H);
      pass.header.settings = h.settings;
      merge_into(part, pass);
    }
    parts.push_back(part);
    write_buffer_file(dir + "/part" + std::to_string(p0) + ".rfb", part);
  }
  SampleBuffer whole = parts[0];
  merge_into(whole, parts[1]);
  merge_into(whole, parts[2]);
  write_buffer_file(dir + "/whole.rfb", whole);
  auto open_all = [&](const std::vector<std::string>& names) {
    std::vector<std::unique_ptr<FrameBands>> in;
    for (const std::string& n : names)
      in.push_back(std::make_unique<BufferFileBands>(dir + "/" + n, 2 * W * 104));
    return in;
  };
  const std::vector<std::string> names = {"part0.rfb", "part2.rfb", "part5.rfb"};
  MergedBands merged(open_all(names), names);
  ASSERT_EQ(merged.band_height(), 2);
  EXPECT_EQ(merged.total_samples(), whole.total_samples());
  EXPECT_EQ(merged.rel_mse(), whole.rel_mse()) << "the same sums in the same order";
  write_buffer_file(dir + "/merged.rfb", merged);
  EXPECT_TRUE(read_file_bytes(dir + "/merged.rfb") == read_file_bytes(dir + "/whole.rfb"));

  const std::vector<std::string> twice = {"part0.rfb", "part2.rfb", "part0.rfb"};
  try {
    MergedBands bad(open_all(twice), twice);
    ADD_FAILURE() << "overlapping passes were merged";
  } catch (const MergeError& e) {
    EXPECT_NE(std::string(e.what()).find("part0.rfb: cannot merge into part0.rfb"),
              std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace rf
