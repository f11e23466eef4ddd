// The coordinator's core (coordinator/core.h) driven directly, without processes or sockets: a
// temporary state directory, an explicit clock, and task results made up as a worker would send
// them. Completion after a restart, late and duplicate results, failure counting, the progress
// report, and the codes of refused requests.
#include "coordinator/core.h"
#include "coordinator/versions.h"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "engine/buffer_file.h"
#include "engine/build_info.h"
#include "engine/digest.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "farm/tags.h"
#include "tests/support/test_support.h"

namespace rf {

// Readable failure messages.
void PrintTo(const TaskRef& t, std::ostream* os) { *os << task_id_text(t); }
void PrintTo(JobState s, std::ostream* os) { *os << job_state_name(s); }
void PrintTo(ErrorCode c, std::ostream* os) { *os << "ErrorCode " << int(c); }

namespace {

namespace fs = std::filesystem;

const std::string kScene = "scenes/cornell-box/scene.json";
constexpr int kSamplesPerPass = 4;

// A coordinator on a temporary state directory with a clock the test sets, and a memory job
// store that outlives its restarts (SQLite on the state directory for the tests of the database
// itself). Jobs render the Cornell box at 16x16 in 8x8 tiles: 4 tiles per pass.
enum class Store { Memory, Sqlite };

class CoreBench {
 public:
  explicit CoreBench(const std::string& tag, Store kind = Store::Memory)
      : state_(test::make_temp_dir(tag) + "/state"),
        store_(kind == Store::Memory ? memory_store() : nullptr) {
    start("A");
  }

  // Starts the coordinator (again) on the same state directory, as a restarted process would.
  void start(const std::string& instance) {
    core_.reset();
    CoreOptions o;
    o.state_dir = state_;
    o.scene_checker = [this](const std::string& dir, const JobSpec& spec) {
      ++scene_checks;
      return in_process_scene_checker()(dir, spec);
    };
    o.store = store_;
    o.lease_seconds = 10;
    o.instance = instance;
    o.clock = [this] { return now; };
    o.limits = limits;
    o.verify_fraction = verify_fraction;
    o.keep_finished_seconds = keep_finished;
    o.blob_grace_seconds = blob_grace;
    core_ = std::make_unique<Coordinator>(o);
  }

  Coordinator& core() { return *core_; }

  // The id the coordinator issued to the worker called `name` in this test (registered on first
  // use; registrations are stored, so they outlive a restart).
  std::string worker(const std::string& name, const Caller& caller = {}) {
    auto it = workers_.find(name);
    if (it != workers_.end()) return it->second;
    return workers_[name] =
               core_->register_worker({name, 1, build_id(), cpu_isa()}, caller).worker_id;
  }

  // Uploads the scene's bundle and submits a job of `passes` passes of frame 1.
  std::string submit(uint32_t passes, const Caller& caller = {}, const std::string& pin = "",
                     const std::string& request_id = "") {
    std::string scene = test::source_dir() + "/" + kScene;
    JobSpec spec;
    spec.name = "cornell";
    spec.scene_path = "scene.json";
    spec.files = bundle_of_scene(scene);
    for (const BundleEntry& f : spec.files)
      core_->put_blob(read_file_bytes((fs::path(scene).parent_path() / f.path).string()), caller);
    spec.frames = frames;
    spec.overrides.width = 16;
    spec.overrides.height = 16;
    spec.overrides.passes = passes;
    spec.overrides.spp = kSamplesPerPass * passes;
    spec.tile_size = 8;
    spec.build_id = pin;
    spec.request_id = request_id;
    spec.required_tags = required_tags;
    return core_->submit(spec, caller);
  }

  TaskAssignment lease(const std::string& worker = "w") {
    LeaseResult l = core_->lease(this->worker(worker));
    EXPECT_TRUE(l.task) << worker << " got no task";
    return l.task.value_or(TaskAssignment{});
  }

  // The task's result as a worker would send it: one pass of its tile, every sample `value`.
  SampleBuffer result_buffer(const TaskAssignment& a, float value) {
    SampleBuffer b(header(a), a.rect, false);
    for (int y = a.rect.y0; y < a.rect.y1(); ++y)
      for (int x = a.rect.x0; x < a.rect.x1(); ++x)
        for (int s = 0; s < kSamplesPerPass; ++s) b.add_sample(x, y, RGB(value));
    b.finish_pass();
    return b;
  }
  std::string result(const TaskAssignment& a, float value) {
    return encode_buffer(result_buffer(a, value));
  }
  const std::string& state_dir() const { return state_; }
  JobStore& store() { return *store_; }  // the memory store (Store::Memory)
  void stop() { core_.reset(); }

  bool complete(const TaskAssignment& a, float value, const std::string& worker = "w") {
    return core_->complete({this->worker(worker), a.lease_id, a.task, result(a, value)});
  }

  SampleBuffer image(const std::string& job, FrameNumber frame = 1) {
    return decode_buffer(core_->fetch(job, frame).buffer, "fetched frame");
  }

  double now = 0;
  std::string frames = "1";                // of the jobs submit() makes
  std::vector<std::string> required_tags;  // and the worker tags they need
  int scene_checks = 0;  // calls of the scene checker, over every start
  JobLimits limits;  // for the next start()
  double verify_fraction = 0;
  double keep_finished = 7 * 86400.0, blob_grace = 3600;  // retention, for the next start()
  std::string scene_file;  // the scene results are rendered from ("": the submitted one)

  // A copy of the submitted scene with `from` replaced by `to` in its scene file, its bundle
  // uploaded: a requeue's new scene version.
  SceneVersion changed_scene(const std::string& tag, const std::string& from,
                             const std::string& to) {
    const std::string dir = test::make_temp_dir(tag);
    fs::copy(fs::path(test::source_dir() + "/" + kScene).parent_path(), dir,
             fs::copy_options::recursive);
    std::string text = read_file_bytes(dir + "/scene.json");
    EXPECT_NE(text.find(from), std::string::npos) << from;
    text.replace(text.find(from), from.size(), to);
    test::write_text(dir + "/scene.json", text);
    SceneVersion v{"scene.json", bundle_of_scene(dir + "/scene.json"), ""};
    for (const BundleEntry& f : v.files) core_->put_blob(read_file_bytes(dir + "/" + f.path));
    return v;
  }

 private:
  // The header a worker's renderer puts on the task's buffer (the engine's calls in one place).
  BufferHeader header(const TaskAssignment& a) {
    Scene scene = load_scene(scene_file.empty() ? test::source_dir() + "/" + kScene : scene_file,
                             a.overrides);
    return frame_header(scene, a.task.frame, PassSet::range(a.task.pass, a.task.pass + 1));
  }

  std::string state_;
  std::shared_ptr<JobStore> store_;  // empty: SQLite on the state directory
  std::unique_ptr<Coordinator> core_;
  std::map<std::string, std::string> workers_;
};

// The message a call is refused with; "" when it is not refused.
template <class F>
std::string refusal_message(F&& f) {
  try {
    f();
  } catch (const CoordinatorError& e) {
    return e.what();
  }
  return "";
}

// The code a call is refused with; nothing when it is not refused.
template <class F>
std::optional<ErrorCode> refusal(F&& f) {
  try {
    f();
  } catch (const CoordinatorError& e) {
    return e.code;
  }
  return std::nullopt;
}

// The result of a lease issued before a restart arrives after it: accepted by its task, once.
// A task completed before the restart is not leased again; nothing is lost or counted twice.
TEST(CoordinatorCore, ResultOfALeaseFromBeforeARestartIsAcceptedOnce) {
  CoreBench bench("core-restart");
  std::string job = bench.submit(2);
  TaskAssignment done = bench.lease(), late = bench.lease();
  EXPECT_TRUE(bench.complete(done, 1.0f));
  bench.start("B");  // the coordinator restarts; `late` was leased by the old one
  EXPECT_EQ(bench.core().status(job).frames[0].progress.passes_merged, 0u);
  EXPECT_TRUE(bench.complete(late, 1.0f));
  EXPECT_FALSE(bench.complete(late, 1.0f)) << "the same result again";
  std::set<TaskRef> rest;
  while (std::optional<TaskAssignment> a = bench.core().lease(bench.worker("w")).task) {
    EXPECT_EQ(a->lease_id.rfind("B-L", 0), 0u) << a->lease_id;
    EXPECT_NE(a->task, done.task);
    EXPECT_NE(a->task, late.task);
    rest.insert(a->task);
    EXPECT_TRUE(bench.complete(*a, 1.0f));
  }
  EXPECT_EQ(rest.size(), 6u) << "8 tasks, 2 of them completed";
  JobStatus s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Completed);
  EXPECT_EQ(s.frames[0].progress.passes_merged, 2u);
  EXPECT_DOUBLE_EQ(s.frames[0].progress.spp, 2.0 * kSamplesPerPass);
}

// A lease expires, its task goes to another worker, and the first worker's result arrives late:
// it is merged (results are deterministic), and the second lease ends.
TEST(CoordinatorCore, LateResultOfAnExpiredLeaseIsMergedAndEndsTheNewerLease) {
  CoreBench bench("core-late");
  std::string job = bench.submit(1);
  TaskAssignment slow = bench.lease("slow");
  bench.now = 5;
  EXPECT_EQ(bench.core().renew(bench.worker("slow"), slow.lease_id), 10u);  // renewed until 15
  bench.now = 16;
  TaskAssignment fast = bench.lease("fast");
  ASSERT_EQ(fast.task, slow.task) << "the expired task is handed out again first";
  EXPECT_EQ(refusal([&] { bench.core().renew(bench.worker("slow"), slow.lease_id); }),
            ErrorCode::FailedPrecondition);
  bench.now = 17;
  EXPECT_TRUE(bench.complete(slow, 2.0f, "slow"));
  EXPECT_EQ(refusal([&] { bench.core().renew(bench.worker("fast"), fast.lease_id); }),
            ErrorCode::FailedPrecondition);
  EXPECT_FALSE(bench.complete(fast, 5.0f, "fast"));
  for (int i = 0; i < 3; ++i) EXPECT_TRUE(bench.complete(bench.lease(), 2.0f));
  SampleBuffer frame = bench.image(job);
  EXPECT_EQ(frame.estimate(slow.rect.x0, slow.rect.y0)[0], 2.0f) << "the late result is merged";
}

// A second result for a task is answered not-accepted and changes nothing: neither while its
// pass is still being assembled, nor after the pass was merged.
TEST(CoordinatorCore, DuplicateCompletionIsNotAcceptedAndLeavesTheImageUnchanged) {
  CoreBench bench("core-duplicate");
  std::string job = bench.submit(2);
  std::vector<TaskAssignment> pass0, pass1;
  for (int i = 0; i < 4; ++i) pass0.push_back(bench.lease());
  for (int i = 0; i < 4; ++i) pass1.push_back(bench.lease());
  for (const TaskAssignment& a : pass0) EXPECT_TRUE(bench.complete(a, 1.0f));
  std::string merged = bench.core().fetch(job, 1).buffer;
  EXPECT_FALSE(bench.complete(pass0[0], 9.0f)) << "pass 0 is merged already";
  EXPECT_EQ(bench.core().fetch(job, 1).buffer, merged);

  EXPECT_TRUE(bench.complete(pass1[0], 3.0f));
  EXPECT_FALSE(bench.complete(pass1[0], 9.0f)) << "its pass is still being assembled";
  for (size_t i = 1; i < 4; ++i) EXPECT_TRUE(bench.complete(pass1[i], 3.0f));
  SampleBuffer frame = bench.image(job);
  EXPECT_EQ(frame.header.passes, PassSet::range(0, 2));
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) ASSERT_EQ(frame.estimate(x, y)[0], 2.0f) << x << "," << y;
  EXPECT_DOUBLE_EQ(bench.core().status(job).frames[0].progress.spp, 2.0 * kSamplesPerPass);
}

