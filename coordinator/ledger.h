// The task ledger (DESIGN.md "The task ledger"): the only code that changes a task's or a job's
// state. Each transition is applied at once to the memory state, the scheduler's (tasks, leases,
// failures) and the job's record (state, error, build pin, core seconds), and its store writes are
// appended to the journal (journal.h) in the same order; the caller waits for them, outside the
// coordinator's lock, before it acknowledges. The coordinator calls every method under its lock.
//
// A job: Queued -> Running (its first lease) -> Completed (every frame done); Queued or Running ->
// Failed (a task failed on max_failures workers, a verification with no two results agreeing, a
// stored job that cannot be restored, frames left out of a retry when the others are done) or
// Cancelled (a client); Failed or Cancelled -> Running (`retry`); Completed, Failed or Cancelled
// -> Running (`requeue`). Any other transition is refused (std::logic_error: a bug, not a request).
// A Queued or Running job may be paused and resumed and given another priority; neither changes its
// state. A task: waiting -> leased -> done; leased -> waiting (lease expired, failed, handed back,
// result refused, result held for verification); waiting or leased -> stopped (its frame needs no
// more passes, its job ended); failed on max_failures workers -> its job fails. Scheduler holds the
// task states (scheduler.h); these methods are the only callers that change them.
#pragma once

#include <functional>
#include <optional>
#include <string>

#include "coordinator/core_internal.h"
#include "coordinator/journal.h"
#include "coordinator/scheduler.h"
#include "engine/frame.h"

namespace rf {

class Ledger {
 public:
  using Ticket = Journal::Ticket;

  // clock: the scheduler's clock (the `now` the methods take), for the transitions that take
  // none; unix_offset added to it gives Unix time (attempts' start and end).
  Ledger(SchedulerOptions options, Journal& journal, std::function<double()> clock = {},
         double unix_offset = 0);

  const Scheduler& scheduler() const { return scheduler_; }
  void forget_worker(const std::string& worker_id) { scheduler_.forget_worker(worker_id); }
  Journal& journal() { return journal_; }

  // ---- Jobs
  // A job accepted (its store row written ahead by intake): its tasks are queued.
  void add_job(const JobRecord& job);
  // The job's state and error; ending it frees its tasks and drops its lease rows. Throws
  // std::logic_error for a transition the state machine above does not have.
  Ticket set_state(JobRecord& job, JobState to, const std::string& error);
  // Cancelled by `by`; a cancelled job stays so (no write). Throws std::logic_error if it has
  // completed or failed (the caller refuses that first).
  Ticket cancel(JobRecord& job, const std::string& by);
  // Paused (no new leases; leases in flight finish and merge) or resumed; the job's priority
  // among jobs (higher first). Neither is a state: a Queued or Running job keeps its state. A
  // change to what the job has already is no write. Throws std::logic_error for an ended job
  // (the caller refuses that first).
  Ticket set_paused(JobRecord& job, bool paused);
  Ticket set_priority(JobRecord& job, int priority);
  // `retry`: a Failed or Cancelled job runs again (-> Running) with its failure counts afresh
  // (the store keeps the old ones as history), or a Queued or Running job's held frames run. The
  // frames in `reopen` need their tasks again (the caller then marks those their checkpoints
  // hold: restore_done, restore_passes); those in `held` wait for a later retry; the others of an
  // ended job need nothing (done). The build pin, merged passes and noise-target stops stay.
  // Throws std::logic_error for a completed job.
  Ticket retry(JobRecord& job, const std::vector<FrameNumber>& reopen,
               const std::vector<FrameNumber>& held);

  // `requeue`: the frames render again from scratch (the caller gives them their new run and
  // scene version, `versions` as stored): their tasks are queued afresh and their leases in
  // flight end (recorded as not needed; their late results are answered so); the job's failure
  // counts start afresh (the store keeps the old ones as history). An ended job runs again
  // (-> Running) with its other frames done or, `held`, waiting for a retry. With release_pin
  // the build and CPU kind pin goes (no merged result is left).
  Ticket requeue(JobRecord& job, const std::vector<FrameNumber>& frames,
                 const std::vector<FrameNumber>& held, const std::string& versions,
                 bool release_pin);

