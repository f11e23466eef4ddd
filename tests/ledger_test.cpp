// The task ledger and its journal (coordinator/ledger.h, journal.h): every job transition and the
// ones the state machine does not have, every task transition with the store rows it leaves, the
// journal's order, grouping, retries and write-ahead refusals, and a coordinator whose leases do
// not wait while the disk is slow.
#include "coordinator/ledger.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <future>
#include <set>
#include <thread>

#include "coordinator/journal.h"
#include "engine/buffer_file.h"
#include "engine/build_info.h"
#include "engine/digest.h"
#include "engine/scene.h"
#include "engine/work_units.h"
#include "farm/blob_store.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

// A memory store whose writes can be made to fail, or to wait at a gate.
class TestStore final : public JobStore {
 public:
  using JobStore::write;
  void write(const std::vector<StoreWrite>& batch) override {
    if (delay_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(int(delay_ms)));
    {
      std::unique_lock lock(m_);
      ++waiting;
      cv_.wait(lock, [&] { return open; });
      --waiting;
    }
    if (failing) throw StoreError("test store: disk full");
    inner_->write(batch);
  }
  uint64_t next_seq() const override { return inner_->next_seq(); }
  std::vector<StoredJob> jobs() const override { return inner_->jobs(); }
  std::vector<StoredWorker> workers() const override { return inner_->workers(); }
  bool blob_tenant(const std::string& t, const std::string& d) const override {
    return inner_->blob_tenant(t, d);
  }
  std::optional<Tombstone> tombstone(const std::string& j) const override {
    return inner_->tombstone(j);
  }
  void for_each_lease(const std::string& j,
                      const std::function<void(const StoredLease&)>& f) const override {
    inner_->for_each_lease(j, f);
  }
  std::vector<TaskFailure> failures(const std::string& j) const override {
    return inner_->failures(j);
  }
  std::vector<std::string> refused_workers(const std::string& j) const override {
    return inner_->refused_workers(j);
  }
  std::vector<TaskFailure> failure_history(const std::string& j) const override {
    return inner_->failure_history(j);
  }
  std::vector<StoredAttempt> attempts(const std::string& j, std::optional<FrameNumber> f,
                                      const std::optional<TaskRef>& t, size_t limit,
                                      bool* more) const override {
    return inner_->attempts(j, f, t, limit, more);
  }
  uint64_t tasks_done(const std::string& j) const override { return inner_->tasks_done(j); }

  void close_gate() {
    std::lock_guard lock(m_);
    open = false;
  }
  void open_gate() {
    {
      std::lock_guard lock(m_);
      open = true;
    }
    cv_.notify_all();
  }
  std::atomic<bool> failing{false};
  std::atomic<double> delay_ms{0};
  int waiting = 0;  // under m_

 private:
  std::unique_ptr<JobStore> inner_ = memory_store();
  std::mutex m_;
  std::condition_variable cv_;
  bool open = true;
};

// A job record of `frames` frames, 4 tiles, `passes` passes (what intake makes, minus the scene).
std::shared_ptr<JobRecord> make_job(const std::string& id, uint32_t frames = 1,
                                    uint32_t passes = 2) {
  auto job = std::make_shared<JobRecord>();
  job->id = id;
  job->passes = passes;
  job->tiles = TileGrid(16, 16, 8);  // {0,0,8,8}, {8,0,8,8}, {0,8,8,8}, {8,8,8,8}
  for (uint32_t n = 1; n <= frames; ++n) {
    auto f = std::make_unique<FrameRecord>();
    f->number = n;
    job->by_number[n] = f.get();
    job->frames.push_back(std::move(f));
  }
  return job;
}

struct Bench {
  TestStore store;
  Journal journal{store};
  Ledger ledger{SchedulerOptions{10, 3, 4, "L", {}}, journal};
  double now = 0;
  void flush() { ASSERT_TRUE(journal.wait(journal.append({}), 10)); }
};

