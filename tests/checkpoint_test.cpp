// Tests of coordinator/checkpoint: a frame's durable prefix and task files, and corrupt files set
// aside.
#include "coordinator/checkpoint.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "engine/buffer_file.h"
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

TEST(FrameCheckpoint, PrefixAbsorbsTasksAndCorruptFilesAreSetAside) {
  std::string dir = test::make_temp_dir("checkpoint") + "/frame-3";
  FrameCheckpoint cp(dir);
  const Rect tile0{0, 0, 4, 8}, tile1{4, 0, 4, 8};
  SampleBuffer t01 = random_pass(0, tile1, 1), t10 = random_pass(1, tile0, 2),
               t21 = random_pass(2, tile1, 3);
  cp.save_task(0, 1, t01);
  cp.save_task(1, 0, t10);
  cp.save_task(2, 1, t21);
  SampleBuffer prefix = random_pass(0, Rect{0, 0, 8, 8}, 4);  // passes [0, 1)
  cp.save_prefix(prefix);
  EXPECT_FALSE(fs::exists(dir + "/task-0-1.rfb")) << "inside the prefix: removed";

  FrameCheckpoint::Loaded loaded = cp.load();
  EXPECT_TRUE(loaded.problems.empty());
  ASSERT_TRUE(loaded.prefix);
  expect_bit_identical(*loaded.prefix, prefix);
  ASSERT_EQ(loaded.tasks.size(), 2u);
  EXPECT_EQ(loaded.tasks[0].pass, 1u);
  EXPECT_EQ(loaded.tasks[0].tile, 0u);
  expect_bit_identical(loaded.tasks[0].buffer, t10);
  EXPECT_EQ(loaded.tasks[1].pass, 2u);
  EXPECT_EQ(loaded.tasks[1].tile, 1u);
  expect_bit_identical(loaded.tasks[1].buffer, t21);

  // Flip one byte in the middle of task-2-1.rfb: its checksum no longer matches.
  std::string bad = dir + "/task-2-1.rfb";
  {
    std::fstream f(bad, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(std::streamoff(fs::file_size(bad) / 2));
    char c = 0;
    f.get(c);
    f.seekp(std::streamoff(fs::file_size(bad) / 2));
    f.put(char(c ^ 0x5a));
  }
  loaded = cp.load();
  ASSERT_EQ(loaded.problems.size(), 1u);
  EXPECT_NE(loaded.problems[0].find("task-2-1.rfb"), std::string::npos) << loaded.problems[0];
  EXPECT_FALSE(fs::exists(bad));
  EXPECT_TRUE(fs::exists(bad + ".bad"));
  ASSERT_EQ(loaded.tasks.size(), 1u);
  EXPECT_EQ(loaded.tasks[0].pass, 1u);
  EXPECT_TRUE(loaded.prefix);
  EXPECT_TRUE(cp.load().problems.empty()) << "a set-aside file is not read again";
}

}  // namespace
}  // namespace rf
