// Tests of coordinator/job_store: the SQLite job store keeps its state across reopening and
// names the path it cannot write.
#include "coordinator/job_store.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <string>

#include "tests/support/test_support.h"

namespace rf {
namespace {

namespace fs = std::filesystem;
using namespace std::string_literals;

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

}  // namespace
}  // namespace rf