TEST(Ledger, JobTransitionsAreTheStateMachinesAndNoOthers) {
  const JobState all[] = {JobState::Queued, JobState::Running, JobState::Completed,
                          JobState::Failed, JobState::Cancelled};
  // Every (from, to): legal exactly as ledger.h says.
  for (JobState from : all)
    for (JobState to : all) {
      Bench b;
      auto job = make_job("j1");
      job->state = from;
      // (An ended job leaves only by retry(), tested below.)
      bool legal = !terminal(from) && to != JobState::Queued &&
                   (to != JobState::Running || from == JobState::Queued);
      if (legal) {
        EXPECT_NO_THROW(b.ledger.set_state(*job, to, "why"))
            << job_state_name(from) << " -> " << job_state_name(to);
        EXPECT_EQ(job->state, to);
      } else {
        EXPECT_THROW(b.ledger.set_state(*job, to, "why"), std::logic_error)
            << job_state_name(from) << " -> " << job_state_name(to);
        EXPECT_EQ(job->state, from) << "a refused transition changes nothing";
      }
    }
  // Cancel: once is the transition, again nothing; a completed job is not cancelled.
  Bench b;
  auto job = make_job("j1");
  b.ledger.add_job(*job);
  b.ledger.cancel(*job, "alice");
  EXPECT_EQ(job->state, JobState::Cancelled);
  EXPECT_EQ(job->error, "cancelled by alice");
  b.ledger.cancel(*job, "bob");
  EXPECT_EQ(job->error, "cancelled by alice");
  auto done = make_job("j2");
  done->state = JobState::Completed;
  EXPECT_THROW(b.ledger.cancel(*done, "alice"), std::logic_error);
}

// An ended job's row says so, its lease rows go, and its tasks are no longer handed out.
TEST(Ledger, EndingAJobStoresItsStateDropsItsLeasesAndItsTasks) {
  Bench b;
  auto job = make_job("j1");
  b.store.write(store::InsertJob{{"j1", 1, JobSpec{}, int(JobState::Queued), "", 0, 0, "", ""}});
  b.ledger.add_job(*job);
  ASSERT_TRUE(b.ledger.lease("w", b.now, {}));
  b.flush();
  EXPECT_EQ(b.store.leases("j1").size(), 1u);
  b.ledger.set_state(*job, JobState::Failed, "broken");
  b.flush();
  EXPECT_EQ(b.store.jobs()[0].state, int(JobState::Failed));
  EXPECT_EQ(b.store.jobs()[0].error, "broken");
  EXPECT_TRUE(b.store.leases("j1").empty());
  EXPECT_FALSE(b.ledger.lease("w", b.now, {})) << "no task of an ended job";
}

// Pause and resume, and a new priority: not states (a Queued or Running job keeps its state),
// stored, idempotent, refused on an ended job. A paused job gets no new lease; its lease in
// flight completes and is counted; resumed, it is leased again. A job raised above another is
// leased first.
TEST(Ledger, PauseResumeAndPriorityAreStoredAndSteerLeases) {
  Bench b;
  auto a = make_job("j1"), c = make_job("j2");
  for (const char* id : {"j1", "j2"})
    b.store.write(store::InsertJob{{id, 1, JobSpec{}, int(JobState::Queued), "", 0, 0, "", ""}});
  b.ledger.add_job(*a);
  b.ledger.add_job(*c);
  std::optional<Lease> first = b.ledger.lease("w1", b.now, {});
  ASSERT_TRUE(first);
  EXPECT_EQ(first->task.job_id, "j1");
  b.ledger.set_state(*a, JobState::Running, "");
  b.ledger.set_paused(*a, true);
  b.flush();
  EXPECT_TRUE(a->paused);
  EXPECT_EQ(a->state, JobState::Running) << "a pause is not a state";
  EXPECT_TRUE(b.store.jobs()[0].paused);
  for (int i = 0; i < 8; ++i) {  // every task of j2, none of the paused j1
    std::optional<Lease> l = b.ledger.lease("w2", b.now, {});
    ASSERT_TRUE(l);
    EXPECT_EQ(l->task.job_id, "j2");
  }
  EXPECT_FALSE(b.ledger.lease("w2", b.now, {})) << "the paused job's tasks wait";
  EXPECT_TRUE(b.ledger.scheduler().work_left_for("w2")) << "a pause is not an end";
  // The lease in flight completes and counts.
  b.ledger.complete(*a, first->lease_id, first->task, "w1", 1.0, "B", "K", b.now);
  b.flush();
  EXPECT_EQ(b.store.tasks_done("j1"), 1u);
  // Pausing again writes nothing; resuming leases j1's remaining tasks.
  const size_t writes = b.store.jobs().size();
  b.ledger.set_paused(*a, true);
  EXPECT_EQ(b.store.jobs().size(), writes);
  b.ledger.set_paused(*a, false);
  b.flush();
  EXPECT_FALSE(b.store.jobs()[0].paused);
  std::optional<Lease> again = b.ledger.lease("w2", b.now, {});
  ASSERT_TRUE(again);
  EXPECT_EQ(again->task.job_id, "j1");
  // Priority: a third job submitted later but raised above j1 gets every lease while it has
  // tasks, though it then holds more leases than j1 (priority before fair share).
  auto d = make_job("j3");
  b.store.write(store::InsertJob{{"j3", 3, JobSpec{}, int(JobState::Queued), "", 0, 0, "", ""}});
  b.ledger.add_job(*d);
  b.ledger.set_priority(*d, 5);
  b.flush();
  EXPECT_EQ(d->priority, 5);
  EXPECT_EQ(b.store.jobs()[2].priority, std::optional<int>(5));
  EXPECT_FALSE(b.store.jobs()[0].priority) << "untouched: the spec's";
  for (int i = 0; i < 8; ++i) EXPECT_EQ(b.ledger.lease("w2", b.now, {})->task.job_id, "j3");
  EXPECT_EQ(b.ledger.lease("w2", b.now, {})->task.job_id, "j1");
  // Ended jobs take neither.
  b.ledger.set_state(*c, JobState::Completed, "");
  EXPECT_THROW(b.ledger.set_paused(*c, true), std::logic_error);
  EXPECT_THROW(b.ledger.set_priority(*c, 9), std::logic_error);
  EXPECT_FALSE(c->paused);
  EXPECT_EQ(c->priority, 0);
}

