// Tests of coordinator/checkpoint: a frame's durable prefix and task log, torn and corrupt records,
// the log's compaction, and task files of builds before the log.
#include "coordinator/checkpoint.h"
#include "coordinator/group_sync.h"

#include <gtest/gtest.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "engine/buffer_file.h"
#include "engine/buffer_merge.h"
#include "tests/support/fixtures.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

namespace fs = std::filesystem;

// Synthetic buffers of an 8x8 frame (tests/support/fixtures.h).
BufferHeader make_header(PassSet passes) { return test::test_header(std::move(passes), 8, 8); }
SampleBuffer random_pass(uint32_t pass, Rect rect, uint64_t seed) {
  return test::random_pass(pass, rect, false, seed, 8, 8);
}
using test::expect_bit_identical;

// Flips the byte at `at` of the file.
void flip_byte(const std::string& path, uint64_t at) {
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  f.seekg(std::streamoff(at));
  char c = 0;
  f.get(c);
  f.seekp(std::streamoff(at));
  f.put(char(c ^ 0x5a));
}

TEST(FrameCheckpoint, PrefixAbsorbsTasksAndCorruptRecordsAreSkipped) {
  std::string dir = test::make_temp_dir("checkpoint") + "/frame-3";
  FrameCheckpoint cp(dir);
  const Rect tile0{0, 0, 4, 8}, tile1{4, 0, 4, 8};
  SampleBuffer t01 = random_pass(0, tile1, 1), t10 = random_pass(1, tile0, 2),
               t21 = random_pass(2, tile1, 3);
  cp.save_task(0, 1, t01);
  cp.save_task(1, 0, t10);
  cp.save_task(2, 1, t21);
  const uint64_t before_prefix = fs::file_size(dir + "/tasks.log");
  SampleBuffer prefix = random_pass(0, Rect{0, 0, 8, 8}, 4);  // passes [0, 1)
  cp.save_prefix(prefix);
  // Two of its three records are of later passes: the log stays as it is until most of it is
  // merged.
  EXPECT_EQ(fs::file_size(dir + "/tasks.log"), before_prefix);

  FrameCheckpoint::Loaded loaded = cp.load();
  EXPECT_TRUE(loaded.problems.empty());
  ASSERT_TRUE(loaded.prefix);
  expect_bit_identical(loaded.prefix->band(0), prefix);
  ASSERT_EQ(loaded.tasks.size(), 2u) << "the record of pass 0 is inside the prefix";
  EXPECT_EQ(loaded.tasks[0].pass, 1u);
  EXPECT_EQ(loaded.tasks[0].tile, 0u);
  expect_bit_identical(loaded.tasks[0].buffer, t10);
  EXPECT_EQ(loaded.tasks[1].pass, 2u);
  EXPECT_EQ(loaded.tasks[1].tile, 1u);
  expect_bit_identical(loaded.tasks[1].buffer, t21);

  // One byte flipped in the middle of the last record's buffer: its checksum no longer matches,
  // it is skipped (its task is rendered again) and the others still read.
  flip_byte(dir + "/tasks.log", before_prefix - encode_buffer(t21).size() / 2);
  loaded = cp.load();
  ASSERT_EQ(loaded.problems.size(), 1u);
  EXPECT_NE(loaded.problems[0].find("task 2-1"), std::string::npos) << loaded.problems[0];
  EXPECT_NE(loaded.problems[0].find("checksum mismatch"), std::string::npos) << loaded.problems[0];
  ASSERT_EQ(loaded.tasks.size(), 1u);
  EXPECT_EQ(loaded.tasks[0].pass, 1u);
  EXPECT_TRUE(loaded.prefix);
}