// A worker that failed max_failures (3) tasks of a job gets no more of them; the others still do.
TEST(CoordinatorCore, AWorkerThatFailsRepeatedlyGetsNoMoreTasksOfTheJob) {
  CoreBench bench("core-bad-worker");
  std::string job = bench.submit(2);
  std::set<TaskRef> failed;
  for (int i = 0; i < 3; ++i) {
    TaskAssignment a = bench.lease("bad");
    EXPECT_TRUE(failed.insert(a.task).second) << "a worker does not get back a task it failed";
    bench.core().fail({bench.worker("bad"), a.lease_id, "driver crash", false});
  }
  EXPECT_FALSE(bench.core().lease(bench.worker("bad")).task);
  EXPECT_EQ(bench.core().status(job).state, JobState::Running) << "each task failed once";
  TaskAssignment good = bench.lease("good");
  EXPECT_TRUE(failed.count(good.task)) << "a failed task is queued again";
}

// A paused job leases nothing, its lease in flight still merges, and its waiting tasks leave the
// autoscalers' queue (rayfarm_tasks_queued) for rayfarm_tasks_paused; resumed, it leases again.
// Pause is idempotent and refused once the job ended.
TEST(CoordinatorCore, APausedJobLeasesNothingAndLeavesTheQueueMetric) {
  CoreBench bench("core-pause");
  std::string job = bench.submit(2);  // 2 passes of 4 tiles
  TaskAssignment out = bench.lease();
  bench.core().set_paused(job, true);
  bench.core().set_paused(job, true);
  EXPECT_FALSE(bench.core().lease(bench.worker("w")).task);
  CoordinatorMetrics m = bench.core().metrics();
  EXPECT_EQ(m.tasks_queued, 0u);
  EXPECT_EQ(m.tasks_paused, 7u);
  EXPECT_EQ(m.tasks_leased, 1u);
  EXPECT_TRUE(bench.complete(out, 0.5f)) << "a lease in flight merges";
  EXPECT_TRUE(bench.core().status(job).paused);
  bench.core().set_paused(job, false);
  m = bench.core().metrics();
  EXPECT_EQ(m.tasks_queued, 7u);
  EXPECT_EQ(m.tasks_paused, 0u);
  for (int i = 0; i < 7; ++i) EXPECT_TRUE(bench.complete(bench.lease(), 0.5f));
  EXPECT_EQ(bench.core().status(job).state, JobState::Completed);
  EXPECT_EQ(refusal([&] { bench.core().set_paused(job, true); }), ErrorCode::FailedPrecondition);
  EXPECT_EQ(refusal([&] { bench.core().set_priority(job, 3); }), ErrorCode::FailedPrecondition);
}

// `workers`: each registered worker with what it registered, its live leases' tasks, its
// failures in jobs not ended, and how long since it called; another tenant sees the tasks of
// jobs not its own hidden, and no principals.
TEST(CoordinatorCore, WorkersListTheirTasksFailuresAndLastContact) {
  CoreBench bench("core-workers");
  const Caller shot1{"alice", "shot1", false}, shot2{"bob", "shot2", false};
  std::string job = bench.submit(2, shot1);
  TaskAssignment a = bench.lease("busy");
  TaskAssignment b = bench.lease("flaky");
  bench.core().fail({bench.worker("flaky"), b.lease_id, "out of memory", false});
  bench.now += 5;
  bench.core().renew(bench.worker("busy"), a.lease_id);
  bench.now += 2;
  std::map<std::string, WorkerStatus> by_host;
  for (const WorkerStatus& w : bench.core().workers()) by_host[w.info.hostname] = w;
  ASSERT_EQ(by_host.size(), 2u);
  EXPECT_EQ(by_host["busy"].tasks, std::vector<std::string>{task_id_text(a.task)});
  EXPECT_EQ(by_host["busy"].failures, 0);
  EXPECT_DOUBLE_EQ(by_host["busy"].seconds_since_contact, 2);
  EXPECT_EQ(by_host["busy"].principal, "local");
  EXPECT_EQ(by_host["busy"].info.cores, 1u);
  EXPECT_TRUE(by_host["flaky"].tasks.empty());
  EXPECT_EQ(by_host["flaky"].failures, 1);
  EXPECT_DOUBLE_EQ(by_host["flaky"].seconds_since_contact, 7);
  for (const WorkerStatus& w : bench.core().workers(shot1))
    if (w.info.hostname == "busy") EXPECT_EQ(w.tasks[0], task_id_text(a.task));
  for (const WorkerStatus& w : bench.core().workers(shot2)) {
    EXPECT_TRUE(w.principal.empty());
    if (w.info.hostname == "busy") EXPECT_EQ(w.tasks[0], "(another tenant's task)");
  }
  bench.core().cancel(job, shot1);
  for (const WorkerStatus& w : bench.core().workers()) {
    EXPECT_TRUE(w.tasks.empty()) << w.worker_id;
    EXPECT_EQ(w.failures, 0) << "failures count in jobs not ended";
  }
  // Pages (the monitor's): in id order, `more` while workers follow.
  bench.worker("third");  // registers it
  std::vector<WorkerStatus> all = bench.core().workers();
  ASSERT_EQ(all.size(), 3u);
  bool more = false;
  std::vector<WorkerStatus> first = bench.core().workers({}, 2, "", &more);
  ASSERT_EQ(first.size(), 2u);
  EXPECT_TRUE(more);
  EXPECT_EQ(first[0].worker_id, all[0].worker_id);
  std::vector<WorkerStatus> rest = bench.core().workers({}, 2, first[1].worker_id, &more);
  ASSERT_EQ(rest.size(), 1u);
  EXPECT_FALSE(more);
  EXPECT_EQ(rest[0].worker_id, all[2].worker_id);
}

// A task failing on max_failures (3) different workers fails its job with their messages, also
// when the failures straddle a restart.
TEST(CoordinatorCore, ATaskFailingOnThreeWorkersFailsTheJob) {
  CoreBench bench("core-failing-task");
  std::string job = bench.submit(1);
  auto fail_on = [&](const std::string& worker) {
    TaskAssignment a = bench.lease(worker);
    EXPECT_EQ(a.task.tile, 0u) << "the failed task comes first again";
    bench.core().fail({bench.worker(worker), a.lease_id, "out of memory on " + worker, false});
  };
  fail_on("w1");
  fail_on("w2");
  bench.start("B");
  EXPECT_EQ(bench.core().status(job).state, JobState::Running);
  fail_on("w3");
  JobStatus s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Failed);
  for (const char* w : {"w1", "w2", "w3"})
    EXPECT_NE(s.error.find(std::string("out of memory on ") + w), std::string::npos) << s.error;
  EXPECT_FALSE(bench.core().lease(bench.worker("w4")).task) << "a failed job hands out nothing";
}

double unix_now() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// A requeue stopped before its store row (the new run's folder and versions.json written, the
// process gone): the store's record wins at the start: the old run's checkpoint serves the frame,
// the new run's folder is removed and the folder's record is rewritten to agree.
TEST(CoordinatorCore, ARequeueStoppedBeforeItsRowLeavesTheOldRunWhole) {
  CoreBench bench("core-requeue-crash");
  const std::string job = bench.submit(1);
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(bench.complete(bench.lease("w"), 1.0f));
  ASSERT_EQ(bench.core().status(job).state, JobState::Completed);
  bench.stop();
  const std::string dir = bench.state_dir() + "/jobs/" + job + "/";
  fs::create_directories(dir + "frame-1.r1");
  JobVersions ahead;
  ahead.frames[1] = FrameRun{0, 1};
  test::write_text(dir + "versions.json", encode_versions(ahead) + "\n");
  bench.start("B");
  JobStatus s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Completed);
  EXPECT_EQ(s.frames[0].run, 0u);
  EXPECT_EQ(s.frames[0].progress.passes_merged, 1u);
  EXPECT_EQ(bench.image(job, 1).header.passes.count(), 1u);
  EXPECT_FALSE(fs::exists(dir + "frame-1.r1"));
  EXPECT_FALSE(fs::exists(dir + "versions.json")) << "the store records no requeue";
}

// A job stored without a CPU kind pin (by a build before it) whose checkpoints hold merged passes
// takes their kind as its pin at the restart, so a worker of another kind gets none of its tasks.
TEST(CoordinatorCore, AJobStoredWithoutAKindPinTakesItsCheckpointsKind) {
  CoreBench bench("core-kind-restore");
  const std::string job = bench.submit(2);
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(bench.complete(bench.lease("w"), 1.0f));  // pass 0
  ASSERT_EQ(bench.core().status(job).cpu_kind, cpu_isa());
  bench.stop();
  bench.store().write(store::SetBuild{job, "", ""});  // as an earlier build stored it
  bench.start("B");
  EXPECT_EQ(bench.core().status(job).cpu_kind, cpu_isa());
  WorkerInfo other{"other", 1, build_id(), "x86_64-other-kind"};
  const std::string w = bench.core().register_worker(other).worker_id;
  EXPECT_FALSE(bench.core().lease(w).task) << "a worker of another kind gets none of its tasks";
  EXPECT_TRUE(bench.core().lease(bench.worker("w")).task);
}