// Retry: a failed job runs again (Failed -> Running) with its failure counts afresh (the workers
// it failed on get its tasks again) and the old failures kept as history; its done frame stays
// done, a frame left out is held (not leased) until a second retry releases it; a held frame
// stays held across a restore. A cancelled job is retried too; a completed one is not.
TEST(Ledger, RetryRunsFailedWorkAgainWithFreshCountsAndKeepsTheHistory) {
  Bench b;
  auto job = make_job("j1", 3, 1);  // frames 1-3, 4 tasks each
  b.store.write(store::InsertJob{{"j1", 1, JobSpec{}, int(JobState::Queued), "", 0, 0, "", ""}});
  b.ledger.add_job(*job);
  b.ledger.set_state(*job, JobState::Running, "");
  for (int i = 0; i < 4; ++i) {  // frame 1 done (frame affinity keeps w0 on it)
    std::optional<Lease> l = b.ledger.lease("w0", b.now, {});
    ASSERT_TRUE(l);
    ASSERT_EQ(l->task.frame, 1);
    b.ledger.complete(*job, l->lease_id, l->task, "w0", 1, "B", "K", b.now);
  }
  std::optional<Lease> r = b.ledger.lease("w4", b.now, {});  // a refused result counts on w4
  ASSERT_TRUE(r);
  b.ledger.refuse_result("w4", r->lease_id, r->task, "NaN", b.now);
  for (const char* w : {"w1", "w2", "w3"}) {  // the same task fails on three workers
    std::optional<Lease> l = b.ledger.lease(w, b.now, {});
    ASSERT_TRUE(l);
    ASSERT_EQ(l->task, r->task);
    Journal::Ticket t = 0;
    b.ledger.fail(l->lease_id, w, std::string("crash on ") + w, false, b.now, &t);
  }
  ASSERT_TRUE(b.ledger.scheduler().job_failed("j1"));
  b.ledger.set_state(*job, JobState::Failed, b.ledger.scheduler().job_error("j1"));
  EXPECT_THROW(b.ledger.set_state(*job, JobState::Running, ""), std::logic_error)
      << "an ended job leaves by retry only";
  b.flush();
  EXPECT_EQ(b.store.failures("j1").size(), 3u);

  b.ledger.retry(*job, {r->task.frame}, {3});
  b.flush();
  EXPECT_EQ(job->state, JobState::Running);
  EXPECT_EQ(job->error, "");
  EXPECT_EQ(b.store.jobs()[0].state, int(JobState::Running));
  EXPECT_EQ(b.store.jobs()[0].held, std::vector<FrameNumber>{3});
  EXPECT_TRUE(b.store.failures("j1").empty()) << "the counts start afresh";
  EXPECT_TRUE(b.store.refused_workers("j1").empty());
  std::vector<TaskFailure> history = b.store.failure_history("j1");
  ASSERT_EQ(history.size(), 3u) << "the history is kept";
  for (const TaskFailure& f : history) EXPECT_FALSE(f.counted);
  // w1 failed the task before; it may take it now. Only frame 2 is leased: 1 is done, 3 held.
  for (int i = 0; i < 4; ++i) {
    std::optional<Lease> l = b.ledger.lease("w1", b.now, {});
    ASSERT_TRUE(l);
    EXPECT_EQ(l->task.frame, 2);
  }
  EXPECT_FALSE(b.ledger.lease("w1", b.now, {})) << "frame 3 is held";
  // A restore of the job as stored holds frame 3 too.
  {
    Bench b2;
    auto copy = make_job("j1", 3, 1);
    copy->state = JobState::Running;
    copy->by_number[3]->held = true;
    b2.ledger.restore_job(*copy, {});
    for (int i = 0; i < 8; ++i) EXPECT_NE(b2.ledger.lease("w", b2.now, {})->task.frame, 3);
    EXPECT_FALSE(b2.ledger.lease("w", b2.now, {}));
  }
  // A second retry of the running job releases frame 3.
  b.ledger.retry(*job, {3}, {});
  b.flush();
  EXPECT_TRUE(b.store.jobs()[0].held.empty());
  std::optional<Lease> three = b.ledger.lease("w1", b.now, {});
  ASSERT_TRUE(three);
  EXPECT_EQ(three->task.frame, 3);

  // Cancelled: retried; completed: refused.
  auto c = make_job("j2");
  b.ledger.add_job(*c);
  b.ledger.cancel(*c, "alice");
  b.ledger.retry(*c, {1}, {});
  EXPECT_EQ(c->state, JobState::Running);
  EXPECT_TRUE(
      b.ledger.scheduler().work_left_for("w9", [](const std::string& id) { return id == "j2"; }));
  b.ledger.set_state(*c, JobState::Completed, "");
  EXPECT_THROW(b.ledger.retry(*c, {1}, {}), std::logic_error);
  EXPECT_EQ(c->state, JobState::Completed);
}

