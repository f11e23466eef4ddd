// Task order, leases, late results, failures and hand-backs, on an explicit clock.
#include <gtest/gtest.h>

#include <cstdio>
#include <functional>
#include <map>
#include <queue>

#include "coordinator/scheduler.h"

namespace rf {
namespace {

TEST(Scheduler, PassZeroOfEveryOpenFrameFirstThenWindowMoves) {
  Scheduler s({30, 3, 2});
  s.add_job("j", {1, 2, 3}, /*tiles=*/2, /*passes=*/2, 0);
  std::vector<std::tuple<uint32_t, uint32_t, uint32_t>> got;  // (frame, pass, tile)
  for (int i = 0; i < 8; ++i) {
    auto l = s.lease("w", 0);
    ASSERT_TRUE(l);
    got.emplace_back(l->task.frame, l->task.pass, l->task.tile);
    EXPECT_EQ(s.complete(l->lease_id, 0), CompleteOutcome::Accepted);
  }
  // Window of 2 frames: frames 1 and 2, all of pass 0 before pass 1 (pass 1 of frame 2 first:
  // the worker holds it); frame 3 only once one closes.
  std::vector<std::tuple<uint32_t, uint32_t, uint32_t>> want = {
      {1, 0, 0}, {1, 0, 1}, {2, 0, 0}, {2, 0, 1}, {2, 1, 0}, {2, 1, 1}, {3, 0, 0}, {3, 0, 1}};
  EXPECT_EQ(got, want);
}

// Frame affinity: within a pass, a worker gets the frame it was last leased in the job (its
// renderer holds that frame's BVH of moving geometry) before the window's order; passes still go
// in order for everyone.
TEST(Scheduler, AWorkerKeepsItsFrameWithinAPass) {
  Scheduler s({30, 3, 2});
  s.add_job("j", {1, 2}, /*tiles=*/2, /*passes=*/3, 0);
  auto lease = [&](const char* w) {
    auto l = s.lease(w, 0);
    EXPECT_TRUE(l);
    EXPECT_EQ(s.complete(l->lease_id, 0), CompleteOutcome::Accepted);
    return std::make_tuple(l->task.frame, l->task.pass, l->task.tile);
  };
  using T = std::tuple<uint32_t, uint32_t, uint32_t>;
  EXPECT_EQ(lease("a"), T(1, 0, 0));
  EXPECT_EQ(lease("b"), T(1, 0, 1));
  EXPECT_EQ(lease("b"), T(2, 0, 0));  // frame 1's pass 0 is out: b moves on
  EXPECT_EQ(lease("a"), T(2, 0, 1));  // pass 0 before a's frame 1 of pass 1
  EXPECT_EQ(lease("a"), T(2, 1, 0));  // a holds frame 2 now
  EXPECT_EQ(lease("b"), T(2, 1, 1));  // and so does b
  EXPECT_EQ(lease("b"), T(1, 1, 0));
  EXPECT_EQ(lease("a"), T(1, 1, 1));  // pass 1 before a's frame 2 of pass 2
  EXPECT_EQ(lease("b"), T(1, 2, 0));  // b holds frame 1
  EXPECT_EQ(lease("a"), T(1, 2, 1));
  EXPECT_EQ(lease("a"), T(2, 2, 0));
}

// Workers on the scheduler's clock: each takes `task_seconds` per task and leases the next one at
// once (a worker that gets nothing asks again a quarter second later); they start task_seconds /
// n apart, as a farm's do. `arrive` is called once at time `at` (a job submitted then), `done`
// for every completed task with the time it completed. Runs until `until`.
struct Workers {
  Scheduler& s;
  int n = 8;
  double task_seconds = 1;
  void run(double until, double at, const std::function<void()>& arrive,
           const std::function<void(const TaskRef&, double)>& done) {
    using Event = std::pair<double, int>;  // (time, worker)
    std::priority_queue<Event, std::vector<Event>, std::greater<Event>> events;
    std::vector<std::optional<Lease>> held(static_cast<size_t>(n));
    for (int w = 0; w < n; ++w) events.push({w * task_seconds / n, w});
    bool arrived = false;
    while (!events.empty() && events.top().first <= until) {
      auto [t, w] = events.top();
      events.pop();
      if (!arrived && t >= at) arrived = true, arrive();
      if (held[size_t(w)]) {
        EXPECT_EQ(s.complete(held[size_t(w)]->lease_id, t), CompleteOutcome::Accepted);
        done(held[size_t(w)]->task, t);
      }
      held[size_t(w)] = s.lease("w" + std::to_string(w), t);
      events.push({t + (held[size_t(w)] ? task_seconds : 0.25), w});
    }
  }
};

// Fair share (docs/farm.md "Fair share"): a huge job (10,000 one-second tasks) holds all 8
// workers when a small job of 40 tasks of the same priority arrives at t = 10.3. Its fair share
// is half the farm, so its fair-share time is 40 / 4 = 10 s: it must finish within 1.2 times
// that plus one task (13 s of its arrival), whether it is another tenant's (shared by tenant)
// or the same tenant's (then by job). Under strict submission order (FairShare::None) it waits
// for the huge job's 1,250 s: the test's own check that the bound can fail.
TEST(Scheduler, ASmallJobAfterAHugeOneFinishesWithinItsFairShareTime) {
  for (FairShare share : {FairShare::Tenants, FairShare::Jobs, FairShare::None})
    for (const char* tenant : {"other", "same"}) {
      SchedulerOptions o{30, 3, 4};
      o.share = share;
      Scheduler s(o);
      s.add_job("huge", {0, 1, 2, 3, 4, 5, 6, 7, 8, 9}, /*tiles=*/1000, /*passes=*/1, 0, "same");
      const double at = 10.3;
      double finished = -1;
      int small_done = 0;
      Workers{s}.run(
          60, at, [&] { s.add_job("small", {0}, /*tiles=*/40, /*passes=*/1, 0, tenant); },
          [&](const TaskRef& t, double when) {
            if (t.job_id == "small" && ++small_done == 40) finished = when;
          });
      const double fair = 40.0 / (8 / 2), bound = 1.2 * fair + 1;
      if (share == FairShare::None) {
        EXPECT_EQ(finished, -1) << "strict order: the small job waits for the huge one";
        continue;
      }
      ASSERT_GT(finished, 0) << tenant;
      std::printf(
          "share %s, %s tenant: the small job finished %.2f s after it arrived (fair %.0f s, "
          "bound %.0f s)\n",
          share == FairShare::Tenants ? "tenants" : "jobs", tenant, finished - at, fair, bound);
      EXPECT_LE(finished - at, bound) << tenant << " tenant, share " << int(share);
      EXPECT_GE(finished - at, fair - 1) << "no more than its share";
    }
}

// Shared by tenant, a tenant with two jobs and a tenant with one each hold half the workers; shared
// by job, each of the three jobs holds a third.
TEST(Scheduler, TenantsShareFirstThenTheirJobs) {
  for (FairShare share : {FairShare::Tenants, FairShare::Jobs}) {
    SchedulerOptions o{30, 3, 4};
    o.share = share;
    Scheduler s(o);
    s.add_job("a1", {0}, 1000, 1, 0, "a");
    s.add_job("a2", {0}, 1000, 1, 0, "a");
    s.add_job("b", {0}, 1000, 1, 0, "b");
    std::map<std::string, int> held;
    for (int w = 0; w < 12; ++w) ++held[s.lease("w" + std::to_string(w), 0)->task.job_id];
    if (share == FairShare::Tenants) {
      EXPECT_EQ(held["b"], 6);
      EXPECT_EQ(held["a1"] + held["a2"], 6);
      EXPECT_EQ(held["a1"], 3);
    } else {
      EXPECT_EQ(held["a1"], 4);
      EXPECT_EQ(held["a2"], 4);
      EXPECT_EQ(held["b"], 4);
    }
  }
}

TEST(Scheduler, PriorityThenSubmissionOrder) {
  Scheduler s;
  s.add_job("low", {0}, 1, 1, 0);
  s.add_job("high", {0}, 1, 1, 5);
  EXPECT_EQ(s.lease("w", 0)->task.job_id, "high");
  EXPECT_EQ(s.lease("w", 0)->task.job_id, "low");
  EXPECT_FALSE(s.lease("w", 0));
}

TEST(Scheduler, ExpiredLeaseIsQueuedAgainAndLateResultStillCountsOnce) {
  Scheduler s({10, 3, 4});
  s.add_job("j", {0}, 1, 1, 0);
  auto a = s.lease("slow", 0);
  ASSERT_TRUE(a);
  EXPECT_FALSE(s.lease("fast", 5)) << "leased and not expired: nothing to hand out";
  EXPECT_EQ(s.renew(a->lease_id, 8), LeaseOutcome::Ok);  // renewed until 18
  EXPECT_FALSE(s.lease("fast", 15));
  auto b = s.lease("fast", 19);  // expired at 18: queued again
  ASSERT_TRUE(b);
  EXPECT_EQ(s.renew(a->lease_id, 19), LeaseOutcome::Ended) << "FAILED_PRECONDITION for the caller";
  // The late result of the expired lease arrives first: it wins, and the other lease ends.
  EXPECT_EQ(s.complete(a->lease_id, 20), CompleteOutcome::Accepted);
  EXPECT_EQ(s.complete(b->lease_id, 21), CompleteOutcome::Duplicate);
  EXPECT_EQ(s.renew(b->lease_id, 21), LeaseOutcome::Ended);
  EXPECT_EQ(s.complete("nope", 21), CompleteOutcome::NotFound);
  EXPECT_FALSE(s.work_left_for("fast"));
}

TEST(Scheduler, FailsJobAfterThreeDifferentWorkersAndSkipsFailedWorkers) {
  Scheduler s({30, 3, 4});
  s.add_job("j", {0}, 1, 1, 0);
  for (const char* w : {"a", "b"}) {
    auto l = s.lease(w, 0);
    ASSERT_TRUE(l);
    EXPECT_EQ(s.fail(l->lease_id, std::string("boom on ") + w, false, 0), LeaseOutcome::Ok);
    EXPECT_FALSE(s.lease(w, 0)) << "a worker does not get back a task it failed";
  }
  EXPECT_FALSE(s.job_failed("j"));
  auto l = s.lease("c", 0);
  ASSERT_TRUE(l);
  s.fail(l->lease_id, "boom on c", false, 0);
  EXPECT_TRUE(s.job_failed("j"));
  EXPECT_NE(s.job_error("j").find("boom on b"), std::string::npos) << s.job_error("j");
  EXPECT_FALSE(s.lease("d", 0));
}

TEST(Scheduler, HandBackIsNotAFailure) {
  Scheduler s({30, 1, 4});  // one failure would exclude the worker
  s.add_job("j", {0}, 1, 1, 0);
  auto l = s.lease("w", 0);
  EXPECT_EQ(s.fail(l->lease_id, "SIGTERM", /*handed_back=*/true, 1), LeaseOutcome::Ok);
  auto again = s.lease("w", 2);
  ASSERT_TRUE(again) << "re-queued, and the worker is not excluded";
  EXPECT_EQ(again->task, l->task);
}

TEST(Scheduler, StopFrameDropsLaterPassesAndFreesTheWindow) {
  Scheduler s({30, 3, 1});
  s.add_job("j", {7, 8}, 1, 4, 0);
  auto a = s.lease("w", 0);
  EXPECT_EQ(a->task.frame, 7u);
  auto b = s.lease("w", 0);
  EXPECT_EQ(b->task.pass, 1u);
  s.complete(a->lease_id, 0);
  s.stop_frame("j", 7, 1);  // noise target met after pass 0: passes 1.. not needed
  EXPECT_EQ(s.complete(b->lease_id, 1), CompleteOutcome::Duplicate) << "beyond the stop: dropped";
  auto c = s.lease("w", 1);
  ASSERT_TRUE(c);
  EXPECT_EQ(c->task.frame, 8u) << "frame 7 closed, the window moved on";
}

TEST(Scheduler, CancelEndsEverything) {
  Scheduler s;
  s.add_job("j", {0, 1}, 4, 4, 0);
  auto l = s.lease("w", 0);
  s.cancel_job("j");
  EXPECT_EQ(s.renew(l->lease_id, 1), LeaseOutcome::Ended);
  EXPECT_FALSE(s.lease("w", 1));
  EXPECT_EQ(s.queued_tasks(), 0u);
}

// Nor the workers a farm ever had: a worker's frame affinity (one per job it leased in) goes when
// the worker is forgotten or the job ends.
TEST(Scheduler, WorkerRecordsGoWithTheWorkerOrTheJob) {
  Scheduler s({30, 3, 4});
  s.add_job("a", {1, 2}, /*tiles=*/100, /*passes=*/2, 0);
  s.add_job("b", {1}, /*tiles=*/100, /*passes=*/2, 0);
  for (int w = 0; w < 50; ++w) {
    std::optional<Lease> l = s.lease("w" + std::to_string(w), 0);
    ASSERT_TRUE(l);
    EXPECT_EQ(s.complete(l->lease_id, 0), CompleteOutcome::Accepted);
  }
  EXPECT_EQ(s.affinity_records(), 50u) << "one job each (fair share: 25 per job)";
  EXPECT_EQ(s.workers_with_live_leases(), std::set<std::string>{});
  ASSERT_TRUE(s.lease("w0", 0));
  EXPECT_EQ(s.workers_with_live_leases(), std::set<std::string>{"w0"});
  for (int w = 0; w < 10; ++w) s.forget_worker("w" + std::to_string(w));
  EXPECT_EQ(s.affinity_records(), 40u);
  s.cancel_job("a");  // ended (a completed job is ended by the same call)
  s.cancel_job("b");
  EXPECT_EQ(s.affinity_records(), 0u);
}

// Memory follows what is in flight, not the job's size: a job of 100 million tasks is added at
// once, and a task has a record only while it is leased (or remembers a failure or a held
// result). Records and leases go when the task is done, its pass is stopped or its job ends;
// a lease id whose record went is answered as ended.
TEST(Scheduler, TasksExistOnlyWhileInFlight) {
  Scheduler s({30, 3, 4});
  s.add_job("big", {0, 1, 2, 3}, /*tiles=*/1'000'000, /*passes=*/25, 0);  // 10^8 tasks
  EXPECT_EQ(s.queued_tasks(), 100'000'000u);
  EXPECT_EQ(s.task_records(), 0u);
  std::vector<Lease> held;
  for (int i = 0; i < 1000; ++i) held.push_back(*s.lease("w", 0));
  EXPECT_EQ(held[999].task, (TaskRef{"big", 0, 0, 999})) << "pass 0 of frame 0 first";
  EXPECT_EQ(s.task_records(), 1000u);
  EXPECT_EQ(s.lease_records(), 1000u);
  EXPECT_EQ(s.queued_tasks(), 100'000'000u - 1000);
  for (const Lease& l : held) EXPECT_EQ(s.complete(l.lease_id, 1), CompleteOutcome::Accepted);
  EXPECT_EQ(s.task_records(), 0u);
  EXPECT_EQ(s.lease_records(), 0u);
  EXPECT_EQ(s.queued_tasks(), 100'000'000u - 1000);
  EXPECT_EQ(s.renew(held[0].lease_id, 2), LeaseOutcome::Ended) << "retired, not unknown";
  EXPECT_EQ(s.complete(held[0].lease_id, 2), CompleteOutcome::Duplicate);
  EXPECT_EQ(s.fail(held[0].lease_id, "late", false, 2), LeaseOutcome::Ended);
  EXPECT_TRUE(s.retired(held[0].lease_id));
  EXPECT_FALSE(s.retired("L1000000")) << "never handed out";
  EXPECT_FALSE(s.retired("M1"));
  EXPECT_TRUE(s.settled(held[0].task));
  EXPECT_FALSE(s.settled(TaskRef{"big", 0, 0, 999'999}));
  auto expired = s.lease("w", 3);  // expires at 33 and is queued again
  ASSERT_TRUE(expired);
  EXPECT_EQ(expired->task, (TaskRef{"big", 0, 0, 1000}));
  EXPECT_EQ(s.task_records(), 1u);
  EXPECT_EQ(s.lease("v", 40)->task, expired->task) << "expired: first in line again";
  EXPECT_EQ(s.complete(expired->lease_id, 41), CompleteOutcome::Accepted) << "the late result";
  EXPECT_EQ(s.task_records(), 0u);
  EXPECT_EQ(s.lease_records(), 0u) << "both leases of the task went with it";
  s.cancel_job("big");
  EXPECT_EQ(s.queued_tasks(), 0u);
}

TEST(Scheduler, RestoredDoneTasksAndFailuresAmongFreshTasks) {
  Scheduler s({30, 3, 1});
  s.add_job("j", {5}, /*tiles=*/4, /*passes=*/2, 0);
  s.mark_done({"j", 5, 0, 1});
  s.mark_done({"j", 5, 1, 2});
  s.restore_failure({"j", 5, 0, 2}, "w", "boom");
  EXPECT_EQ(s.queued_tasks(), 6u);
  std::vector<TaskRef> got;
  while (auto l = s.lease("w", 0)) got.push_back(l->task);
  // Tile 1 of pass 0 is done, tile 2 failed on w before: w gets the rest in order.
  std::vector<TaskRef> want = {
      {"j", 5, 0, 0}, {"j", 5, 0, 3}, {"j", 5, 1, 0}, {"j", 5, 1, 1}, {"j", 5, 1, 3}};
  EXPECT_EQ(got, want);
  EXPECT_EQ(s.queued_tasks(), 1u) << "tile 2 of pass 0 waits for another worker";
  auto other = s.lease("v", 0);
  ASSERT_TRUE(other);
  EXPECT_EQ(other->task, (TaskRef{"j", 5, 0, 2}));
  s.mark_passes_done("j", 5, 2);
  EXPECT_FALSE(s.work_left_for("w"));
  EXPECT_EQ(s.lease_records(), 0u);
  EXPECT_EQ(s.task_records(), 0u);
}

TEST(Scheduler, StopFrameCountsOnlyTheNeededTasksAsQueued) {
  Scheduler s({30, 3, 4});
  s.add_job("j", {0}, /*tiles=*/3, /*passes=*/4, 0);
  s.mark_done({"j", 0, 3, 0});  // a task of a pass about to be stopped
  s.mark_done({"j", 0, 1, 1});
  EXPECT_EQ(s.queued_tasks(), 10u);
  auto a = s.lease("w", 0);
  s.stop_frame("j", 0, 2);
  EXPECT_EQ(s.queued_tasks(), 4u) << "passes 0 and 1 less the leased and the done task";
  int leased = 0;
  while (auto l = s.lease("w", 0)) {
    EXPECT_LT(l->task.pass, 2u);
    EXPECT_EQ(s.complete(l->lease_id, 0), CompleteOutcome::Accepted);
    ++leased;
  }
  EXPECT_EQ(leased, 4);
  EXPECT_TRUE(s.work_left_for("w")) << "the first lease is still out";
  EXPECT_EQ(s.complete(a->lease_id, 1), CompleteOutcome::Accepted);
  EXPECT_FALSE(s.work_left_for("w"));
}

// Restarts: results of leases issued before a coordinator restart.

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
  EXPECT_EQ(after.complete(old->lease_id, TaskRef{"gone", 0, 0, 0}, 2), CompleteOutcome::NotFound);

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
  s.mark_done({"j", 4, 0, 2});  // twice: no effect
  s.mark_done({"j", 9, 0, 0});  // unknown task: ignored
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