// The bytes of the files under `dir` (each file once: bundles are hard links of blobs).
uint64_t disk_bytes(const std::string& dir) {
  std::set<std::pair<dev_t, ino_t>> seen;
  uint64_t total = 0;
  std::error_code ec;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    struct stat st {};
    if (::lstat(it->path().c_str(), &st) == 0 && S_ISREG(st.st_mode) &&
        seen.insert({st.st_dev, st.st_ino}).second)
      total += uint64_t(st.st_size);
  }
  return total;
}

// Retention: finished jobs expire once --keep-finished has passed since they ended (a queued one
// never does), their folders go and their ids answer "expired" to their tenant ("no job" to
// others); blobs no job references go once their grace period passed since they were last
// stored or asked for. The job and blob folders are back to their bytes before the jobs, across
// a restart in the middle of a cleanup (a job's folder renamed, the point of no return, and the
// process gone before the rest).
TEST(CoordinatorCore, RetentionExpiresFinishedJobsAndCollectsBlobsNoJobUses) {
  CoreBench bench("core-retention");
  bench.keep_finished = 100;
  bench.blob_grace = 50;
  bench.start("A");
  const std::string jobs_dir = bench.state_dir() + "/jobs",
                    blobs_dir = bench.state_dir() + "/blobs";
  const uint64_t jobs0 = disk_bytes(jobs_dir), blobs0 = disk_bytes(blobs_dir);
  const Caller shot1{"alice", "shot1", false}, shot2{"bob", "shot2", false};
  const std::string done = bench.submit(1, shot1);
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(bench.complete(bench.lease("w"), 1.0f));
  ASSERT_EQ(bench.core().status(done).state, JobState::Completed);
  const std::string cancelled = bench.submit(1, shot1);
  bench.core().cancel(cancelled);
  const std::string interrupted = bench.submit(1, shot1);
  bench.core().cancel(interrupted);
  const std::string queued = bench.submit(1, shot1);
  EXPECT_GT(disk_bytes(jobs_dir), jobs0);
  EXPECT_GT(disk_bytes(blobs_dir), blobs0);

  const double t0 = unix_now();
  Coordinator::Collected c = bench.core().collect(t0 + 50);
  EXPECT_EQ(c.jobs_expired, 0u) << "kept for 100 s";
  // The restart in the middle of a cleanup: one job's folder renamed with its expiry time, as
  // remove_job leaves it at its point of no return, and the process stopped.
  bench.stop();
  fs::rename(jobs_dir + "/" + interrupted, jobs_dir + "/.deleted-" + interrupted);
  test::write_text(jobs_dir + "/.deleted-" + interrupted + "/expired",
                   std::to_string(int64_t(t0 + 60)));
  bench.start("B");
  EXPECT_FALSE(fs::exists(jobs_dir + "/.deleted-" + interrupted)) << "finished at the start";
  std::string why = refusal_message([&] { bench.core().status(interrupted, shot1); });
  EXPECT_NE(why.find("expired at"), std::string::npos) << why;
  // The restored ended jobs' frames were read back from their checkpoints: the next pass drops
  // those accumulators, and a later pass visits them no more.
  c = bench.core().collect(t0 + 55);
  EXPECT_EQ(c.jobs_expired, 0u);
  EXPECT_GE(c.accumulators_released, 1u);
  EXPECT_EQ(bench.core().collect(t0 + 56).accumulators_released, 0u);

  c = bench.core().collect(t0 + 101);
  EXPECT_EQ(c.jobs_expired, 2u);
  EXPECT_EQ(bench.core().metrics().counters.jobs_expired, 2u);
  EXPECT_GT(bench.core().metrics().blob_store_bytes, 0u);
  EXPECT_EQ(c.blobs_removed, 0u) << "the queued job uses them";
  for (const std::string& id : {done, cancelled}) {
    EXPECT_FALSE(fs::exists(jobs_dir + "/" + id));
    why = refusal_message([&] { bench.core().status(id, shot1); });
    EXPECT_NE(why.find("job " + id + " expired at"), std::string::npos) << why;
    EXPECT_NE(why.find("--keep-finished"), std::string::npos) << why;
    EXPECT_EQ(refusal([&] { bench.core().fetch(id, 1, shot1); }), ErrorCode::NotFound);
    why = refusal_message([&] { bench.core().status(id, shot2); });
    EXPECT_EQ(why, "no job '" + id + "'") << "another tenant learns nothing";
  }
  EXPECT_EQ(bench.core().status(queued).state, JobState::Queued) << "only finished jobs expire";

  // The queued job deleted, its blobs are no job's: gone once their grace period passed.
  bench.core().delete_job(queued, true);
  const std::string fresh = bench.core().put_blob("a blob uploaded for a submit to come", shot1);
  c = bench.core().collect(unix_now() + 10);
  EXPECT_EQ(c.blobs_removed, 0u) << "within 50 s of their upload (and of a MissingBlobs)";
  EXPECT_TRUE(bench.core().missing_blobs({fresh}, shot1).empty());
  c = bench.core().collect(unix_now() + 51);
  EXPECT_GT(c.blobs_removed, 1u);
  EXPECT_EQ(bench.core().missing_blobs({fresh}, shot1), std::vector<std::string>{fresh});
  EXPECT_EQ(disk_bytes(jobs_dir), jobs0);
  EXPECT_EQ(disk_bytes(blobs_dir), blobs0);
  EXPECT_EQ(bench.core().metrics().blob_store_bytes, blobs0);
  // Jobs submitted after, and a restart, see none of it.
  bench.start("C");
  const std::string again = bench.submit(1, shot1);
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(bench.complete(bench.lease("w"), 1.0f));
  EXPECT_EQ(bench.core().status(again, shot1).state, JobState::Completed);
}

// `requeue`: frame 2 of a running job renders again from a new scene version; a lease of its old
// run in flight is answered not needed and counts against no one; frame 1 keeps its result. The
// completed job runs again for frame 1 (its own scene), the versions and runs survive a restart,
// and the replaced checkpoint folders go. A repeated request changes nothing; a scene that does
// not fit the job, a bad range and a frame the job lacks are refused.
TEST(CoordinatorCore, RequeueRendersFramesAgainFromANewSceneVersion) {
  CoreBench bench("core-requeue");
  bench.frames = "1-2";
  std::string job = bench.submit(1);  // 4 tasks per frame
  TaskAssignment in_flight;
  for (int i = 0; i < 8; ++i) {
    TaskAssignment a = bench.lease("w");
    if (a.task.frame == 2 && in_flight.lease_id.empty()) {
      in_flight = a;  // held across the requeue
      continue;
    }
    ASSERT_TRUE(bench.complete(a, 1.0f));
  }
  const std::string old_digest = bench.image(job, 1).header.scene_digest;
  SceneVersion blue =
      bench.changed_scene("core-requeue-blue", "[0.63, 0.065, 0.05]", "[0.05, 0.065, 0.63]");
  EXPECT_EQ(refusal([&] { bench.core().requeue(job, "", blue); }), ErrorCode::InvalidArgument);
  EXPECT_EQ(refusal([&] { bench.core().requeue(job, "9", blue); }), ErrorCode::InvalidArgument);
  EXPECT_EQ(refusal([&] { bench.core().requeue(job, "2-x", blue); }), ErrorCode::InvalidArgument);
  SceneVersion splatting =
      bench.changed_scene("core-requeue-light", "\"type\": \"path\"", "\"type\": \"light\"");
  std::string why = refusal_message([&] { bench.core().requeue(job, "2", splatting); });
  EXPECT_NE(why.find("differs from the job"), std::string::npos) << why;
  SceneVersion missing = blue;
  missing.files[0].sha256 = std::string(64, 'a');
  EXPECT_EQ(refusal([&] { bench.core().requeue(job, "2", missing); }), ErrorCode::InvalidArgument);

  bench.core().requeue(job, "2", blue, "request-1");
  JobStatus s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Running);
  EXPECT_EQ(s.frames[1].scene_version, 1u);
  EXPECT_EQ(s.frames[1].run, 1u);
  EXPECT_EQ(s.frames[1].progress.passes_merged, 0u);
  EXPECT_EQ(s.frames[0].progress.passes_merged, 1u) << "frame 1 keeps its result";
  EXPECT_FALSE(bench.complete(in_flight, 1.0f)) << "a result of the old run is not needed";
  EXPECT_EQ(bench.core().workers()[0].failures, 0) << "and counts against no one";
  bench.core().requeue(job, "2", blue, "request-1");  // a repeat: nothing changes
  EXPECT_EQ(bench.core().status(job).frames[1].run, 1u);
  bench.scene_file = bench.state_dir() + "/jobs/" + job + "/bundle-v1/scene.json";
  for (int i = 0; i < 4; ++i) {
    TaskAssignment a = bench.lease("w");
    ASSERT_EQ(a.task.frame, 2);
    EXPECT_EQ(a.files, blue.files);
    ASSERT_TRUE(bench.complete(a, 2.0f));
  }
  s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Completed);
  const std::string blue_digest = bench.image(job, 2).header.scene_digest;
  EXPECT_NE(blue_digest, old_digest);
  EXPECT_EQ(bench.image(job, 1).header.scene_digest, old_digest);

  // Completed -> Running: frame 1 again from its own scene; frame 2 keeps version 1.
  bench.core().requeue(job, "1", std::nullopt);
  s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Running);
  EXPECT_EQ(s.frames[0].scene_version, 0u);
  EXPECT_EQ(s.frames[0].run, 1u);
  EXPECT_TRUE(s.frames[1].progress.done);
  const std::string jobs = bench.state_dir() + "/jobs/" + job + "/";
  EXPECT_FALSE(fs::exists(jobs + "frame-1")) << "the replaced run's checkpoint is removed";
  EXPECT_FALSE(fs::exists(jobs + "frame-2"));
  EXPECT_TRUE(fs::exists(jobs + "frame-2.r1/prefix.rfb"));
  bench.start("B");
  s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Running);
  EXPECT_EQ(s.frames[0].run, 1u);
  EXPECT_EQ(s.frames[1].scene_version, 1u);
  EXPECT_TRUE(s.frames[1].progress.done);
  EXPECT_EQ(bench.image(job, 2).header.scene_digest, blue_digest);
  bench.scene_file = "";
  for (int i = 0; i < 4; ++i) {
    TaskAssignment a = bench.lease("w");
    ASSERT_EQ(a.task.frame, 1);
    ASSERT_TRUE(bench.complete(a, 3.0f));
  }
  EXPECT_EQ(bench.core().status(job).state, JobState::Completed);
  EXPECT_EQ(bench.image(job, 1).header.scene_digest, old_digest);
}

