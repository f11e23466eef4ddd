// Tests of coordinator/job_store.h: one list of tests runs against both stores (SQLite on disk,
// reopened between writing and reading; memory, the same object), then what only SQLite has (a
// path it cannot write, rows of earlier builds), and the store's codec for a job spec
// (spec_codec.h) against the wire's protobuf encoding it replaced.
#include "coordinator/job_store.h"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <filesystem>
#include <functional>
#include <random>
#include <string>

#include "coordinator/spec_codec.h"
#include "farm/convert.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

namespace fs = std::filesystem;
using namespace std::string_literals;

// A store and the way to get it back as a restarted coordinator would.
struct StoreKind {
  std::string name;
  std::function<std::shared_ptr<JobStore>(const std::string& dir)> open;
  bool reopens;  // reopening reads from disk (SQLite); memory hands back the same object
};

class StoreTest : public ::testing::TestWithParam<StoreKind> {
 protected:
  void SetUp() override {
    dir_ = test::make_temp_dir("store-" + GetParam().name);
    store_ = GetParam().open(dir_);
  }
  // As after a restart.
  JobStore& reopened() {
    if (GetParam().reopens) {
      store_.reset();
      store_ = GetParam().open(dir_);
    }
    return *store_;
  }
  JobStore& store() { return *store_; }

 private:
  std::string dir_;
  std::shared_ptr<JobStore> store_;
};

JobSpec spec_named(const std::string& name) {
  JobSpec s;
  s.name = name;
  s.scene_path = "shot.####.json";
  s.files = {{"shot.0001.json", std::string(64, 'a')}, {"m/tree.ply", std::string(64, 'b')}};
  s.frames = "1-3";
  s.overrides.spp = 64;
  s.overrides.noise_target = 0.125;
  s.priority = -2;
  s.tile_size = 32;
  s.request_id = "r1";
  return s;
}

TEST_P(StoreTest, JobsTheirStatesCoreSecondsAndTaskEventsSurvive) {
  EXPECT_EQ(store().next_seq(), 1u) << "empty store";
  store().write(store::InsertJob{{"job-a", 5, spec_named("a"), 1, "", 1700000000, 0, "t1", ""}});
  store().write(std::vector<StoreWrite>{
      store::InsertJob{{"job-b", 9, spec_named("b\nc"), 1, "", 1700000100, 0, "", ""}},
      store::SetState{"job-a", 3, "task frame 0 failed"}, store::AddCoreSeconds{"job-a", 1.25},
      store::AddCoreSeconds{"job-a", 2.5}, store::SetBuild{"job-a", "build-7"},
      store::TaskEvent{"job-a", 0, 0, 0, "w1", TaskEventKind::Done, ""},
      store::TaskEvent{"job-a", 0, 0, 1, "w2", TaskEventKind::Done, ""},
      store::TaskEvent{"job-a", 0, 1, 0, "w1", TaskEventKind::Failed, "out of memory"},
      store::TaskEvent{"job-a", 0, 1, 1, "w3", TaskEventKind::ResultRefused, "NaN"},
      store::TaskEvent{"job-b", 0, 0, 0, "w1", TaskEventKind::Done, ""}});
  JobStore& s = reopened();
  std::vector<StoredJob> jobs = s.jobs();
  ASSERT_EQ(jobs.size(), 2u);
  const StoredJob& a = jobs[0];
  EXPECT_EQ(a.id, "job-a");
  EXPECT_EQ(a.seq, 5u);
  ASSERT_TRUE(a.spec);
  EXPECT_EQ(*a.spec, spec_named("a"));
  EXPECT_EQ(a.state, 3);
  EXPECT_EQ(a.error, "task frame 0 failed");
  EXPECT_EQ(a.submitted_unix, 1700000000);
  EXPECT_EQ(a.core_seconds, 3.75);  // exact: 1.25 and 2.5 are binary fractions
  EXPECT_EQ(a.tenant, "t1");
  EXPECT_EQ(a.build_id, "build-7");
  EXPECT_EQ(jobs[1].id, "job-b");
  EXPECT_EQ(*jobs[1].spec, spec_named("b\nc"));
  EXPECT_EQ(jobs[1].state, 1);
  EXPECT_EQ(jobs[1].error, "");
  EXPECT_EQ(jobs[1].core_seconds, 0.0);
  EXPECT_EQ(s.tasks_done("job-a"), 2u) << "the failure and the refusal are not counted";
  EXPECT_EQ(s.tasks_done("job-b"), 1u);
  EXPECT_EQ(s.tasks_done("job-none"), 0u);
  ASSERT_EQ(s.failures("job-a").size(), 1u);
  EXPECT_EQ(s.failures("job-a")[0].message, "out of memory");
  EXPECT_EQ(s.failures("job-a")[0].pass, 1u);
  EXPECT_EQ(s.refused_workers("job-a"), std::vector<std::string>{"w3"});
  EXPECT_EQ(s.next_seq(), 10u);
}

