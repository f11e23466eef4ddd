// Tests of the coordinator's durable state and restart path: the SQLite job store, the frame
// checkpoints, resuming a frame accumulator from a checkpointed prefix, per-frame file patterns,
// and the scheduler accepting results of leases issued before a restart.
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "coordinator/checkpoint.h"
#include "coordinator/job_store.h"
#include "coordinator/scheduler.h"
#include "engine/buffer_file.h"
#include "engine/buffer_merge.h"
#include "engine/frame_accumulator.h"
#include "farm/frame_range.h"
#include "tests/support/fixtures.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

namespace fs = std::filesystem;
using namespace std::string_literals;

// Synthetic buffers of an 8x8 frame (tests/support/fixtures.h).
BufferHeader make_header(PassSet passes) { return test::test_header(std::move(passes), 8, 8); }
SampleBuffer random_pass(uint32_t pass, Rect rect, uint64_t seed) {
  return test::random_pass(pass, rect, false, seed, 8, 8);
}
using test::expect_bit_identical;

// ----------------------------------------------------------------------------------- JobStore

TEST(JobStore, StateSurvivesReopening) {
  std::string path = test::make_temp_dir("jobstore") + "/jobs.db";
  const std::string spec = "\x0a\x03" "abc\0\0\x12\x00\xff"s;  // serialized protobuf: has NULs
  ASSERT_EQ(spec.size(), 10u);
  {
    JobStore store(path);
    EXPECT_EQ(store.next_seq(), 1u) << "empty store";
    store.insert_job({"job-a", 5, spec, 1, "", 1700000000, 0});
    store.insert_job({"job-b", 9, "other", 1, "", 1700000100, 0});
    store.set_state("job-a", 3, "task frame 0 failed");
    store.add_core_seconds("job-a", 1.25);
    store.add_core_seconds("job-a", 2.5);
    store.task_done("job-a", 0, 0, 0, "w1");
    store.task_done("job-a", 0, 0, 1, "w2");
    store.task_failed("job-a", 0, 1, 0, "w1", "out of memory");
    store.task_done("job-b", 0, 0, 0, "w1");
  }
  JobStore store(path);
  std::vector<StoredJob> jobs = store.jobs();
  ASSERT_EQ(jobs.size(), 2u);
  const StoredJob& a = jobs[0];
  EXPECT_EQ(a.id, "job-a");
  EXPECT_EQ(a.seq, 5u);
  EXPECT_EQ(a.spec, spec);
  EXPECT_EQ(a.state, 3);
  EXPECT_EQ(a.error, "task frame 0 failed");
  EXPECT_EQ(a.submitted_unix, 1700000000);
  EXPECT_EQ(a.core_seconds, 3.75);  // exact: 1.25 and 2.5 are binary fractions
  EXPECT_EQ(jobs[1].id, "job-b");
  EXPECT_EQ(jobs[1].state, 1);
  EXPECT_EQ(jobs[1].error, "");
  EXPECT_EQ(jobs[1].core_seconds, 0.0);
  EXPECT_EQ(store.tasks_done("job-a"), 2u) << "the failure is not counted";
  EXPECT_EQ(store.tasks_done("job-b"), 1u);
  EXPECT_EQ(store.tasks_done("job-none"), 0u);
  EXPECT_EQ(store.next_seq(), 10u);
}