// A crash in the middle of an append leaves a torn record at the log's end: it is cut off, and
// the next append follows the last whole record.
TEST(FrameCheckpoint, ATornAppendIsCutOffAndTheLogGoesOn) {
  std::string dir = test::make_temp_dir("checkpoint-torn") + "/frame-0";
  const Rect tile0{0, 0, 4, 8}, tile1{4, 0, 4, 8};
  SampleBuffer t00 = random_pass(0, tile0, 5), t01 = random_pass(0, tile1, 6);
  {
    FrameCheckpoint cp(dir);
    cp.save_task(0, 0, t00);
    cp.save_task(0, 1, t01);
  }
  const uint64_t whole = fs::file_size(dir + "/tasks.log");
  fs::resize_file(dir + "/tasks.log", whole - 100);  // the second record's end never arrived
  {
    FrameCheckpoint cp(dir);  // a new process
    FrameCheckpoint::Loaded loaded = cp.load();
    ASSERT_EQ(loaded.problems.size(), 1u);
    EXPECT_NE(loaded.problems[0].find("not a whole record; cut off"), std::string::npos)
        << loaded.problems[0];
    ASSERT_EQ(loaded.tasks.size(), 1u);
    expect_bit_identical(loaded.tasks[0].buffer, t00);
    cp.save_task(0, 1, t01);
  }
  FrameCheckpoint::Loaded loaded = FrameCheckpoint(dir).load();
  EXPECT_TRUE(loaded.problems.empty());
  ASSERT_EQ(loaded.tasks.size(), 2u);
  expect_bit_identical(loaded.tasks[1].buffer, t01);
  // A process that appends without loading first cuts a torn end off too.
  fs::resize_file(dir + "/tasks.log", fs::file_size(dir + "/tasks.log") - 7);
  FrameCheckpoint(dir).save_task(0, 1, t01);
  loaded = FrameCheckpoint(dir).load();
  EXPECT_TRUE(loaded.problems.empty());
  EXPECT_EQ(loaded.tasks.size(), 2u);
}

// The log is emptied once the prefix holds all of it, rewritten with the later passes' records
// once they are less than half of it; task files of builds before the log are still read, and
// removed once inside the prefix.
TEST(FrameCheckpoint, TheLogShrinksAsThePrefixGrowsAndOldTaskFilesStillRead) {
  std::string dir = test::make_temp_dir("checkpoint-compact") + "/frame-1";
  FrameCheckpoint cp(dir);
  const Rect frame{0, 0, 8, 8};
  for (uint32_t p = 0; p < 4; ++p) cp.save_task(p, 0, random_pass(p, frame, 10 + p));
  const uint64_t record = fs::file_size(dir + "/tasks.log") / 4;
  SampleBuffer prefix = random_pass(0, frame, 20);
  for (uint32_t p = 1; p < 3; ++p) merge_into(prefix, random_pass(p, frame, 20 + p));
  cp.save_prefix(prefix);  // passes 0-2: one record of four is live
  EXPECT_EQ(fs::file_size(dir + "/tasks.log"), record);
  FrameCheckpoint::Loaded loaded = cp.load();
  ASSERT_EQ(loaded.tasks.size(), 1u);
  EXPECT_EQ(loaded.tasks[0].pass, 3u);
  expect_bit_identical(loaded.tasks[0].buffer, random_pass(3, frame, 13));
  merge_into(prefix, random_pass(3, frame, 23));
  cp.save_prefix(prefix);
  EXPECT_EQ(fs::file_size(dir + "/tasks.log"), 0u);

  // A task file as the build before the log wrote it (pass 4, tile 0).
  SampleBuffer old = random_pass(4, frame, 30);
  write_buffer_file(dir + "/task-4-0.rfb", old);
  loaded = cp.load();
  ASSERT_EQ(loaded.tasks.size(), 1u);
  expect_bit_identical(loaded.tasks[0].buffer, old);
  merge_into(prefix, old);
  cp.save_prefix(prefix);
  EXPECT_FALSE(fs::exists(dir + "/task-4-0.rfb"));
}

// Sixteen uploads in flight, each announced before its write: the flush that the first to call
// sync() starts waits for the others to take their tickets, and one syncfs covers them all.
TEST(GroupSync, OneFlushCoversTheWritersInFlight) {
  std::string dir = test::make_temp_dir("group-sync");
  GroupSync g(dir, /*gather_seconds=*/10);  // the gather ends when all have come, not on time
  const int n = 16;
  std::vector<std::unique_ptr<GroupSync::Writer>> writers;
  for (int i = 0; i < n; ++i) writers.push_back(std::make_unique<GroupSync::Writer>(g));
  std::vector<std::thread> threads;
  std::atomic<int> done{0};
  for (int i = 0; i < n; ++i)
    threads.emplace_back([&, i] {
      test::write_text(dir + "/f" + std::to_string(i), "result");
      writers[size_t(i)]->sync();
      ++done;
    });
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(done, n);
  EXPECT_EQ(g.flushes(), 1u);
  g.sync();  // an unannounced writer flushes alone
  EXPECT_EQ(g.flushes(), 2u);
}

}  // namespace
}  // namespace rf