TEST_P(StoreTest, WorkersBlobTenantsAndLeases) {
  store().write(std::vector<StoreWrite>{
      store::InsertWorker{{"w1", "t:aaa", "b1", ""}}, store::InsertWorker{{"w2", "t:bbb", "", ""}},
      store::InsertWorker{{"w3", "t:aaa", "b1", ""}}, store::RefuseWorker{"w2", "outvoted"},
      store::DeleteWorker{"w3"}, store::AddBlobTenant{"shot1", "d1"},
      store::AddBlobTenant{"shot1", "d1"}});
  store().write(std::vector<StoreWrite>{
      store::InsertLease{{"L1", "j1", 1, 0, 0, "w1"}},
      store::InsertLease{{"L2", "j1", 2, 0, 0, "w1"}},
      store::InsertLease{{"L3", "j2", 1, 0, 0, "w2"}},
      store::InsertLease{{"L4", "j1", 1, 1, 0, "w2"}},
      store::InsertLease{{"L1", "j1", 1, 0, 3, "w1"}}});  // the same id again: replaced, last
  JobStore& s = reopened();
  std::vector<StoredWorker> workers = s.workers();
  ASSERT_EQ(workers.size(), 2u);
  std::sort(workers.begin(), workers.end(),
            [](const StoredWorker& a, const StoredWorker& b) { return a.id < b.id; });
  EXPECT_EQ(workers[0].principal, "t:aaa");
  EXPECT_EQ(workers[0].build_id, "b1");
  EXPECT_EQ(workers[1].refused, "outvoted");
  EXPECT_TRUE(s.blob_tenant("shot1", "d1"));
  EXPECT_FALSE(s.blob_tenant("shot2", "d1"));
  auto ids = [&](const std::string& job) {
    std::vector<std::string> out;
    for (const StoredLease& l : s.leases(job)) out.push_back(l.lease_id);
    return out;
  };
  EXPECT_EQ(ids("j1"), (std::vector<std::string>{"L2", "L4", "L1"}));
  EXPECT_EQ(s.leases("j1").back().tile, 3u);
  s.write(store::DeleteLeases{"j1", 1u});
  EXPECT_EQ(ids("j1"), std::vector<std::string>{"L2"});
  s.write(store::DeleteLeases{"j1", std::nullopt});
  EXPECT_TRUE(ids("j1").empty());
  EXPECT_EQ(ids("j2"), std::vector<std::string>{"L3"});
}

// A batch is applied whole or not at all: one that inserts a job id already stored changes
// nothing, not even the writes before it in the batch.
TEST_P(StoreTest, ABatchIsAllOrNothing) {
  store().write(store::InsertJob{{"job-a", 1, spec_named("a"), 1, "", 0, 0, "", ""}});
  EXPECT_THROW(store().write(std::vector<StoreWrite>{
                   store::SetState{"job-a", 4, "failed"},
                   store::TaskEvent{"job-a", 0, 0, 0, "w", TaskEventKind::Done, ""},
                   store::InsertJob{{"job-a", 2, spec_named("again"), 1, "", 0, 0, "", ""}}}),
               StoreError);
  JobStore& s = reopened();
  ASSERT_EQ(s.jobs().size(), 1u);
  EXPECT_EQ(s.jobs()[0].state, 1);
  EXPECT_EQ(s.tasks_done("job-a"), 0u);
  s.write(std::vector<StoreWrite>{});  // nothing to do
}

INSTANTIATE_TEST_SUITE_P(
    Stores, StoreTest,
    ::testing::Values(StoreKind{"sqlite",
                                [](const std::string& dir) -> std::shared_ptr<JobStore> {
                                  return open_sqlite_store(dir + "/jobs.sqlite");
                                },
                                true},
                      StoreKind{"memory",
                                [](const std::string&) -> std::shared_ptr<JobStore> {
                                  return memory_store();
                                },
                                false}),
    [](const ::testing::TestParamInfo<StoreKind>& info) { return info.param.name; });