// `retry` of a failed job: the frames named run again (a worker it failed on gets its tasks), the
// other unfinished frames are held across a restart, and once the named frames are done the job
// fails again naming the held ones; a second retry renders them from the passes merged before,
// and the job completes. Refusals: a completed job, a frame it lacks, a bad range, all done.
TEST(CoordinatorCore, RetryRunsNamedFramesAgainHoldsTheRestAndKeepsMergedPasses) {
  CoreBench bench("core-retry");
  bench.frames = "1-3";
  std::string job = bench.submit(2);  // 8 tasks per frame
  for (int i = 0; i < 4; ++i) {       // pass 0 of frame 1
    TaskAssignment a = bench.lease("w");
    ASSERT_EQ(a.task.frame, 1);
    ASSERT_TRUE(bench.complete(a, 1.0f));
  }
  for (const char* w : {"w1", "w2", "w3"}) {
    TaskAssignment a = bench.lease(w);
    ASSERT_EQ(a.task.frame, 2);
    bench.core().fail({bench.worker(w), a.lease_id, std::string("crash on ") + w, false});
  }
  ASSERT_EQ(bench.core().status(job).state, JobState::Failed);
  EXPECT_EQ(refusal([&] { bench.core().retry(job, "9"); }), ErrorCode::InvalidArgument);
  EXPECT_EQ(refusal([&] { bench.core().retry(job, "2-x"); }), ErrorCode::InvalidArgument);

  bench.core().retry(job, "2");
  JobStatus s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Running);
  EXPECT_EQ(s.error, "");
  EXPECT_EQ(s.held, (std::vector<FrameNumber>{1, 3})) << "frame 1 has a pass left";
  EXPECT_NO_THROW(bench.core().retry(job, "2")) << "frame 2 runs already: nothing to do";
  bench.start("B");  // the retry and the held frames are stored
  s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Running);
  EXPECT_EQ(s.held, (std::vector<FrameNumber>{1, 3}));
  EXPECT_EQ(s.frames[0].progress.passes_merged, 1u);
  for (int i = 0; i < 8; ++i) {  // w1 failed frame 2 before: it renders it now, alone
    TaskAssignment a = bench.lease("w1");
    ASSERT_EQ(a.task.frame, 2);
    ASSERT_TRUE(bench.complete(a, 2.0f, "w1"));
  }
  s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Failed);
  EXPECT_NE(s.error.find("frames 1,3 were left out of a retry"), std::string::npos) << s.error;

  bench.core().retry(job, "");
  EXPECT_TRUE(bench.core().status(job).held.empty());
  int leased = 0;
  for (;;) {
    LeaseResult l = bench.core().lease(bench.worker("w2"));
    if (!l.task) break;
    EXPECT_NE(l.task->task.frame, 2);
    EXPECT_TRUE(l.task->task.frame == 3 || l.task->task.pass == 1) << "frame 1's pass 0 is in";
    ASSERT_TRUE(bench.complete(*l.task, 1.0f, "w2"));
    ++leased;
  }
  EXPECT_EQ(leased, 4 + 8);
  s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Completed);
  for (const FrameStatus& f : s.frames) EXPECT_EQ(f.progress.passes_merged, 2u);
  EXPECT_EQ(bench.image(job, 2).header.passes.count(), 2u);
  EXPECT_EQ(refusal([&] { bench.core().retry(job, ""); }), ErrorCode::FailedPrecondition);

  // A cancelled job runs again; a retry naming only done frames of an ended job is refused.
  bench.frames = "1-2";
  std::string c = bench.submit(1);
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(bench.complete(bench.lease("w"), 1.0f));  // frame 1
  bench.core().cancel(c);
  EXPECT_EQ(refusal([&] { bench.core().retry(c, "1"); }), ErrorCode::FailedPrecondition);
  bench.core().retry(c, "");
  for (int i = 0; i < 4; ++i) {
    TaskAssignment a = bench.lease("w");
    EXPECT_EQ(a.task.frame, 2);
    ASSERT_TRUE(bench.complete(a, 1.0f));
  }
  EXPECT_EQ(bench.core().status(c).state, JobState::Completed);
}

// `delete`: an ended job goes with its folder and rows (a restart does not bring it back) and its
// id is never given again; a running one only with force (its lease's result is then NotFound).
// A delete a crash interrupted after its folder was renamed is finished at the next start.
TEST(CoordinatorCore, DeleteRemovesAJobItsFolderAndRowsAndItsIdIsNotReused) {
  CoreBench bench("core-delete");
  const std::string a = bench.submit(1);
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(bench.complete(bench.lease("w"), 1.0f));
  ASSERT_EQ(bench.core().status(a).state, JobState::Completed);
  const std::string b = bench.submit(1);
  TaskAssignment held = bench.lease("w");
  EXPECT_EQ(refusal([&] { bench.core().delete_job(b, false); }), ErrorCode::FailedPrecondition);
  EXPECT_NE(refusal_message([&] { bench.core().delete_job(b, false); }).find("delete --force"),
            std::string::npos);
  const fs::path folder = fs::path(bench.state_dir()) / "jobs" / a;
  ASSERT_TRUE(fs::exists(folder));
  bench.core().delete_job(a, false);
  EXPECT_FALSE(fs::exists(folder));
  EXPECT_EQ(refusal([&] { bench.core().status(a); }), ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] { bench.core().fetch(a, 1); }), ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] { bench.core().delete_job(a, false); }), ErrorCode::NotFound);
  bench.core().delete_job(b, true);
  EXPECT_EQ(refusal([&] { bench.complete(held, 1.0f); }), ErrorCode::NotFound);
  EXPECT_FALSE(bench.core().lease(bench.worker("w")).task) << "nothing of b is left";
  EXPECT_TRUE(bench.core().list().empty());
  const std::string c = bench.submit(1);
  EXPECT_TRUE(c != a && c != b) << c;
  bench.start("B");
  ASSERT_EQ(bench.core().list().size(), 1u) << "a restart brings no deleted job back";
  EXPECT_EQ(bench.core().list()[0].job_id, c);
  // Interrupted after the rename (the point of no return): the next start finishes it.
  bench.core().cancel(c);
  bench.stop();
  fs::rename(fs::path(bench.state_dir()) / "jobs" / c,
             fs::path(bench.state_dir()) / "jobs" / (".deleted-" + c));
  bench.start("C");
  EXPECT_TRUE(bench.core().list().empty());
  EXPECT_FALSE(fs::exists(fs::path(bench.state_dir()) / "jobs" / (".deleted-" + c)));
  const std::string d = bench.submit(1);
  EXPECT_TRUE(d != a && d != b && d != c) << d;
}

// Tasks handed back by workers shutting down are queued again without counting as failures.
TEST(CoordinatorCore, HandedBackTasksAreNotFailures) {
  CoreBench bench("core-hand-back");
  std::string job = bench.submit(1);
  for (const char* w : {"w1", "w2", "w3", "w4", "w1", "w1", "w1"}) {
    TaskAssignment a = bench.lease(w);
    EXPECT_EQ(a.task.tile, 0u) << "the handed-back task is next, for any worker";
    bench.core().fail({bench.worker(w), a.lease_id, "worker shutting down", true});
  }
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(bench.complete(bench.lease("w1"), 1.0f, "w1"));
  EXPECT_EQ(bench.core().status(job).state, JobState::Completed);
}

// spp, relMSE and ETA per frame, from engine/progress.h's model. Every sample of pass p has
// radiance v_p = 1, 3, 2, ...: after 3 passes each pixel's mean is 2 and its batch-means
// variance of the mean s^2/n = 1/3, so relMSE = (1/3) / (2^2 + 0.01).
TEST(CoordinatorCore, ProgressReportsSppRelMseAndEta) {
  CoreBench bench("core-progress");
  std::string job = bench.submit(4);
  FrameProgress p = bench.core().status(job).frames[0].progress;
  EXPECT_EQ(p.passes_total, 4u);
  EXPECT_EQ(p.eta_seconds, -1.0) << "unknown before the first pass";
  bench.now = 100;  // the frame's first lease
  std::vector<TaskAssignment> tasks;
  for (int i = 0; i < 16; ++i) tasks.push_back(bench.lease());
  const float values[4] = {1.0f, 3.0f, 2.0f, 2.0f};
  for (int i = 0; i < 12; ++i) EXPECT_TRUE(bench.complete(tasks[i], values[tasks[i].task.pass]));
  bench.now = 130;  // 3 passes in 30 s: 10 s per pass, 1 pass to go
  p = bench.core().status(job).frames[0].progress;
  EXPECT_EQ(p.passes_merged, 3u);
  EXPECT_DOUBLE_EQ(p.spp, 3.0 * kSamplesPerPass);
  EXPECT_NEAR(p.rel_mse, (1.0 / 3.0) / 4.01, 1e-12);
  EXPECT_DOUBLE_EQ(p.eta_seconds, 10.0);
  EXPECT_FALSE(p.done);
  EXPECT_DOUBLE_EQ(bench.core().list()[0].frames[0].progress.eta_seconds, 10.0);
  FrameImage image = bench.core().fetch(job, 1);
  EXPECT_DOUBLE_EQ(image.status.progress.spp, 3.0 * kSamplesPerPass);
  for (int i = 12; i < 16; ++i) EXPECT_TRUE(bench.complete(tasks[i], values[tasks[i].task.pass]));
  p = bench.core().status(job).frames[0].progress;
  EXPECT_TRUE(p.done);
  EXPECT_EQ(p.eta_seconds, 0.0);
  EXPECT_DOUBLE_EQ(p.spp, 4.0 * kSamplesPerPass);
}

