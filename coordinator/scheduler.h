// Task scheduling and leases (DESIGN.md "Work units", "Coordinator"), as plain logic with an
// explicit clock so it is tested without servers or sleeps. The coordinator's core (core.h)
// drives it beside the SQLite store; it knows nothing of either, nor of gRPC.
//
// Order: jobs by priority (higher first), then fair share between equal priorities (FairShare),
// then submission, paused jobs left out; within a job, a
// window of at most `window_frames` unfinished frames is open; within the window, passes in order
// (all tiles of pass 0 of every open frame before pass 1), then the frame this worker was last
// leased in the job (frame affinity: its renderer holds that frame's BVH of moving geometry), then
// frame, then tile. Leases: a task leased to a worker must be renewed within lease_seconds or it is
// queued again. The first completion of a task wins, from whichever lease (an expired one
// included): later ones are answered accepted = false, and the task's other leases end. A task that
// fails on max_failures different workers fails its job; a worker that fails max_failures tasks of
// a job gets no more of them. A task handed back (worker shutting down) is re-queued without
// counting.
//
// Memory is bounded by what is in flight, not by the job's size: a task exists as its number
// in its frame (pass * tiles + tile) until it is handed out; a frame holds one bit per task
// while it is open; tasks with leases, failures or held results have a record, and records and
// leases go when their task is done, its pass is stopped or its job ends. A lease id of this
// run whose record is gone is "retired": it ended and its task needs nothing more from it.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "engine/frame.h"
#include "farm/job.h"  // TaskRef

namespace rf {

// How workers are shared between jobs of equal priority (docs/farm.md "Fair share"): each lease
// goes to the job whose tenant holds the fewest live leases, then to that tenant's job holding the
// fewest (Tenants); to the job holding the fewest (Jobs); or to the earliest submitted (None:
// strict submission order, one job at a time). Ties go to the earlier job.
enum class FairShare { Tenants, Jobs, None };

struct SchedulerOptions {
  double lease_seconds = 30;
  int max_failures = 3;
  uint32_t window_frames = 4;
  std::string lease_prefix = "L";  // lease ids are prefix + a counter: unique per coordinator run
  FairShare share = FairShare::Tenants;
  // Called when a lease ends for want of renewal (how a crashed, stalled or cut-off worker is
  // noticed), with the lease, its worker and its task.
  std::function<void(const std::string& lease_id, const std::string& worker_id,
                     const TaskRef& task)>
      on_expired;
};

struct Lease {
  std::string lease_id;
  TaskRef task;
  double expires_at = 0;
};

enum class LeaseOutcome { Ok, NotFound, Ended };
enum class CompleteOutcome { Accepted, Duplicate, NotFound };

class Scheduler {
 public:
  explicit Scheduler(SchedulerOptions options = {}) : options_(options) {}

  // A job of `frames` (in order), each split into `tiles` x `passes` tasks, of `tenant`.
  void add_job(const std::string& job_id, const std::vector<FrameNumber>& frames, uint32_t tiles,
               uint32_t passes, int priority, const std::string& tenant = "");
  void cancel_job(const std::string& job_id);  // drops its queued tasks and ends its leases
  void remove_job(const std::string& job_id);  // forgets it (deleted): its tasks, leases, counts
  // A failed or cancelled job runs again (`retry`): its failure counts (per task and per worker)
  // start afresh and every frame's tasks are queued (the caller marks the done ones, mark_done,
  // and stops the frames that need none, stop_frame); its order, tenant, priority and pause stay.
  void reopen_job(const std::string& job_id);
  // A frame that was stopped (stop_frame) needs all its tasks again; the caller marks the done
  // ones. Its task records and their leases go.
  void reopen_frame(const std::string& job_id, FrameNumber frame);
  // The job's failure counts (per task and per worker) start afresh (`requeue`); its tasks,
  // leases and ended leases stay.
  void forget_failures(const std::string& job_id);
  // A paused job gets no new leases; its leases in flight run on, and their results are taken.
  // Its tasks still count as work left (work_left_for): a pause is not an end.
  void set_paused(const std::string& job_id, bool paused);
  void set_priority(const std::string& job_id, int priority);