TEST(SqliteJobStore, UnwritablePathThrowsNamingIt) {
  std::string file = test::make_temp_dir("jobstore-bad") + "/regular-file";
  test::write_text(file, "not a directory");
  std::string path = file + "/jobs.db";
  try {
    open_sqlite_store(path);
    ADD_FAILURE() << "opening " << path << " did not throw";
  } catch (const StoreError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
}

// A database an earlier build wrote (its spec column holds protobuf wire bytes) reads the same.
TEST(SqliteJobStore, RowsOfEarlierBuildsRead) {
  std::string path = test::make_temp_dir("jobstore-legacy") + "/jobs.sqlite";
  { open_sqlite_store(path); }  // the schema
  JobSpec spec = spec_named("legacy");
  std::string bytes = encode_job_spec(spec);
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db,
                               "INSERT INTO jobs (id, seq, spec, state, error, submitted) VALUES "
                               "('j000001', 1, ?, 2, '', 1700000000)",
                               -1, &st, nullptr),
            SQLITE_OK);
  sqlite3_bind_blob(st, 1, bytes.data(), int(bytes.size()), SQLITE_TRANSIENT);
  EXPECT_EQ(sqlite3_step(st), SQLITE_DONE);
  sqlite3_finalize(st);
  sqlite3_close(db);
  std::vector<StoredJob> jobs = open_sqlite_store(path)->jobs();
  ASSERT_EQ(jobs.size(), 1u);
  ASSERT_TRUE(jobs[0].spec);
  EXPECT_EQ(*jobs[0].spec, spec);
}

// The codec: JSON of its own, and the protobuf wire bytes of earlier builds decoded by its own
// reader, for specs of every field, set and unset, over a thousand random draws.
TEST(SpecCodec, RoundTripsAndReadsTheWireBytesOfEarlierBuilds) {
  std::mt19937_64 rng(43);
  // UTF-8 text (protobuf refuses anything else), of whole characters: ASCII, escapes JSON must
  // write, NUL, and two- and four-byte characters.
  const std::vector<std::string> alphabet = {"a",  "b",  "X",  "0",  " ",
                                             "-",  "_",  ".",  "/",  "#",
                                             "\n", "\t", "\"", "\\", std::string(1, '\0'),
                                             "é",  "🎬"};
  auto text = [&](size_t n) {
    std::string s;
    for (size_t i = 0; i < n; ++i) s += alphabet[rng() % alphabet.size()];
    return s;
  };
  for (int i = 0; i < 1000; ++i) {
    JobSpec s;
    s.name = text(rng() % 20);
    s.scene_path = text(rng() % 30);
    for (size_t k = 0, n = rng() % 4; k < n; ++k) s.files.push_back({text(10), text(64)});
    s.frames = text(rng() % 8);
    SceneOverrides& o = s.overrides;
    if (rng() % 2) o.spp = rng();
    if (rng() % 2) o.passes = uint32_t(rng());
    if (rng() % 2) o.integrator = text(5);
    if (rng() % 2) o.seed = rng();
    if (rng() % 2) o.width = int(rng() % 16384);
    if (rng() % 2) o.height = int(rng() % 16384);
    if (rng() % 2) o.max_depth = int(int32_t(rng()));
    if (rng() % 2) o.filter = text(6);
    if (rng() % 2) o.noise_target = double(rng() % 100000) / 997.0;
    if (rng() % 2) o.sampler = text(6);
    if (rng() % 2) o.aovs = text(6);
    if (rng() % 2) o.light_selection = text(4);
    s.priority = int(int32_t(rng()));
    s.tile_size = uint32_t(rng());
    s.build_id = text(rng() % 12);
    s.request_id = text(rng() % 12);
    std::optional<JobSpec> json = decode_spec(encode_spec(s));
    ASSERT_TRUE(json) << encode_spec(s);
    EXPECT_EQ(*json, s) << encode_spec(s);
    std::optional<JobSpec> legacy = decode_spec(encode_job_spec(s));
    ASSERT_TRUE(legacy);
    EXPECT_EQ(*legacy, s) << i;
  }
  EXPECT_FALSE(decode_spec("{not json"));
  EXPECT_FALSE(decode_spec("{\"v\": 2}")) << "a later layout is not guessed at";
  EXPECT_FALSE(decode_spec("\x0a\x7f"s)) << "a length past the end";
  EXPECT_FALSE(decode_spec("\x0b"s)) << "a group";
}

}  // namespace
}  // namespace rf