// Each refusal carries the code the gRPC service answers with (DESIGN.md "Status codes"), and
// a refused submit leaves no job behind.
TEST(CoordinatorCore, RefusalsCarryTheirCodes) {
  CoreBench bench("core-refusals");
  Coordinator& core = bench.core();
  EXPECT_EQ(refusal([&] { core.status("j999999"); }), ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] { core.missing_blobs({"not-hex"}); }), ErrorCode::InvalidArgument);
  EXPECT_EQ(refusal([&] { core.blob(std::string(64, 'a')); }), ErrorCode::NotFound);
  JobSpec missing;
  missing.scene_path = "scene.json";
  missing.files = {{"scene.json", std::string(64, 'a')}};
  EXPECT_EQ(refusal([&] { core.submit(missing); }), ErrorCode::InvalidArgument);
  EXPECT_TRUE(core.list().empty());
  std::string job = bench.submit(1);
  EXPECT_EQ(refusal([&] { core.fetch(job, 1); }), ErrorCode::FailedPrecondition) << "no pass yet";
  EXPECT_EQ(refusal([&] { core.fetch(job, 7); }), ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] { core.renew(bench.worker("w"), "no-such-lease"); }), ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] { core.lease(""); }), ErrorCode::InvalidArgument);
  TaskAssignment a = bench.lease();
  TaskAssignment wrong = a;
  wrong.rect.w = 4;  // a buffer that does not cover the task's tile
  EXPECT_EQ(refusal([&] {
              core.complete({bench.worker("w"), a.lease_id, a.task, bench.result(wrong, 1)});
            }),
            ErrorCode::InvalidArgument);
  EXPECT_EQ(refusal([&] {
              core.complete({bench.worker("w"), a.lease_id, a.task, "not a buffer"});
            }),
            ErrorCode::InvalidArgument);
  TaskRef unknown = a.task;
  unknown.tile = 99;
  EXPECT_EQ(refusal([&] {
              core.complete({bench.worker("w"), a.lease_id, unknown, bench.result(a, 1)});
            }),
            ErrorCode::NotFound);
  core.cancel(job);
  EXPECT_EQ(refusal([&] { core.cancel(job); }), std::nullopt) << "a second cancel succeeds";
  EXPECT_EQ(core.status(job).state, JobState::Cancelled);
  core.shut_down();
  EXPECT_EQ(refusal([&] { core.lease(bench.worker("w")); }), ErrorCode::Unavailable);
}

// Batched leases and uploads (docs/design.md "Batched leases"): a lease asks for up to 8 tasks
// and gets one until the job has merged kTasksBeforeBatching results (their time unknown), then
// 8 of the same job (these tasks take no measured time). Their results go up in one
// complete_batch: a flush of the results' files covers all of them, each is answered on its own
// (merged; a wrong buffer refused with its code; a second result of a task in the same batch not
// needed), and the merged image is what singly completed results give.
TEST(CoordinatorCore, ABatchOfResultsIsFlushedOnceAndEachIsAnsweredAlone) {
  CoreBench bench("core-batch");
  Coordinator& core = bench.core();
  std::string job = bench.submit(4);  // 4 tiles a pass, 16 tasks
  const std::string w = bench.worker("w");
  LeaseResult first = core.lease(w, {}, 8);
  ASSERT_TRUE(first.task);
  EXPECT_TRUE(first.more.empty()) << "no batch before the job's tasks were timed";
  EXPECT_TRUE(bench.complete(*first.task, 1.0f));
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(bench.complete(bench.lease(), 1.0f));
  LeaseResult batch = core.lease(w, {}, 8);
  ASSERT_TRUE(batch.task);
  ASSERT_EQ(batch.more.size(), 7u);
  std::vector<TaskAssignment> tasks{*batch.task};
  tasks.insert(tasks.end(), batch.more.begin(), batch.more.end());
  std::set<std::string> leases;
  for (const TaskAssignment& a : tasks) {
    EXPECT_EQ(a.task.job_id, job);
    leases.insert(a.lease_id);
  }
  EXPECT_EQ(leases.size(), 8u) << "each task under its own lease";
  std::vector<TaskResult> results;
  for (const TaskAssignment& a : tasks)
    results.push_back({w, a.lease_id, a.task, bench.result(a, 1.0f + float(a.task.pass))});
  TaskAssignment wrong = tasks[2];
  wrong.rect.w = 4;
  results[2].buffer = bench.result(wrong, 1.0f);  // refused: it does not cover its tile
  results.push_back(results[0]);                  // the same task again: not needed
  const uint64_t flushes = core.metrics().counters.result_flushes;
  std::vector<Coordinator::ResultOutcome> out = core.complete_batch(results);
  EXPECT_EQ(core.metrics().counters.result_flushes, flushes + 1) << "one flush for the batch";
  ASSERT_EQ(out.size(), 9u);
  for (size_t i = 0; i < 8; ++i) {
    if (i == 2) continue;
    EXPECT_TRUE(out[i].accepted) << i;
    EXPECT_FALSE(out[i].error) << i << ": " << out[i].error->what();
  }
  ASSERT_TRUE(out[2].error);
  EXPECT_EQ(out[2].error->code, ErrorCode::InvalidArgument);
  EXPECT_FALSE(out[2].accepted);
  EXPECT_FALSE(out[8].accepted);
  EXPECT_FALSE(out[8].error);
  // The refused task is leased again; the rest of the job one task at a time.
  for (int i = 0; i < 5; ++i) {
    TaskAssignment a = bench.lease();
    ASSERT_TRUE(bench.complete(a, 1.0f + float(a.task.pass)));
  }
  EXPECT_EQ(core.status(job).state, JobState::Completed);
  SampleBuffer image = bench.image(job);
  EXPECT_EQ(image.header.passes, PassSet::range(0, 4));
  for (int y = 0; y < 16; ++y)  // passes of 1, 2, 3 and 4
    for (int x = 0; x < 16; ++x) ASSERT_EQ(image.estimate(x, y)[0], 2.5f) << x << "," << y;
}

// Uploads, renewals and failures count only from the worker holding the lease, called by the
// identity that registered it. Another identity using the holder's worker id, another worker
// using its lease, invented worker or lease ids, and a lease sent with another task are refused;
// three invented workers failing the task do not fail the job; the holder's result is merged.
TEST(CoordinatorCore, OnlyTheLeaseHolderMayCompleteRenewOrFailItsTask) {
  CoreBench bench("core-lease-holder");
  std::string job = bench.submit(1);
  Coordinator& core = bench.core();
  const Caller alice{"t:alice", "", true}, mallory{"t:mallory", "", true};
  std::string a = bench.worker("a", alice), m = bench.worker("m", mallory);
  TaskAssignment task = core.lease(a, alice).task.value();
  std::string forged = bench.result(task, 1000.0f);
  EXPECT_EQ(refusal([&] {
              core.complete({a, task.lease_id, task.task, forged}, mallory);
            }),
            ErrorCode::PermissionDenied);
  EXPECT_EQ(refusal([&] {
              core.complete({m, task.lease_id, task.task, forged}, mallory);
            }),
            ErrorCode::PermissionDenied);
  EXPECT_EQ(refusal([&] {
              core.complete({"invented", task.lease_id, task.task, forged}, mallory);
            }),
            ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] {
              core.complete({m, "", task.task, forged}, mallory);
            }),
            ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] { core.check_upload(m, "A-L999", task.task, mallory); }),
            ErrorCode::NotFound);
  TaskRef other = task.task;
  other.tile = (other.tile + 1) % 4;
  EXPECT_EQ(refusal([&] {
              core.complete({a, task.lease_id, other, forged}, alice);
            }),
            ErrorCode::PermissionDenied);
  EXPECT_EQ(refusal([&] { core.renew(m, task.lease_id, mallory); }), ErrorCode::PermissionDenied);
  EXPECT_EQ(refusal([&] {
              core.fail({m, task.lease_id, "forged", false}, mallory);
            }),
            ErrorCode::PermissionDenied);
  for (int i = 0; i < 3; ++i)
    EXPECT_EQ(refusal([&] {
                core.fail({"fake-" + std::to_string(i), task.lease_id, "forged", false}, mallory);
              }),
              ErrorCode::NotFound);
  EXPECT_EQ(core.status(job).state, JobState::Running);
  EXPECT_EQ(core.renew(a, task.lease_id, alice), 10u);
  EXPECT_TRUE(core.complete({a, task.lease_id, task.task, bench.result(task, 1.0f)}, alice));
  while (std::optional<TaskAssignment> t = core.lease(a, alice).task)
    EXPECT_TRUE(core.complete({a, t->lease_id, t->task, bench.result(*t, 1.0f)}, alice));
  EXPECT_EQ(core.status(job).state, JobState::Completed);
  SampleBuffer frame = bench.image(job);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) ASSERT_EQ(frame.estimate(x, y)[0], 1.0f) << x << "," << y;
}

// A result that could not come from one honest pass of its task is refused before it is merged:
// a non-finite sum, a negative sum of squares, a pixel with one sample too many, an absurd
// core_seconds. Its lease ends and the task is queued again at once; the frame is then made of
// honest results alone.
TEST(CoordinatorCore, ResultsWithWrongCountsOrNonFiniteSumsAreRefused) {
  CoreBench bench("core-bad-results");
  std::string job = bench.submit(1);
  std::vector<std::function<void(SampleBuffer&)>> damage = {
      [](SampleBuffer& b) { b.sum[5] = std::nan(""); },
      [](SampleBuffer& b) { b.batch_sum[0] = INFINITY; },
      [](SampleBuffer& b) { b.sum_sq[2] = -1; },
      [](SampleBuffer& b) { b.count[7] += 1; },
      [](SampleBuffer& b) { b.header.core_seconds = 1e308; },
  };
  TaskRef first;
  for (size_t i = 0; i < damage.size(); ++i) {
    std::string name = "bad" + std::to_string(i);
    TaskAssignment a = bench.lease(name);
    if (i == 0) first = a.task;
    EXPECT_EQ(a.task, first) << "a refused task is queued again at once";
    SampleBuffer b = bench.result_buffer(a, 1.0f);
    damage[i](b);
    EXPECT_EQ(refusal([&] {
                bench.core().complete({bench.worker(name), a.lease_id, a.task, encode_buffer(b)});
              }),
              ErrorCode::InvalidArgument)
        << "damage " << i;
    EXPECT_EQ(refusal([&] { bench.core().renew(bench.worker(name), a.lease_id); }),
              ErrorCode::FailedPrecondition)
        << "the refused result's lease ended";
  }
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(bench.complete(bench.lease("good"), 2.0f, "good"));
  EXPECT_EQ(bench.core().status(job).state, JobState::Completed);
  SampleBuffer frame = bench.image(job);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) ASSERT_EQ(frame.estimate(x, y)[0], 2.0f) << x << "," << y;
  EXPECT_LT(frame.header.core_seconds, 1.0);
}