// Requeue: a running job's frame renders again from scratch: its leases in flight end (their
// attempts "not needed", their renewals Ended, their rows gone), its tasks are queued afresh, and
// the job's failure counts start afresh (history kept). A completed job runs again with its other
// frames done; a failed one with its other unfinished frames held. The versions text and a
// released pin are stored.
TEST(Ledger, RequeueRendersFramesAgainFromScratch) {
  Bench b;
  auto job = make_job("j1", 2, 1);  // frames 1-2, 4 tasks each
  b.store.write(store::InsertJob{{"j1", 1, JobSpec{}, int(JobState::Queued), "", 0, 0, "", ""}});
  b.ledger.add_job(*job);
  b.ledger.set_state(*job, JobState::Running, "");
  std::vector<Lease> frame1;
  for (int i = 0; i < 4; ++i) {
    std::optional<Lease> l = b.ledger.lease("w0", b.now, {});
    ASSERT_TRUE(l);
    ASSERT_EQ(l->task.frame, 1);
    frame1.push_back(*l);
  }
  b.ledger.complete(*job, frame1[0].lease_id, frame1[0].task, "w0", 1, "B", "K", b.now);
  std::optional<Lease> f = b.ledger.lease("w1", b.now, {});  // frame 2: fails on w1
  ASSERT_TRUE(f);
  Journal::Ticket t = 0;
  b.ledger.fail(f->lease_id, "w1", "crash", false, b.now, &t);
  b.flush();
  ASSERT_EQ(b.store.failures("j1").size(), 1u);

  b.ledger.requeue(*job, {1}, {}, "V1", false);
  b.flush();
  EXPECT_EQ(job->state, JobState::Running);
  for (size_t i = 1; i < 4; ++i)
    EXPECT_EQ(b.ledger.renew(frame1[i].lease_id, b.now), LeaseOutcome::Ended) << "it ended";
  EXPECT_TRUE(b.store.leases("j1").size() <= 1u) << "frame 1's lease rows are gone";
  for (const StoredLease& l : b.store.leases("j1")) EXPECT_NE(l.frame, 1);
  bool more = false;
  int not_needed = 0;
  for (const StoredAttempt& a : b.store.attempts("j1", 1, std::nullopt, 100, &more))
    not_needed += a.outcome == AttemptOutcome::NotNeeded && a.message == "its frame was requeued";
  EXPECT_EQ(not_needed, 3);
  EXPECT_TRUE(b.store.failures("j1").empty()) << "the counts start afresh";
  EXPECT_EQ(b.store.failure_history("j1").size(), 1u) << "the history is kept";
  EXPECT_EQ(b.store.jobs()[0].versions, "V1");
  std::set<uint32_t> tiles;  // all four of frame 1's pass-0 tasks again, the done one included
  for (int i = 0; i < 4; ++i) {
    std::optional<Lease> l = b.ledger.lease("w0", b.now, {});
    ASSERT_TRUE(l);
    ASSERT_EQ(l->task.frame, 1);
    tiles.insert(l->task.tile);
    b.ledger.complete(*job, l->lease_id, l->task, "w0", 1, "B", "K", b.now);
  }
  EXPECT_EQ(tiles.size(), 4u);
  for (int i = 0; i < 4; ++i) {  // frame 2
    std::optional<Lease> l = b.ledger.lease("w0", b.now, {});
    ASSERT_TRUE(l);
    b.ledger.complete(*job, l->lease_id, l->task, "w0", 1, "B", "K", b.now);
  }
  b.ledger.set_state(*job, JobState::Completed, "");

  // Completed -> Running: only the named frame is leased; the pin goes when asked.
  b.ledger.requeue(*job, {2}, {}, "V2", true);
  b.flush();
  EXPECT_EQ(job->state, JobState::Running);
  EXPECT_EQ(job->build_id, "");
  EXPECT_EQ(b.store.jobs()[0].state, int(JobState::Running));
  EXPECT_EQ(b.store.jobs()[0].build_id, "");
  EXPECT_EQ(b.store.jobs()[0].versions, "V2");
  for (int i = 0; i < 4; ++i) {
    std::optional<Lease> l = b.ledger.lease("w5", b.now, {});
    ASSERT_TRUE(l);
    EXPECT_EQ(l->task.frame, 2);
  }
  EXPECT_FALSE(b.ledger.lease("w5", b.now, {})) << "frame 1 stays done";

  // Failed -> Running, the other unfinished frame held.
  auto g = make_job("j2", 2, 1);
  b.ledger.add_job(*g);
  b.ledger.set_state(*g, JobState::Failed, "broken scene");
  b.ledger.requeue(*g, {2}, {1}, "", false);
  b.flush();
  EXPECT_EQ(g->state, JobState::Running);
  EXPECT_EQ(g->error, "");
  for (int i = 0; i < 4; ++i) {
    std::optional<Lease> l =
        b.ledger.lease("w6", b.now, [](const std::string& id) { return id == "j2"; });
    ASSERT_TRUE(l);
    EXPECT_EQ(l->task.frame, 2);
  }
  EXPECT_FALSE(b.ledger.lease("w6", b.now, [](const std::string& id) { return id == "j2"; }))
      << "frame 1 is held";
}