  // `delete`: the job is forgotten (its tasks and leases) and its store rows go (store::DeleteJob).
  Ticket delete_job(const JobRecord& job, int64_t expired_unix = 0);

  // ---- Restoring at start (nothing written: it is what the store and checkpoints hold)
  struct Trail {
    std::vector<StoredLease> leases;           // handed out before the restart
    std::vector<std::string> refused_workers;  // one per refused result
    std::vector<TaskFailure> failures;         // in the order recorded
  };
  // A stored job: its tasks queued again, minus an ended job's; its trail counted as before (the
  // caller fails a job whose failures fail it now: scheduler().job_failed()).
  void restore_job(JobRecord& job, const Trail& trail);
  // A job that could not be restored after restore_job began: its tasks go.
  void drop_job(const std::string& job_id);
  // Tasks whose results a frame's checkpoint holds, and passes [0, passes) merged.
  void restore_done(const TaskRef& task);
  void restore_passes(const std::string& job_id, FrameNumber frame, uint32_t passes);

  // ---- Tasks
  // The next task for the worker, and its lease row (the caller moves a queued job to Running).
  std::optional<Lease> lease(const std::string& worker_id, double now,
                             const Scheduler::JobFilter& may);
  LeaseOutcome renew(const std::string& lease_id, double now);
  // Every way a lease ends also stores its attempt's record (store::Attempt: worker, start and
  // end, outcome, reason, the worker's log lines) for `rayfarm logs`.
  //
  // A result merged: the task is done, its event and the job's core seconds stored, and the job
  // pinned to the result's build and CPU kind if it was not.
  Ticket complete(JobRecord& job, const std::string& lease_id, const TaskRef& task,
                  const std::string& worker_id, double core_seconds, const std::string& build_id,
                  const std::string& cpu_kind, double now,
                  const std::vector<std::string>& log = {});
  // A result not merged because its task needs none (settled, merged already, beyond its
  // frame's stop) or because another result of it is being stored: its lease ends, only the
  // attempt is stored. The task is not done by it (Scheduler::release): were it, the result
  // being stored would find its task settled and not be merged either, and the task be lost.
  void not_needed(const std::string& lease_id, const TaskRef& task, const std::string& worker_id,
                  double now, const std::vector<std::string>& log = {});
  // A result refused (or an upload refused on its way in): the lease ends, the task is queued
  // again, and the refusal counts against the worker in the job.
  Ticket refuse_result(const std::string& worker_id, const std::string& lease_id,
                       const TaskRef& task, const std::string& why, double now,
                       const std::vector<std::string>& log = {});
  // A verified task's first result, held: the task goes to another worker.
  void hold_for_verification(const std::string& lease_id, double now,
                             const std::vector<std::string>& log = {});
  // The worker could not render the task (or hands it back): a failure counts (the caller fails
  // the job when scheduler().job_failed() says the task failed on max_failures workers).
  LeaseOutcome fail(const std::string& lease_id, const std::string& worker_id,
                    const std::string& message, bool handed_back, double now, Ticket* ticket,
                    const std::vector<std::string>& log = {});
  // The scheduler let the lease expire (SchedulerOptions::on_expired): its attempt's record.
  void expired(const std::string& lease_id, double now);
  // The frame needs no more passes from `passes` on: its remaining tasks are stopped and its
  // lease rows dropped (once).
  Ticket frame_done(JobRecord& job, FrameRecord& frame, uint32_t passes);

 private:
  // The record of the attempt under `lease_id` (its task and worker from the lease when known,
  // else `task` and `worker_id`), ended now.
  store::Attempt attempt(const std::string& lease_id, const TaskRef& task,
                         const std::string& worker_id, AttemptOutcome outcome,
                         const std::string& message, const std::vector<std::string>& log,
                         double now) const;
  // Records for the live leases that a job's end or a frame's stop is about to end.
  void stopped_attempts(std::vector<StoreWrite>& writes, const std::string& job_id,
                        std::optional<FrameNumber> frame, uint32_t first_pass,
                        const std::string& why, double now) const;

  double now() const { return clock_ ? clock_() : 0; }

  Scheduler scheduler_;
  Journal& journal_;
  std::function<double()> clock_;
  double unix_offset_;
};

}  // namespace rf