// Refused results count against the worker that sent them, never against the job: after 3, the
// worker gets no more of the job's tasks (across a restart), and the job runs on and completes.
TEST(CoordinatorCore, AWorkerWhoseResultsAreRefusedGetsNoMoreOfTheJob) {
  CoreBench bench("core-refused-worker");
  std::string job = bench.submit(2);
  for (int i = 0; i < 3; ++i) {
    TaskAssignment a = bench.lease("liar");
    SampleBuffer b = bench.result_buffer(a, 1.0f);
    b.sum[0] = std::nan("");
    EXPECT_EQ(refusal([&] {
                bench.core().complete({bench.worker("liar"), a.lease_id, a.task, encode_buffer(b)});
              }),
              ErrorCode::InvalidArgument);
  }
  EXPECT_FALSE(bench.core().lease(bench.worker("liar")).task);
  EXPECT_EQ(bench.core().status(job).state, JobState::Running);
  bench.start("B");  // the refusals are stored: a restart does not forgive them
  EXPECT_FALSE(bench.core().lease(bench.worker("liar")).task);
  for (int i = 0; i < 8; ++i) EXPECT_TRUE(bench.complete(bench.lease("good"), 1.0f, "good"));
  EXPECT_EQ(bench.core().status(job).state, JobState::Completed);
}

// A client token sees its tenant's jobs only: another tenant's job is refused as a missing one
// (status, watch, cancel, fetch: NotFound, the same message as for an id that was never made, so
// a tenant cannot tell which ids exist) and left out of the list; an admin sees all. The tenant
// survives a restart.
TEST(CoordinatorCore, ClientsSeeOnlyTheirTenantsJobs) {
  CoreBench bench("core-tenants");
  const Caller shot1{"t:a", "shot1", false}, shot2{"t:b", "shot2", false},
      admin{"t:ops", "ops", true};
  std::string job = bench.submit(1, shot1);
  Coordinator& core = bench.core();
  EXPECT_EQ(core.status(job, shot1).tenant, "shot1");
  EXPECT_EQ(refusal([&] { core.status(job, shot2); }), ErrorCode::NotFound);
  EXPECT_EQ(refusal_message([&] { core.status(job, shot2); }), "no job '" + job + "'");
  EXPECT_EQ(refusal_message([&] { core.status("j999999", shot2); }), "no job 'j999999'");
  uint64_t seen = 0;
  EXPECT_EQ(refusal([&] { core.next_status(job, seen, 0.0, shot2); }), ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] { core.fetch(job, 1, shot2); }), ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] { core.cancel(job, shot2); }), ErrorCode::NotFound);
  EXPECT_TRUE(core.list(shot2).empty());
  EXPECT_EQ(core.list(shot1).size(), 1u);
  EXPECT_EQ(core.list(admin).size(), 1u);
  // Blobs are scoped per tenant: shot2 sees none of shot1's uploads and cannot name them.
  std::vector<std::string> digests;
  for (const BundleEntry& f : bundle_of_scene(test::source_dir() + "/" + kScene))
    digests.push_back(f.sha256);
  EXPECT_TRUE(core.missing_blobs(digests, shot1).empty());
  EXPECT_EQ(core.missing_blobs(digests, shot2).size(), digests.size());
  EXPECT_TRUE(core.missing_blobs(digests, admin).empty());
  JobSpec borrowed;
  borrowed.scene_path = "scene.json";
  borrowed.files = bundle_of_scene(test::source_dir() + "/" + kScene);
  EXPECT_EQ(refusal([&] { core.submit(borrowed, shot2); }), ErrorCode::InvalidArgument);
  EXPECT_NO_THROW(bench.submit(1, shot2)) << "once shot2 uploads them itself";
  bench.start("B");
  EXPECT_EQ(refusal([&] { bench.core().status(job, shot2); }), ErrorCode::NotFound);
  EXPECT_EQ(bench.core().status(job, admin).tenant, "shot1");
  bench.core().cancel(job, shot1);
  EXPECT_EQ(bench.core().status(job, shot1).state, JobState::Cancelled);
}

// One coordinator per state directory: a second one is refused, naming the first one's pid.
TEST(CoordinatorCore, ASecondCoordinatorOnTheSameStateDirectoryIsRefused) {
  CoreBench bench("core-lock");
  CoreOptions o;
  o.state_dir = bench.state_dir();
  o.scene_checker = in_process_scene_checker();
  try {
    Coordinator second(o);
    ADD_FAILURE() << "a second coordinator opened the same state directory";
  } catch (const StoreError& e) {
    EXPECT_NE(std::string(e.what()).find("pid " + std::to_string(::getpid())), std::string::npos)
        << e.what();
  }
  bench.start("B");  // the lock is released with the first coordinator
}

// A job over a limit is refused at submit with the limit's name, and leaves nothing behind.
TEST(CoordinatorCore, JobsOverALimitAreRefusedNamingTheLimit) {
  CoreBench bench("core-limits");
  struct Case {
    const char* limit;
    uint64_t value;
    ErrorCode code;
  };
  // The bench's job: 16x16 pixels, 4 tiles, 8 tasks at 2 passes, spp 8, name "cornell" and 3
  // bundle files.
  for (Case c : {Case{"pixels_per_frame", 255, ErrorCode::ResourceExhausted},
                 Case{"tiles_per_frame", 3, ErrorCode::ResourceExhausted},
                 Case{"tasks_per_job", 7, ErrorCode::ResourceExhausted},
                 Case{"spp", 7, ErrorCode::ResourceExhausted},
                 Case{"name_bytes", 6, ErrorCode::InvalidArgument},
                 Case{"bundle_files", 2, ErrorCode::ResourceExhausted}}) {
    bench.limits = JobLimits{};
    ASSERT_TRUE(bench.limits.set(c.limit, c.value));
    bench.start("A");
    size_t jobs = bench.core().list().size();
    std::string why;
    try {
      bench.submit(2);
    } catch (const CoordinatorError& e) {
      why = e.what();
      EXPECT_EQ(e.code, c.code) << c.limit;
    }
    EXPECT_NE(why.find(c.limit), std::string::npos) << c.limit << ": '" << why << "'";
    EXPECT_EQ(bench.core().list().size(), jobs) << "a refused job leaves nothing behind";
    ASSERT_TRUE(bench.limits.set(c.limit, c.value + 1));
    bench.start("A");
    std::string job;
    EXPECT_NO_THROW(job = bench.submit(2)) << c.limit << " at the job's own size";
    if (!job.empty()) bench.core().cancel(job);
  }
  EXPECT_FALSE(bench.limits.set("no_such_limit", 1));
}

// A stored job the coordinator cannot restore (here: over a limit lowered since) is marked
// failed with the reason; the other jobs are served and complete. It stays failed after.
TEST(CoordinatorCore, AJobThatCannotBeRestoredIsFailedAndTheOthersAreServed) {
  CoreBench bench("core-restore-failed");
  std::string big = bench.submit(2), small = bench.submit(1);  // 8 and 4 tasks
  bench.limits.tasks_per_job = 4;
  bench.start("B");
  JobStatus s = bench.core().status(big);
  EXPECT_EQ(s.state, JobState::Failed);
  EXPECT_NE(s.error.find("tasks_per_job"), std::string::npos) << s.error;
  EXPECT_TRUE(s.frames.empty());
  EXPECT_EQ(bench.core().list().size(), 2u);
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(bench.complete(bench.lease(), 1.0f));
  EXPECT_EQ(bench.core().status(small).state, JobState::Completed);
  bench.limits = JobLimits{};
  bench.start("C");
  EXPECT_EQ(bench.core().status(big).state, JobState::Failed);
  EXPECT_EQ(bench.core().status(small).state, JobState::Completed);
}

// A registration that no call uses for 10 minutes (10 lease times if longer) is forgotten at a
// later registration, in memory and in the store: registrations of a client that never leases
// do not pile up. So is a worker that leased and then fell silent for 10 lease times (at least a
// minute) with no live lease: killed (the soak's workers come and go by the thousand), since a
// live one calls at least once a lease time. A worker that keeps calling stays; a forgotten one
// that comes back is NotFound (and registers again).
TEST(CoordinatorCore, RegistrationsThatAreNeverUsedOrFallSilentExpire) {
  CoreBench bench("core-registrations");  // lease 10 s: silent for 100 s is gone
  Coordinator& core = bench.core();
  std::vector<std::string> idle;
  for (int i = 0; i < 200; ++i)
    idle.push_back(core.register_worker({"idle", 1, "b", "i"}).worker_id);
  std::string busy = core.register_worker({"busy", 1, build_id(), "i"}).worker_id;
  std::string killed = core.register_worker({"killed", 1, build_id(), "i"}).worker_id;
  bench.submit(1);
  EXPECT_TRUE(core.lease(busy).task);
  EXPECT_TRUE(core.lease(killed).task);  // and never heard from again: its lease expires
  EXPECT_EQ(core.metrics().workers_registered, 202u);
  bench.now = 99;
  core.lease(busy);  // still calling
  core.register_worker({"late", 1, "b", "i"});
  EXPECT_EQ(core.metrics().workers_registered, 203u) << "nobody silent for 100 s yet";
  bench.now = 161;
  core.lease(busy);
  core.register_worker({"later", 1, "b", "i"});
  EXPECT_EQ(core.metrics().workers_registered, 203u) << "killed gone, later came";
  EXPECT_EQ(refusal([&] { core.lease(killed); }), ErrorCode::NotFound);
  bench.now = 650;
  core.lease(busy);
  bench.now = 700;
  core.register_worker({"last", 1, "b", "i"});
  EXPECT_EQ(core.metrics().workers_registered, 3u)
      << "busy, later and last: idle and late unused for over 10 minutes";
  EXPECT_EQ(refusal([&] { core.lease(idle[7]); }), ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] { core.lease(busy); }), std::nullopt);
  bench.start("B");
  EXPECT_EQ(bench.core().metrics().workers_registered, 3u) << "the store forgot them too";
}

// The blob store deleted while the coordinator was stopped: the job fails at the restart, saying
// its blobs are missing from the store (it said "was not uploaded"), and keeps its frames, so the
// pass merged before is still fetched.
TEST(CoordinatorCore, AJobWhoseBlobsWentKeepsItsMergedPasses) {
  CoreBench bench("core-blobs-gone");
  std::string job = bench.submit(2);
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(bench.complete(bench.lease(), 1.0f));  // pass 0
  bench.stop();
  fs::remove_all(bench.state_dir() + "/blobs");
  bench.start("B");
  JobStatus s = bench.core().status(job);
  EXPECT_EQ(s.state, JobState::Failed);
  EXPECT_NE(s.error.find("is missing from the coordinator's blob store"), std::string::npos)
      << s.error;
  ASSERT_EQ(s.frames.size(), 1u);
  EXPECT_EQ(s.frames[0].progress.passes_merged, 1u);
  EXPECT_EQ(bench.image(job).header.passes.count(), 1u);
}