// Delete, from any state: the scheduler forgets the job (its leases are retired: renewing one
// answers Ended), its events, attempts and lease rows go, and its row stays unlisted so that the
// next sequence number passes it.
TEST(Ledger, DeleteForgetsTheJobAndItsRowsButNotItsId) {
  Bench b;
  auto job = make_job("j1");
  b.store.write(store::InsertJob{{"j1", 1, JobSpec{}, int(JobState::Queued), "", 0, 0, "", ""}});
  b.ledger.add_job(*job);
  std::optional<Lease> l = b.ledger.lease("w1", b.now, {});
  ASSERT_TRUE(l);
  Journal::Ticket t = 0;
  b.ledger.fail(l->lease_id, "w1", "crash", false, b.now, &t);
  std::optional<Lease> live = b.ledger.lease("w2", b.now, {});
  ASSERT_TRUE(live);
  b.flush();
  bool more = false;
  ASSERT_EQ(b.store.attempts("j1", std::nullopt, std::nullopt, 10, &more).size(), 1u);
  b.ledger.delete_job(*job);
  b.flush();
  EXPECT_FALSE(b.ledger.lease("w3", b.now, {})) << "nothing of it is leased";
  EXPECT_EQ(b.ledger.renew(live->lease_id, b.now), LeaseOutcome::Ended);
  EXPECT_TRUE(b.store.jobs().empty());
  EXPECT_EQ(b.store.next_seq(), 2u) << "its id is not given again";
  EXPECT_TRUE(b.store.failure_history("j1").empty());
  EXPECT_TRUE(b.store.leases("j1").empty());
  EXPECT_TRUE(b.store.attempts("j1", std::nullopt, std::nullopt, 10, &more).empty());
  EXPECT_FALSE(b.ledger.scheduler().work_left_for("w3"));
}