  // Which jobs a worker may get tasks of (all when empty).
  using JobFilter = std::function<bool(const std::string& job_id)>;
  // The next task for a worker, or nothing. Expires overdue leases first.
  std::optional<Lease> lease(const std::string& worker_id, double now, const JobFilter& may = {});
  LeaseOutcome renew(const std::string& lease_id, double now);
  // A result arrived for this lease (the caller merges it only on Accepted).
  CompleteOutcome complete(const std::string& lease_id, double now);
  // The same, for a result whose lease this scheduler does not know (issued before a coordinator
  // restart): it is identified by its task. Results are deterministic, so it counts the same.
  CompleteOutcome complete(const std::string& lease_id, const TaskRef& task, double now);
  // A result arrived for this lease and is not merged (another result of its task is being
  // stored, or was merged, or the task is past its frame's stop): the lease ends, the task stays
  // as it is. Never marks the task done: a result that is not merged must not settle it. A task
  // left with no live lease and not done goes back to the queue.
  void release(const std::string& lease_id, const TaskRef& task, double now);
  // Restoring from checkpoints: the task's result is already merged or stored.
  void mark_done(const TaskRef& task);
  // Restoring from checkpoints: passes [0, passes) of the frame are merged.
  void mark_passes_done(const std::string& job_id, FrameNumber frame, uint32_t passes);
  // The task is done or not needed (or its job ended): a result for it would not be merged.
  bool settled(const TaskRef& task) const;
  // A lease id handed out by this scheduler whose record is gone: it ended, and its task is
  // settled. Renewing it answers Ended, completing it Duplicate.
  bool retired(const std::string& lease_id) const;
  std::optional<TaskRef> lease_task(const std::string& lease_id) const;
  std::string lease_worker(const std::string& lease_id) const;  // "" for an unknown lease
  // A lease as handed out (live or ended, while its record is kept), for its attempt's record.
  struct LeaseInfo {
    std::string lease_id;
    TaskRef task;
    std::string worker_id;
    double leased_at = -1;  // on the scheduler's clock; < 0: before a restart
  };
  std::optional<LeaseInfo> lease_info(const std::string& lease_id) const;
  // The live leases of a job (of one frame from pass `first_pass` on, when given).
  std::vector<LeaseInfo> live_leases(const std::string& job_id,
                                     std::optional<FrameNumber> frame = std::nullopt,
                                     uint32_t first_pass = 0) const;
  // Restoring from the job store: a lease handed out before a restart, ended (its task is
  // queued again), so that its holder's late result is recognised.
  void restore_lease(const std::string& lease_id, const TaskRef& task,
                     const std::string& worker_id);
  // Restoring from the job store: a failure recorded before a restart counts as before.
  void restore_failure(const TaskRef& task, const std::string& worker_id,
                       const std::string& message);
  // The worker could not render the task (or, handed_back, will not: it is shutting down).
  LeaseOutcome fail(const std::string& lease_id, const std::string& message, bool handed_back,
                    double now);
  // A result sent under this lease was refused (it did not match its task): the lease ends, the
  // task is queued again, and the refusal counts against the lease's worker in the job (toward
  // giving it no more of the job's tasks), never against the task or the job.
  void refuse_result(const std::string& lease_id, double now);
  // Restoring from the job store: a refused result recorded before a restart counts as before.
  void restore_refusal(const std::string& job_id, const std::string& worker_id);
  // A result sent under this lease is held until another worker's agrees (verification): the
  // lease ends and the task is queued again for any worker but those that sent one.
  void verify_again(const std::string& lease_id, double now);
  // The frame needs no more passes from `first_unneeded_pass` on (noise target met, or done):
  // those tasks leave the queue, their leases end, and the frame's window slot frees when no
  // needed task remains.
  void stop_frame(const std::string& job_id, FrameNumber frame, uint32_t first_unneeded_pass);

  bool job_failed(const std::string& job_id) const;
  std::string job_error(const std::string& job_id) const;  // the failing workers' messages
  // The jobs of the live leases held by workers for which `whose` is true.
  std::set<std::string> leased_jobs(
      const std::function<bool(const std::string& worker_id)>& whose) const;
  // Workers holding a live lease.
  std::set<std::string> workers_with_live_leases() const;
  // A worker gone for good (its registration forgotten): its frame affinity in every job. Its
  // failure counts stay (they bar nobody who can come back, and fail jobs by their number).
  void forget_worker(const std::string& worker_id);
  // A worker's live leases' tasks, and its failures and refused results in jobs not ended.
  std::vector<TaskRef> leased_to(const std::string& worker_id) const;
  int failures_of(const std::string& worker_id) const;
  // Queued or leased tasks this worker could still get (for --exit-when-idle).
  bool work_left_for(const std::string& worker_id, const JobFilter& may = {}) const;
  size_t queued_tasks() const;
  // Per job (failed and cancelled ones left out): tasks waiting, and live leases.
  struct JobLoad {
    uint64_t queued = 0, leased = 0;
  };
  std::map<std::string, JobLoad> load_by_job() const;
  // Records held (tasks with leases, failures or exclusions; leases): for tests of the bound.
  size_t task_records() const { return tasks_.size(); }
  size_t lease_records() const { return leases_.size(); }
  size_t affinity_records() const {  // (job, worker) frame affinities
    size_t n = 0;
    for (const auto& [id, j] : jobs_) n += j.worker_frame.size();
    return n;
  }