// A process killed during an atomic write leaves NAME.tmp.PID.N behind (a checkpoint, a blob):
// the next start removes such files, and only those.
TEST(CoordinatorCore, TemporariesOfInterruptedWritesAreRemovedAtStart) {
  CoreBench bench("core-temporaries");
  std::string job = bench.submit(1);
  bench.stop();
  const std::string frame = bench.state_dir() + "/jobs/" + job + "/frame-1";
  test::write_text(frame + "/prefix.rfb.tmp.4242.0", "half a checkpoint");
  test::write_text(bench.state_dir() + "/blobs/ab/abcd.tmp.99.3", "half a blob");
  test::write_text(frame + "/notes.tmp.txt", "not ours");
  bench.start("B");
  EXPECT_FALSE(fs::exists(frame + "/prefix.rfb.tmp.4242.0"));
  EXPECT_FALSE(fs::exists(bench.state_dir() + "/blobs/ab/abcd.tmp.99.3"));
  EXPECT_TRUE(fs::exists(frame + "/notes.tmp.txt"));
  EXPECT_EQ(bench.core().status(job).state, JobState::Queued);
}

// A restart plans each stored job from the scene summaries its submit's check left in the job's
// folder (scenes.json, with the build that made them), starting no scene check; a copy that is
// damaged, or of another build, is replaced by a new check.
TEST(CoordinatorCore, ARestartTakesSceneSummariesFromTheJobFolder) {
  CoreBench bench("core-scene-cache");
  std::string a = bench.submit(2), b = bench.submit(1);
  EXPECT_EQ(bench.scene_checks, 2);
  const std::string cache = bench.state_dir() + "/jobs/" + a + "/scenes.json";
  nlohmann::json j = nlohmann::json::parse(read_file_bytes(cache));
  EXPECT_EQ(j.at("build"), build_id());
  EXPECT_EQ(j.at("scenes").size(), 1u);
  bench.start("B");
  EXPECT_EQ(bench.scene_checks, 2) << "no check at a restart";
  EXPECT_EQ(bench.core().status(a).frames.size(), 1u);
  test::write_text(cache, "{\"build\": \"another\", \"scenes\": []}");
  test::write_text(bench.state_dir() + "/jobs/" + b + "/scenes.json", "not json");
  bench.start("C");
  EXPECT_EQ(bench.scene_checks, 4);
  for (int i = 0; i < 12; ++i) EXPECT_TRUE(bench.complete(bench.lease(), 1.0f));
  EXPECT_EQ(bench.core().status(a).state, JobState::Completed);
  EXPECT_EQ(bench.core().status(b).state, JobState::Completed);
  EXPECT_EQ(nlohmann::json::parse(read_file_bytes(cache)).at("build"), build_id());
}

// A job merges results of one build: the first merged result's, or the one its submitter pins.
// A result of another build is refused, and a worker of another build gets none of its tasks.
TEST(CoordinatorCore, AJobMergesResultsOfOneBuildOnly) {
  CoreBench bench("core-build");
  std::string job = bench.submit(1);
  TaskAssignment a = bench.lease(), b = bench.lease();
  EXPECT_TRUE(bench.complete(a, 1.0f));
  EXPECT_EQ(bench.core().status(job).build_id, build_id());
  SampleBuffer other = bench.result_buffer(b, 1.0f);
  other.header.build_id = "rayfarm-0.0.1+old";
  EXPECT_EQ(refusal([&] {
              bench.core().complete({bench.worker("w"), b.lease_id, b.task, encode_buffer(other)});
            }),
            ErrorCode::FailedPrecondition);
  std::string old = bench.core().register_worker({"old", 1, "rayfarm-0.0.1+old", "x"}).worker_id;
  LeaseResult none = bench.core().lease(old);
  EXPECT_FALSE(none.task);
  EXPECT_TRUE(none.no_more_work) << "another build's job is not this worker's work";
  EXPECT_TRUE(bench.complete(b, 1.0f));
  for (int i = 0; i < 2; ++i) EXPECT_TRUE(bench.complete(bench.lease(), 1.0f));
  bench.start("B");
  EXPECT_EQ(bench.core().status(job).build_id, build_id()) << "the pin is stored";

  // Pinned by its submitter: only the old build's worker gets its tasks.
  std::string pinned = bench.submit(1, {}, "rayfarm-0.0.1+old");
  EXPECT_EQ(bench.core().status(pinned).build_id, "rayfarm-0.0.1+old");
  EXPECT_FALSE(bench.core().lease(bench.worker("w")).task);
  std::optional<TaskAssignment> t = bench.core().lease(old).task;
  ASSERT_TRUE(t);
  EXPECT_EQ(t->task.job_id, pinned);
}

// The CPU kind is pinned as the build is: the first merged result's kind (Embree's ISA and
// RAYFARM_EMBREE_CONFIG, BufferHeader::isa) is the job's, a worker of another kind gets none of
// its tasks, and a result of another kind leased before the pin is not merged, nor counted against
// its worker: its task goes back to the queue. The pin and the workers' kinds outlive a restart.
TEST(CoordinatorCore, AJobMergesResultsOfOneCpuKindOnly) {
  CoreBench bench("core-cpu-kind");
  const std::string job = bench.submit(1);
  const std::string other_kind = "x86_64-avx512 embree:isa=avx512";
  ASSERT_NE(other_kind, cpu_isa());
  const std::string x = bench.core().register_worker({"x", 1, build_id(), other_kind}).worker_id;
  TaskAssignment a = bench.lease("w");
  std::optional<TaskAssignment> b = bench.core().lease(x).task;
  ASSERT_TRUE(b) << "before the pin, any kind may lease";
  EXPECT_TRUE(bench.complete(a, 1.0f));
  EXPECT_EQ(bench.core().status(job).cpu_kind, cpu_isa());
  SampleBuffer theirs = bench.result_buffer(*b, 1.0f);
  theirs.header.isa = other_kind;
  const std::string why = refusal_message([&] {
    bench.core().complete({x, b->lease_id, b->task, encode_buffer(theirs)});
  });
  EXPECT_NE(why.find("merges results of CPU kind '" + cpu_isa() + "'"), std::string::npos) << why;
  LeaseResult none = bench.core().lease(x);
  EXPECT_FALSE(none.task);
  EXPECT_TRUE(none.no_more_work) << "a job of another kind is not this worker's work";
  for (const WorkerStatus& w : bench.core().workers())
    EXPECT_EQ(w.failures, 0) << w.worker_id << ": another kind's result is not a fault";
  for (int i = 0; i < 3; ++i) {
    TaskAssignment t = bench.lease("w");
    EXPECT_TRUE(bench.complete(t, 1.0f));
  }
  EXPECT_EQ(bench.core().status(job).state, JobState::Completed);
  // A worker registered by an earlier build has no kind on record: it may lease a pinned job's
  // task; its result tells its kind, and the task goes back, uncounted, for the pin's workers.
  bench.frames = "1";
  const std::string second = bench.submit(1);
  TaskAssignment first = bench.lease("w");
  ASSERT_TRUE(bench.complete(first, 1.0f));
  const std::string old = bench.core().register_worker({"old", 1, build_id(), ""}).worker_id;
  std::optional<TaskAssignment> o = bench.core().lease(old).task;
  ASSERT_TRUE(o) << "an unknown kind may lease";
  SampleBuffer olds = bench.result_buffer(*o, 1.0f);
  olds.header.isa = other_kind;
  EXPECT_EQ(refusal([&] {
              bench.core().complete({old, o->lease_id, o->task, encode_buffer(olds)});
            }),
            ErrorCode::FailedPrecondition);
  EXPECT_FALSE(bench.core().lease(old).task) << "its kind is known now";
  bench.start("B");
  EXPECT_EQ(bench.core().status(job).cpu_kind, cpu_isa()) << "the pin is stored";
  bool listed = false;
  for (const WorkerStatus& w : bench.core().workers())
    if (w.worker_id == x) {
      listed = true;
      EXPECT_EQ(w.info.isa, other_kind);
    }
  EXPECT_TRUE(listed) << "the registration and its kind outlive the restart";
}

// Tags and pools: a job requiring pool=gpu is leased only to a worker with that tag (stored, so
// also after a restart); until one registers, `status` says why it waits, and the per-pool metric
// counts its tasks under "gpu", not "any" (a paused job's under neither). Bad tags and
// requirements are refused naming them.
TEST(CoordinatorCore, JobsRequiringTagsGoOnlyToWorkersWithThemAndSayWhenNoneCan) {
  CoreBench bench("core-tags");
  bench.required_tags = {"pool=gpu", "memory_gb>=8"};
  const std::string job = bench.submit(1);
  EXPECT_EQ(bench.core().status(job).waiting_for, "no worker is registered");
  LeaseResult plain = bench.core().lease(bench.worker("plain"));
  EXPECT_FALSE(plain.task);
  EXPECT_TRUE(plain.no_more_work) << "a job this worker cannot meet is not its work";
  EXPECT_EQ(bench.core().status(job).waiting_for,
            "no registered worker has what it needs: tags pool=gpu memory_gb>=8");
  CoordinatorMetrics m = bench.core().metrics();
  EXPECT_EQ(m.pools["gpu"].tasks_queued, 4u);
  EXPECT_EQ(m.pools[kAnyPool].tasks_queued, 0u);
  EXPECT_EQ(refusal([&] {
              bench.core().register_worker({"bad", 1, build_id(), cpu_isa(), {"Pool=GPU"}});
            }),
            ErrorCode::InvalidArgument);
  const std::string small =
      bench.core()
          .register_worker({"s", 1, build_id(), cpu_isa(), {"pool=gpu", "memory_gb=4"}})
          .worker_id;
  EXPECT_FALSE(bench.core().lease(small).task) << "4 GB is not 8";
  const std::string gpu =
      bench.core()
          .register_worker({"g", 1, build_id(), cpu_isa(), {"pool=gpu", "memory_gb=64"}})
          .worker_id;
  EXPECT_EQ(bench.core().status(job).waiting_for, "");
  bench.start("B");  // the tags are stored with the registration
  std::optional<TaskAssignment> t = bench.core().lease(gpu).task;
  ASSERT_TRUE(t);
  EXPECT_EQ(t->task.job_id, job);
  bench.core().set_paused(job, true);
  m = bench.core().metrics();
  EXPECT_EQ(m.pools["gpu"].tasks_queued, 0u) << "a paused job's tasks scale no pool";
  EXPECT_EQ(m.pools["gpu"].tasks_leased, 1u);
  bench.required_tags = {"memory_gb>=lots"};
  EXPECT_EQ(refusal([&] { bench.submit(1); }), ErrorCode::InvalidArgument);
}