// A task: leased, then done (one event, the core seconds, the build pinned once); a second
// result needs nothing stored but its attempt; refused, failed and held tasks go back to the queue
// (held ones to another worker), a failure and a refusal are stored; a frame's stop ends its
// tasks. Every lease that ends leaves its attempt's record (worker, times, outcome, reason, log)
// in that order, a lease a frame's stop ended included.
TEST(Ledger, TaskTransitionsAndTheirRows) {
  Bench b;
  auto job = make_job("j1", 1, 2);  // 8 tasks
  b.store.write(store::InsertJob{{"j1", 1, JobSpec{}, int(JobState::Queued), "", 0, 0, "", ""}});
  b.ledger.add_job(*job);
  std::optional<Lease> a = b.ledger.lease("w1", b.now, {});
  ASSERT_TRUE(a);
  b.now = 5;
  b.ledger.complete(*job, a->lease_id, a->task, "w1", 1.5, "build-1", "K", b.now,
                    {"info: rendered"});
  EXPECT_TRUE(b.ledger.scheduler().settled(a->task));
  EXPECT_EQ(job->build_id, "build-1");
  std::optional<Lease> c = b.ledger.lease("w1", b.now, {});
  b.ledger.complete(*job, c->lease_id, c->task, "w1", 2.5, "build-1", "K", b.now);
  b.flush();
  EXPECT_EQ(b.store.tasks_done("j1"), 2u);
  EXPECT_EQ(b.store.jobs()[0].core_seconds, 4.0);
  EXPECT_EQ(b.store.jobs()[0].build_id, "build-1");
  EXPECT_EQ(job->core_seconds, 4.0);

  // Refused: queued again, at once, for anyone; counted against w2.
  std::optional<Lease> r = b.ledger.lease("w2", b.now, {});
  b.ledger.refuse_result("w2", r->lease_id, r->task, "NaN", b.now);
  EXPECT_EQ(b.ledger.renew(r->lease_id, b.now), LeaseOutcome::Ended);
  std::optional<Lease> again = b.ledger.lease("w3", b.now, {});
  EXPECT_EQ(again->task, r->task);
  // Failed: queued again; its event stored under the worker.
  Journal::Ticket t = 0;
  EXPECT_EQ(
      b.ledger.fail(again->lease_id, "w3", "out of memory", false, b.now, &t, {"error: bad_alloc"}),
      LeaseOutcome::Ok);
  EXPECT_EQ(b.ledger.fail(again->lease_id, "w3", "twice", false, b.now, &t), LeaseOutcome::Ended);
  // Held for verification: it goes to another worker than w4.
  std::optional<Lease> h = b.ledger.lease("w4", b.now, {});
  EXPECT_EQ(h->task, r->task);
  b.ledger.hold_for_verification(h->lease_id, b.now);
  std::optional<Lease> other = b.ledger.lease("w4", b.now, {});
  ASSERT_TRUE(other);
  EXPECT_FALSE(other->task == r->task) << "w4 may not verify its own result";
  // Not needed (another result of it being stored, or merged already, or beyond its frame's
  // stop): the lease ends, with only its attempt stored; the task is not done by it.
  b.ledger.not_needed(other->lease_id, other->task, "w4", b.now);
  EXPECT_EQ(b.ledger.renew(other->lease_id, b.now), LeaseOutcome::Ended);
  EXPECT_FALSE(b.ledger.scheduler().settled(other->task));
  b.flush();
  EXPECT_EQ(b.store.refused_workers("j1"), std::vector<std::string>{"w2"});
  ASSERT_EQ(b.store.failures("j1").size(), 1u);
  EXPECT_EQ(b.store.failures("j1")[0].message, "out of memory");
  EXPECT_EQ(b.store.tasks_done("j1"), 2u);

  // The frame needs no pass from 0 on: every task stopped, the lease rows dropped once.
  std::optional<Lease> live = b.ledger.lease("w5", b.now, {});
  ASSERT_TRUE(live);
  b.ledger.frame_done(*job, *job->frames[0], 0);
  EXPECT_TRUE(job->frames[0]->leases_dropped);
  b.flush();
  EXPECT_TRUE(b.store.leases("j1").empty());
  EXPECT_FALSE(b.ledger.lease("w9", b.now, {}));
  EXPECT_TRUE(b.ledger.scheduler().settled(other->task));

  bool more = true;
  std::vector<StoredAttempt> log = b.store.attempts("j1", std::nullopt, std::nullopt, 100, &more);
  EXPECT_FALSE(more);
  std::vector<std::pair<AttemptOutcome, std::string>> want{
      {AttemptOutcome::Done, "w1"},     {AttemptOutcome::Done, "w1"},
      {AttemptOutcome::Refused, "w2"},  {AttemptOutcome::Failed, "w3"},
      {AttemptOutcome::Held, "w4"},     {AttemptOutcome::NotNeeded, "w4"},
      {AttemptOutcome::NotNeeded, "w5"}};
  ASSERT_EQ(log.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(log[i].outcome, want[i].first) << i << ": " << attempt_outcome_name(log[i].outcome);
    EXPECT_EQ(log[i].worker_id, want[i].second) << i;
  }
  EXPECT_EQ(log[0].log, std::vector<std::string>{"info: rendered"});
  EXPECT_EQ(log[0].started_unix, 0) << "leased at 0 on a clock whose Unix offset is 0";
  EXPECT_EQ(log[0].ended_unix, 5);
  EXPECT_EQ(log[2].message, "NaN");
  EXPECT_EQ(log[3].message, "out of memory");
  EXPECT_EQ(log[3].log, std::vector<std::string>{"error: bad_alloc"});
  EXPECT_EQ(log[6].message, "its frame needs no more passes");
  // One task's, the most recent first cut by the limit.
  log = b.store.attempts("j1", std::nullopt, r->task, 2, &more);
  EXPECT_TRUE(more) << "four attempts of the task: refused, failed, held, stopped (w5's)";
  ASSERT_EQ(log.size(), 2u);
  EXPECT_EQ(log[0].outcome, AttemptOutcome::Held);
  EXPECT_EQ(log[1].outcome, AttemptOutcome::NotNeeded);
  EXPECT_EQ(log[1].worker_id, "w5");
}