TEST(JobStore, UnwritablePathThrowsNamingIt) {
  std::string file = test::make_temp_dir("jobstore-bad") + "/regular-file";
  test::write_text(file, "not a directory");
  std::string path = file + "/jobs.db";
  try {
    JobStore store(path);
    ADD_FAILURE() << "opening " << path << " did not throw";
  } catch (const StoreError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

// ------------------------------------------------------------------------------ FrameCheckpoint

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

// ------------------------------------------------------------------- FrameAccumulator resume

const std::vector<Rect> kTiles = {{0, 0, 4, 4}, {4, 0, 4, 4}, {0, 4, 4, 4}, {4, 4, 4, 4}};

// Feeds passes [from, to) tile by tile (tiles in reverse order) until the accumulator is done.
void feed(FrameAccumulator& acc, uint32_t from, uint32_t to) {
  for (uint32_t p = from; p < to && !acc.done(); ++p)
    for (size_t t = kTiles.size(); t-- > 0;) acc.add(random_pass(p, kTiles[t], 1000 * p + t));
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

// ------------------------------------------------------------------------ expand_frame_pattern

TEST(ExpandFramePattern, PadsEachRunOfHashes) {
  EXPECT_EQ(expand_frame_pattern("shot.####.json", 7), "shot.0007.json");
  EXPECT_EQ(expand_frame_pattern("shot.####.json", 12345), "shot.12345.json");
  EXPECT_EQ(expand_frame_pattern("a#b##", 3), "a3b03");
  EXPECT_EQ(expand_frame_pattern("scene.json", 42), "scene.json");
  EXPECT_EQ(expand_frame_pattern("#", 0), "0");
}

// ------------------------------------------------------------------------- Scheduler restart

TEST(SchedulerRestart, ResultOfALeaseFromBeforeARestartCountsOnce) {
  Scheduler before({30, 3, 4, "A"});
  before.add_job("j", {0, 1}, /*tiles=*/2, /*passes=*/1, 0);
  auto old = before.lease("w", 0);
  ASSERT_TRUE(old);
  EXPECT_EQ(old->lease_id.rfind("A", 0), 0u) << old->lease_id;
  EXPECT_EQ(before.lease_task(old->lease_id), old->task);

  Scheduler after({30, 3, 4, "B"});  // the restarted coordinator
  after.add_job("j", {0, 1}, 2, 1, 0);
  EXPECT_FALSE(after.lease_task(old->lease_id)) << "the old lease is unknown after the restart";
  EXPECT_EQ(after.complete(old->lease_id, old->task, 1), CompleteOutcome::Accepted);
  EXPECT_EQ(after.complete(old->lease_id, old->task, 2), CompleteOutcome::Duplicate);
  EXPECT_EQ(after.complete(old->lease_id, 2), CompleteOutcome::NotFound) << "by lease id alone";
  EXPECT_EQ(after.complete(old->lease_id, TaskRef{"gone", 0, 0, 0}, 2),
            CompleteOutcome::NotFound);

  // The accepted task is not handed out again; the others are, under the new prefix.
  std::vector<TaskRef> leased;
  while (auto l = after.lease("w", 3)) {
    EXPECT_EQ(l->lease_id.rfind("B", 0), 0u) << l->lease_id;
    EXPECT_EQ(after.lease_task(l->lease_id), l->task);
    leased.push_back(l->task);
  }
  EXPECT_EQ(leased.size(), 3u);
  for (const TaskRef& t : leased) EXPECT_FALSE(t == old->task);
}

TEST(SchedulerRestart, ALeaseIdReusedForAnotherTaskIsMatchedByTask) {
  Scheduler after;  // default prefix "L", as before the restart: lease ids repeat
  after.add_job("j", {0}, 2, 1, 0);
  auto fresh = after.lease("v", 1);  // "L1" again, now for tile 0
  ASSERT_TRUE(fresh);
  ASSERT_EQ(fresh->lease_id, "L1");
  TaskRef old_task{"j", 0, 0, 1};  // what "L1" was for before the restart
  EXPECT_EQ(after.complete("L1", old_task, 2), CompleteOutcome::Accepted);
  EXPECT_EQ(after.renew("L1", 2), LeaseOutcome::Ok) << "the other task's lease lives on";
  EXPECT_FALSE(after.lease("w", 2)) << "tile 1 is done, tile 0 is leased";
  EXPECT_EQ(after.complete("L1", fresh->task, 3), CompleteOutcome::Accepted);
  EXPECT_FALSE(after.work_left_for("w"));
}

TEST(SchedulerRestart, MarkDoneTasksAreNeverLeased) {
  Scheduler s;
  s.add_job("j", {4}, /*tiles=*/3, /*passes=*/1, 0);
  s.mark_done({"j", 4, 0, 0});
  s.mark_done({"j", 4, 0, 2});
  s.mark_done({"j", 4, 0, 2});    // twice: no effect
  s.mark_done({"j", 9, 0, 0});    // unknown task: ignored
  auto l = s.lease("w", 0);
  ASSERT_TRUE(l);
  EXPECT_EQ(l->task, (TaskRef{"j", 4, 0, 1}));
  EXPECT_FALSE(s.lease("w", 0));
  EXPECT_EQ(s.complete(l->lease_id, 1), CompleteOutcome::Accepted);
  EXPECT_FALSE(s.work_left_for("w"));
  EXPECT_EQ(s.complete("x", {"j", 4, 0, 0}, 2), CompleteOutcome::Duplicate) << "already done";
}

}  // namespace
}  // namespace rf