// `logs`: an expired lease's attempt (expired, with its start and end 11 s apart on the
// coordinator's clock), the live one (running), a handed-back one; one task's attempts only when
// asked; another tenant's job is NotFound; a task id of another job is InvalidArgument.
TEST(CoordinatorCore, TaskLogsListEndedAndLiveAttempts) {
  CoreBench bench("core-logs");
  const Caller alice{"alice", "shot1", false}, bob{"bob", "shot2", false};
  const std::string job = bench.submit(1, alice);
  TaskAssignment first = bench.lease("w1");
  bench.now += 11;  // past the 10 s lease: it expires at the next call
  TaskAssignment second = bench.lease("w2");
  EXPECT_EQ(second.task, first.task) << "the expired task comes first again";
  TaskAssignment third = bench.lease("w2");
  bench.core().fail({bench.worker("w2"), third.lease_id, "shutting down", true, {"info: bye"}});
  TaskLog log = bench.core().task_log(job, std::nullopt, "", 0, alice);
  ASSERT_EQ(log.attempts.size(), 3u);
  EXPECT_EQ(log.attempts[0].outcome, AttemptOutcome::Expired);
  EXPECT_EQ(log.attempts[0].worker_id, bench.worker("w1"));
  EXPECT_NEAR(log.attempts[0].ended_unix - log.attempts[0].started_unix, 11, 1e-6);
  EXPECT_EQ(log.attempts[1].outcome, AttemptOutcome::HandedBack);
  EXPECT_EQ(log.attempts[1].log, std::vector<std::string>{"info: bye"});
  EXPECT_EQ(log.attempts[2].outcome, AttemptOutcome::Running);
  EXPECT_EQ(log.attempts[2].lease_id, second.lease_id);
  log = bench.core().task_log(job, std::nullopt, task_id_text(third.task), 0, alice);
  ASSERT_EQ(log.attempts.size(), 1u);
  EXPECT_EQ(log.attempts[0].outcome, AttemptOutcome::HandedBack);
  EXPECT_EQ(refusal([&] { bench.core().task_log(job, std::nullopt, "", 0, bob); }),
            ErrorCode::NotFound);
  EXPECT_EQ(refusal([&] { bench.core().task_log(job, std::nullopt, "j9/1/0/0", 0, alice); }),
            ErrorCode::InvalidArgument);
  EXPECT_EQ(refusal([&] { bench.core().task_log(job, 7, "", 0, alice); }), ErrorCode::NotFound);
}

// The job list comes in pages: at most `limit` jobs after a given job, and whether more follow.
TEST(CoordinatorCore, TheJobListComesInPages) {
  CoreBench bench("core-pages");
  std::vector<std::string> jobs;
  for (int i = 0; i < 5; ++i) jobs.push_back(bench.submit(1));
  bool more = false;
  std::vector<JobStatus> page = bench.core().list({}, 2, "", &more);
  ASSERT_EQ(page.size(), 2u);
  EXPECT_EQ(page[1].job_id, jobs[1]);
  EXPECT_TRUE(more);
  page = bench.core().list({}, 2, jobs[3], &more);
  ASSERT_EQ(page.size(), 1u);
  EXPECT_EQ(page[0].job_id, jobs[4]);
  EXPECT_FALSE(more);
  EXPECT_EQ(refusal([&] { bench.core().list({}, 2, "j999999"); }), ErrorCode::NotFound);
}

// The job database lost (deleted, or truncated to nothing, or its WAL with the last jobs
// removed): every job is recovered from its folder (spec, state, checkpoints) with the passes
// it had merged, ended jobs stay ended, and new jobs never reuse an id. Before, the coordinator
// started with 0 jobs and gave the next job the id of an old folder.
TEST(CoordinatorCore, JobsTheDatabaseLostAreRecoveredFromTheirFolders) {
  CoreBench bench("core-lost-db", Store::Sqlite);
  std::string done = bench.submit(2), cancelled = bench.submit(2), running = bench.submit(2);
  for (int i = 0; i < 8; ++i) {  // all of the first job's tasks
    TaskAssignment a = bench.lease();
    ASSERT_EQ(a.task.job_id, done);
    EXPECT_TRUE(bench.complete(a, 1.0f));
  }
  bench.core().cancel(cancelled);
  for (int i = 0; i < 4; ++i) {  // pass 0 of the third
    TaskAssignment a = bench.lease();
    ASSERT_EQ(a.task.job_id, running);
    EXPECT_TRUE(bench.complete(a, 1.0f));
  }
  SampleBuffer before = bench.image(done);
  bench.core().set_paused(running, true);  // a setting in the folder's record too
  bench.core().set_priority(running, 7);
  bench.stop();
  for (const char* f : {"/jobs.sqlite", "/jobs.sqlite-wal", "/jobs.sqlite-shm"})
    std::filesystem::remove(bench.state_dir() + f);
  bench.start("B");
  bench.start("C");  // the recovered rows hold the settings: a second start keeps them
  EXPECT_TRUE(bench.core().status(running).paused);
  EXPECT_EQ(bench.core().status(running).priority, 7);
  bench.core().set_paused(running, false);
  EXPECT_EQ(bench.core().status(done).state, JobState::Completed);
  EXPECT_EQ(bench.core().status(cancelled).state, JobState::Cancelled);
  JobStatus r = bench.core().status(running);
  EXPECT_EQ(r.frames[0].progress.passes_merged, 1u) << "pass 0 came back from its checkpoint";
  SampleBuffer after = bench.image(done);
  EXPECT_EQ(after.sum, before.sum);
  std::string next = bench.submit(2);
  EXPECT_EQ(next, "j000004") << "after the highest folder";
  // Worker registrations were in the database: workers register again (NOT_FOUND tells them).
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(bench.complete(bench.lease("w2"), 1.0f, "w2"));
  EXPECT_EQ(bench.core().status(running).state, JobState::Completed);
}

// A damaged database (not a database, or failing SQLite's check) stops the coordinator with
// StoreDamaged, exit status 4 from the process, and a message that says how to recover; doing
// what it says brings every job back.
TEST(CoordinatorCore, ADamagedJobDatabaseStopsTheCoordinatorSayingHowToRecover) {
  CoreBench bench("core-damaged-db", Store::Sqlite);
  std::string job = bench.submit(2);
  bench.stop();
  std::string db = bench.state_dir() + "/jobs.sqlite";
  auto size = std::filesystem::file_size(db);
  std::filesystem::resize_file(db, size / 2);
  std::string message;
  try {
    bench.start("B");
  } catch (const StoreDamaged& e) {
    message = e.what();
  }
  EXPECT_NE(message.find("To recover"), std::string::npos) << message;
  test::write_text(db, std::string(8192, 'x'));
  test::CommandResult r = test::run_command(test::rayfarm_binary() + " coordinator --state-dir " +
                                            bench.state_dir() + " --listen 127.0.0.1:0");
  EXPECT_EQ(r.exit_code, 4) << r.output;
  EXPECT_NE(r.output.find("jobs.sqlite"), std::string::npos) << r.output;
  for (const char* f : {"/jobs.sqlite", "/jobs.sqlite-wal", "/jobs.sqlite-shm"})
    std::filesystem::remove(bench.state_dir() + f);
  bench.start("C");
  EXPECT_EQ(bench.core().status(job).state, JobState::Queued);
}

// A submit retried with its request id (the client makes one per command) gets the job the
// first attempt made, also after a restart; the same id with another spec is refused; ids are
// per tenant; submits without one always make a job.
TEST(CoordinatorCore, ARetriedSubmitWithItsRequestIdMakesOneJob) {
  CoreBench bench("core-idempotent");
  const Caller a{"t:a", "a", false}, b{"t:b", "b", false};
  std::string first = bench.submit(2, a, "", "req-1");
  EXPECT_EQ(bench.submit(2, a, "", "req-1"), first);
  EXPECT_EQ(refusal([&] { bench.submit(3, a, "", "req-1"); }), ErrorCode::InvalidArgument);
  std::string other = bench.submit(2, b, "", "req-1");
  EXPECT_NE(other, first) << "another tenant's request id is its own";
  EXPECT_NE(bench.submit(2, a), bench.submit(2, a)) << "no request id: a job each";
  bench.start("B");
  EXPECT_EQ(bench.submit(2, a, "", "req-1"), first) << "the request ids are restored";
  EXPECT_EQ(bench.core().list({"t:admin", "", true}, 100, "").size(), 4u);
}

// --verify-fraction 1: every task is rendered by two workers and merged only when their results
// are bit-identical. A worker that sends a plausible wrong result (finite, the right counts) is
// outvoted by a third and refused from then on; the image is the honest one.
TEST(CoordinatorCore, VerificationMergesOnlyAgreeingResultsAndRefusesTheOutvotedWorker) {
  CoreBench bench("core-verify");
  bench.verify_fraction = 1;
  bench.start("A");
  std::string job = bench.submit(1);
  TaskAssignment lie = bench.lease("liar");
  EXPECT_TRUE(bench.complete(lie, 5.0f, "liar")) << "taken, held for verification";
  EXPECT_EQ(bench.core().status(job).frames[0].progress.passes_merged, 0u);
  TaskAssignment a = bench.lease("a");
  EXPECT_EQ(a.task, lie.task) << "the held task goes to another worker first";
  EXPECT_TRUE(bench.complete(a, 1.0f, "a"));
  TaskAssignment c = bench.lease("c");
  EXPECT_EQ(c.task, lie.task) << "a disagreement needs a third worker";
  EXPECT_TRUE(bench.complete(c, 1.0f, "c"));
  EXPECT_EQ(refusal([&] { bench.core().lease(bench.worker("liar")); }),
            ErrorCode::PermissionDenied);
  bench.start("B");  // stored with the worker's registration: still refused after a restart
  EXPECT_EQ(refusal([&] { bench.core().lease(bench.worker("liar")); }),
            ErrorCode::PermissionDenied);
  // The other three tasks, each by two honest workers.
  for (int i = 0; i < 3; ++i) {
    TaskAssignment x = bench.lease("a");
    EXPECT_TRUE(bench.complete(x, 1.0f, "a"));
    TaskAssignment y = bench.lease("c");
    ASSERT_EQ(x.task, y.task);
    EXPECT_TRUE(bench.complete(y, 1.0f, "c"));
  }
  EXPECT_EQ(bench.core().status(job).state, JobState::Completed);
  SampleBuffer frame = bench.image(job);
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) ASSERT_EQ(frame.estimate(x, y)[0], 1.0f) << x << "," << y;
}

}  // namespace
}  // namespace rf