// A result not merged never settles its task. The soak lost tasks this way: a stalled worker's
// lease expired, the task went to a second worker, and the first one's late result, arriving
// while the second's was being stored, was "not needed" and marked the task done; the stored
// result then found its task settled and was not merged either, and the frame never completed.
TEST(Ledger, AResultNotMergedLeavesItsTaskToTheResultThatIs) {
  Bench b;
  auto job = make_job("j1", 1, 1);
  b.store.write(store::InsertJob{{"j1", 1, JobSpec{}, int(JobState::Queued), "", 0, 0, "", ""}});
  b.ledger.add_job(*job);
  std::optional<Lease> first = b.ledger.lease("w1", b.now, {});
  ASSERT_TRUE(first);
  b.now += 100;  // w1 stalls past its lease: the task is queued again and goes to w2
  std::optional<Lease> second = b.ledger.lease("w2", b.now, {});
  ASSERT_TRUE(second);
  ASSERT_EQ(second->task, first->task);
  // w1's late result is not merged (w2's is being stored): the expired lease is retired ...
  b.ledger.not_needed(first->lease_id, first->task, "w1", b.now);
  EXPECT_FALSE(b.ledger.scheduler().settled(first->task));
  EXPECT_EQ(b.ledger.renew(second->lease_id, b.now), LeaseOutcome::Ok) << "w2's lease lives on";
  // ... and a live one (two results racing with the lease still held).
  std::optional<Lease> third = b.ledger.lease("w3", b.now, {});
  ASSERT_TRUE(third);
  EXPECT_FALSE(third->task == first->task) << "leased to w2 still";
  b.ledger.not_needed(second->lease_id, second->task, "w2", b.now);
  EXPECT_FALSE(b.ledger.scheduler().settled(second->task));
  std::optional<Lease> again = b.ledger.lease("w4", b.now, {});
  ASSERT_TRUE(again) << "no live lease left: the task is queued again";
  EXPECT_EQ(again->task, first->task);
  // The result that is merged settles it.
  b.ledger.complete(*job, again->lease_id, again->task, "w4", 1, "build-1", "K", b.now);
  EXPECT_TRUE(b.ledger.scheduler().settled(first->task));
}

// Restoring: an ended job's tasks are not queued; a running job's trail counts as before.
TEST(Ledger, RestoringCountsTheTrail) {
  Bench b;
  auto ended = make_job("j1");
  ended->state = JobState::Completed;
  b.ledger.restore_job(*ended, {});
  EXPECT_FALSE(b.ledger.lease("w", b.now, {}));
  auto job = make_job("j2");
  Ledger::Trail trail;
  trail.failures = {{1, 0, 0, "a", "x"}, {1, 0, 0, "b", "y"}, {1, 0, 0, "c", "z"}};
  b.ledger.restore_job(*job, trail);
  EXPECT_TRUE(b.ledger.scheduler().job_failed("j2")) << "failed on 3 workers before the restart";
}

// The journal stores appended writes in order, many calls' writes in one batch while the store
// is busy (group commit), and wait() says when a ticket is stored.
TEST(Journal, AppendedWritesAreStoredInOrderAndGrouped) {
  TestStore store;
  store.delay_ms = 20;
  Journal journal(store);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (uint32_t i = 0; i < 50; ++i)
        journal.append({store::TaskEvent{"j" + std::to_string(t), 0, i, 0, "w",
                                         TaskEventKind::Failed, std::to_string(i)}});
    });
  for (auto& t : threads) t.join();
  ASSERT_TRUE(journal.wait(journal.append({}), 30));
  for (int t = 0; t < 4; ++t) {
    std::vector<TaskFailure> f = store.failures("j" + std::to_string(t));
    ASSERT_EQ(f.size(), 50u);
    for (uint32_t i = 0; i < 50; ++i) EXPECT_EQ(f[i].pass, i) << "in the order appended";
  }
  EXPECT_LT(journal.batches(), 50u) << "200 appends, grouped while the store was busy";
  EXPECT_TRUE(journal.problem().empty());
}