 private:
  struct TaskState {  // only for tasks with something to remember
    std::set<std::string> failed_workers;
    std::vector<std::string> messages;
    std::set<std::string> leases;    // live leases of this task
    std::set<std::string> ended;     // its ended leases, kept for their holders' late results
    std::set<std::string> excluded;  // workers that sent a result held for verification
  };
  struct FrameState {
    FrameNumber frame;
    uint32_t passes_needed;  // tasks of passes >= this are not needed
    uint64_t open_tasks;     // needed tasks not done
    // Tasks numbered >= fresh (number = pass * tiles + tile) were never handed out: they wait
    // in number order unless done (restored from a checkpoint; done_ahead counts those).
    uint64_t fresh = 0, done_ahead = 0;
    std::vector<bool> done;      // by number, while the frame is open and has a done task
    std::set<uint64_t> waiting;  // numbered below fresh, queued again
  };
  struct JobState {
    std::string id, tenant;
    int priority = 0;
    uint64_t order = 0;
    uint32_t tiles = 0, passes = 0;
    std::vector<FrameState> frames;
    std::map<FrameNumber, size_t> frame_index;  // frame number -> position in frames
    std::map<std::string, int> worker_failures;
    std::map<std::string, FrameNumber> worker_frame;  // the frame each worker was last leased
    bool failed = false, cancelled = false, paused = false;
    std::string error;
    uint64_t live_leases = 0;  // its fair share's measure
  };
  struct LeaseState {
    TaskRef task;
    std::string worker_id;
    double expires_at;
    bool live;
    double leased_at = -1;  // < 0: unknown (restored from before a restart)
  };

  void expire(double now);
  void end_lease(const std::string& lease_id, LeaseState& lease);  // ends it if live
  void count_live(const TaskRef& task, int delta);  // a live lease began (+1) or ended (-1)
  // Queues the task again when it is still needed and no live lease holds it.
  void requeue_if_needed(const TaskRef& task);
  CompleteOutcome complete_task(const TaskRef& ref);
  // Counts a failure of `ref` on `worker_id`; true if it failed the job.
  bool count_failure(const TaskRef& ref, const std::string& worker_id, const std::string& message);
  void drop_job_tasks(JobState& j);
  // Ends the task's leases and forgets them and the task's record.
  void forget_task(const TaskRef& ref);
  // Forgets every task record (and its leases) of the frame from pass `first_pass` on.
  void forget_tasks_from(const JobState& j, FrameNumber frame, uint32_t first_pass);
  bool needed(const JobState& j, const FrameState& f, uint32_t pass) const;
  bool is_done(const FrameState& f, uint64_t number) const;
  // The frame's first task this worker may get, as its number, or none.
  std::optional<uint64_t> first_for(const JobState& j, FrameState& f, const std::string& worker_id);
  bool excluded(const TaskRef& ref, const std::string& worker_id) const;
  uint64_t queued_in(const JobState& j, const FrameState& f) const;
  JobState* job(const std::string& id);
  const JobState* job(const std::string& id) const;
  FrameState* frame_of(JobState& j, FrameNumber frame);
  const FrameState* frame_of(const JobState& j, FrameNumber frame) const;
  // The task's job and frame, if the task is one of a known job's.
  std::pair<JobState*, FrameState*> locate(const TaskRef& ref);
  std::pair<const JobState*, const FrameState*> locate(const TaskRef& ref) const;

  SchedulerOptions options_;
  std::map<std::string, JobState> jobs_;
  std::map<TaskRef, TaskState> tasks_;
  std::map<std::string, LeaseState> leases_;
  std::set<std::pair<double, std::string>> expiry_;  // live leases by expiry time
  std::map<std::string, uint64_t> tenant_leases_;    // live leases per tenant
  uint64_t next_order_ = 0, next_lease_ = 0;
};

}  // namespace rf