// A store that refuses: appended writes are kept and retried (wait() runs out, problem() says
// why, the listener hears it), and stored once it takes them; a write ahead is refused and
// dropped; one queued behind a refused batch gives up after its timeout and is never written.
TEST(Journal, RefusedWritesAreRetriedOrDroppedAsTheirKindSays) {
  TestStore store;
  std::vector<std::string> heard;
  std::mutex heard_mu;
  Journal journal(store, [&](const std::string& p) {
    std::lock_guard lock(heard_mu);
    heard.push_back(p);
  });
  store.failing = true;
  EXPECT_THROW(journal.write_ahead({store::InsertWorker{{"w1", "p", "", ""}}}), StoreError);
  Journal::Ticket t = journal.append({store::InsertWorker{{"w2", "p", "", ""}}});
  EXPECT_FALSE(journal.wait(t, 0.5));
  EXPECT_NE(journal.problem().find("disk full"), std::string::npos);
  EXPECT_THROW(journal.write_ahead({store::InsertWorker{{"w3", "p", "", ""}}}, 0.3), StoreError);
  store.failing = false;
  EXPECT_TRUE(journal.wait(t, 10));
  EXPECT_TRUE(journal.problem().empty());
  std::vector<StoredWorker> w = store.workers();
  ASSERT_EQ(w.size(), 1u);
  EXPECT_EQ(w[0].id, "w2") << "w1 was refused, w3 given up on: neither is stored";
  std::lock_guard lock(heard_mu);
  ASSERT_GE(heard.size(), 2u);
  EXPECT_NE(heard.front().find("disk full"), std::string::npos);
  EXPECT_EQ(heard.back(), "") << "told when writes work again";
}

// A coordinator on a store that is slow to take writes: leases answer without waiting for it
// (no disk write under the lock leases take), while a result is acknowledged only once its
// record is stored.
TEST(Ledger, LeasesDoNotWaitForTheDiskAndResultsWaitForTheirRecord) {
  auto store = std::make_shared<TestStore>();
  std::string dir = test::make_temp_dir("ledger-slow");
  CoreOptions o;
  o.state_dir = dir + "/state";
  o.scene_checker = in_process_scene_checker();
  o.store = store;
  o.lease_seconds = 30;
  Coordinator core(o);
  std::string scene = test::source_dir() + "/scenes/cornell-box/scene.json";
  JobSpec spec;
  spec.scene_path = "scene.json";
  spec.files = bundle_of_scene(scene);
  for (const BundleEntry& f : spec.files)
    core.put_blob(read_file_bytes((std::filesystem::path(scene).parent_path() / f.path).string()));
  spec.overrides.width = 16;
  spec.overrides.height = 16;
  spec.overrides.spp = 4;
  spec.overrides.passes = 1;
  spec.tile_size = 8;
  core.submit(spec);
  std::string w = core.register_worker({"w", 1, build_id(), "test"}).worker_id;
  std::optional<TaskAssignment> first = core.lease(w).task;
  ASSERT_TRUE(first);

  store->close_gate();  // every write now waits at the gate
  auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < 3; ++i) ASSERT_TRUE(core.lease(w).task);
  double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_LT(took, 1.0) << "leases waited for the store";

  Scene s = load_scene(scene, first->overrides);
  SampleBuffer b(frame_header(s, first->task.frame, PassSet::range(0, 1)), first->rect, false);
  for (int y = first->rect.y0; y < first->rect.y1(); ++y)
    for (int x = first->rect.x0; x < first->rect.x1(); ++x)
      for (int k = 0; k < 4; ++k) b.add_sample(x, y, RGB(1.0f));
  b.finish_pass();
  auto done = std::async(std::launch::async, [&] {
    return core.complete({w, first->lease_id, first->task, encode_buffer(b)});
  });
  EXPECT_EQ(done.wait_for(std::chrono::milliseconds(500)), std::future_status::timeout)
      << "the result was acknowledged before its record was stored";
  store->open_gate();
  EXPECT_TRUE(done.get());
}

}  // namespace
}  // namespace rf
