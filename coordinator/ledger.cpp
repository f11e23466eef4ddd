#include "coordinator/ledger.h"

#include <set>
#include <stdexcept>

namespace rf {

namespace {

// The job state machine (ledger.h): which transitions exist.
bool legal(JobState from, JobState to) {
  if (to == JobState::Running && terminal(from)) return true;  // retry (not Completed), requeue
  if (terminal(from)) return false;
  switch (to) {
    case JobState::Queued:
      return false;
    case JobState::Running:
      return from == JobState::Queued;
    case JobState::Completed:
    case JobState::Failed:
    case JobState::Cancelled:
      return true;
  }
  return false;
}

}  // namespace

Ledger::Ledger(SchedulerOptions options, Journal& journal, std::function<double()> clock,
               double unix_offset)
    : scheduler_(std::move(options)),
      journal_(journal),
      clock_(std::move(clock)),
      unix_offset_(unix_offset) {}

store::Attempt Ledger::attempt(const std::string& lease_id, const TaskRef& task,
                               const std::string& worker_id, AttemptOutcome outcome,
                               const std::string& message, const std::vector<std::string>& log,
                               double now) const {
  StoredAttempt a{task.job_id, task.frame,         task.pass, task.tile, lease_id, worker_id,
                  0,           now + unix_offset_, outcome,   message,   log};
  if (std::optional<Scheduler::LeaseInfo> l = scheduler_.lease_info(lease_id)) {
    a.job_id = l->task.job_id, a.frame = l->task.frame, a.pass = l->task.pass;
    a.tile = l->task.tile, a.worker_id = l->worker_id;
    if (l->leased_at >= 0) a.started_unix = l->leased_at + unix_offset_;
  }
  return {std::move(a)};
}

void Ledger::stopped_attempts(std::vector<StoreWrite>& writes, const std::string& job_id,
                              std::optional<FrameNumber> frame, uint32_t first_pass,
                              const std::string& why, double now) const {
  for (const Scheduler::LeaseInfo& l : scheduler_.live_leases(job_id, frame, first_pass))
    writes.push_back(
        attempt(l.lease_id, l.task, l.worker_id, AttemptOutcome::NotNeeded, why, {}, now));
}

void Ledger::add_job(const JobRecord& job) {
  scheduler_.add_job(job.id, job.frame_numbers(), uint32_t(job.tiles.size()), job.passes,
                     job.priority, job.tenant);
  scheduler_.set_paused(job.id, job.paused);
}

Ledger::Ticket Ledger::set_state(JobRecord& job, JobState to, const std::string& error) {
  if (!legal(job.state, to) || terminal(job.state))  // an ended job leaves by retry() only
    throw std::logic_error(std::string("job ") + job.id + ": no transition " +
                           job_state_name(job.state) + " -> " + job_state_name(to));
  job.state = to;
  job.error = error;
  job.ended_unix = terminal(to) ? int64_t(now() + unix_offset_) : 0;
  if (terminal(to)) ++job.endings;
  std::vector<StoreWrite> writes{store::SetState{job.id, int(to), error, job.ended_unix}};
  if (terminal(to)) {
    stopped_attempts(writes, job.id, std::nullopt, 0,
                     std::string("its job ended (") + job_state_name(to) + ")", now());
    writes.push_back(store::DeleteLeases{job.id, std::nullopt});
    scheduler_.cancel_job(job.id);  // frees its tasks and leases (a no-op once all are done)
  }
  return journal_.append(std::move(writes));
}

Ledger::Ticket Ledger::cancel(JobRecord& job, const std::string& by) {
  if (job.state == JobState::Cancelled) return journal_.append({});
  return set_state(job, JobState::Cancelled, "cancelled by " + by);
}

Ledger::Ticket Ledger::set_paused(JobRecord& job, bool paused) {
  if (terminal(job.state))
    throw std::logic_error(std::string("job ") + job.id + ": no pause or resume once " +
                           job_state_name(job.state));
  if (job.paused == paused) return journal_.append({});
  job.paused = paused;
  scheduler_.set_paused(job.id, paused);
  return journal_.append({store::SetPaused{job.id, paused}});
}

Ledger::Ticket Ledger::set_priority(JobRecord& job, int priority) {
  if (terminal(job.state))
    throw std::logic_error(std::string("job ") + job.id + ": no priority change once " +
                           job_state_name(job.state));
  if (job.priority == priority) return journal_.append({});
  job.priority = priority;
  scheduler_.set_priority(job.id, priority);
  return journal_.append({store::SetPriority{job.id, priority}});
}

Ledger::Ticket Ledger::retry(JobRecord& job, const std::vector<FrameNumber>& reopen,
                             const std::vector<FrameNumber>& held) {
  const bool ended = terminal(job.state);
  std::vector<StoreWrite> writes;
  if (ended) {
    if (job.state == JobState::Completed)
      throw std::logic_error(std::string("job ") + job.id + ": no retry once " +
                             job_state_name(job.state));
    job.state = JobState::Running;
    job.error.clear();
    job.ended_unix = 0;
    writes.push_back(store::SetState{job.id, int(JobState::Running), "", 0});
    scheduler_.reopen_job(job.id);
    std::set<FrameNumber> open(reopen.begin(), reopen.end());
    for (FrameNumber f : job.frame_numbers())
      if (!open.count(f)) scheduler_.stop_frame(job.id, f, 0);
  } else {
    for (FrameNumber f : reopen) scheduler_.reopen_frame(job.id, f);
  }
  writes.push_back(store::Retry{job.id, held, ended});
  return journal_.append(std::move(writes));
}

Ledger::Ticket Ledger::requeue(JobRecord& job, const std::vector<FrameNumber>& frames,
                               const std::vector<FrameNumber>& held, const std::string& versions,
                               bool release_pin) {
  std::vector<StoreWrite> writes;
  const std::set<FrameNumber> again(frames.begin(), frames.end());
  if (terminal(job.state)) {
    job.state = JobState::Running;
    job.error.clear();
    job.ended_unix = 0;
    writes.push_back(store::SetState{job.id, int(JobState::Running), "", 0});
    scheduler_.reopen_job(job.id);
    for (FrameNumber f : job.frame_numbers())
      if (!again.count(f)) scheduler_.stop_frame(job.id, f, 0);
  } else {
    const double t = now();
    for (FrameNumber f : frames) {
      stopped_attempts(writes, job.id, f, 0, "its frame was requeued", t);
      writes.push_back(store::DeleteLeases{job.id, f});
    }
    scheduler_.forget_failures(job.id);
    for (FrameNumber f : frames) scheduler_.reopen_frame(job.id, f);
  }
  writes.push_back(store::Retry{job.id, held, true});
  writes.push_back(store::SetVersions{job.id, versions});
  if (release_pin) {
    job.build_id.clear();
    job.cpu_kind.clear();
    writes.push_back(store::SetBuild{job.id, "", ""});
  }
  return journal_.append(std::move(writes));
}

Ledger::Ticket Ledger::delete_job(const JobRecord& job, int64_t expired_unix) {
  scheduler_.remove_job(job.id);
  return journal_.append({store::DeleteJob{job.id, expired_unix}});
}

void Ledger::restore_job(JobRecord& job, const Trail& trail) {
  add_job(job);
  if (terminal(job.state)) {
    scheduler_.cancel_job(job.id);
    return;
  }
  for (const auto& f : job.frames)  // left out of a retry: they wait for the next
    if (f->held) scheduler_.stop_frame(job.id, f->number, 0);
  // Leases from before the restart, ended: their holders' late results are still accepted.
  for (const StoredLease& l : trail.leases)
    scheduler_.restore_lease(l.lease_id, TaskRef{job.id, l.frame, l.pass, l.tile}, l.worker_id);
  // Refused results before the restart still count against their workers.
  for (const std::string& worker : trail.refused_workers)
    scheduler_.restore_refusal(job.id, worker);
  // Failures before the restart still count toward failing a task (and skipping a worker).
  for (const TaskFailure& e : trail.failures)
    scheduler_.restore_failure(TaskRef{job.id, e.frame, e.pass, e.tile}, e.worker_id, e.message);
}

void Ledger::drop_job(const std::string& job_id) { scheduler_.cancel_job(job_id); }

void Ledger::restore_done(const TaskRef& task) { scheduler_.mark_done(task); }

void Ledger::restore_passes(const std::string& job_id, FrameNumber frame, uint32_t passes) {
  scheduler_.mark_passes_done(job_id, frame, passes);
}

std::optional<Lease> Ledger::lease(const std::string& worker_id, double now,
                                   const Scheduler::JobFilter& may) {
  std::optional<Lease> l = scheduler_.lease(worker_id, now, may);
  if (l)
    journal_.append({store::InsertLease{
        {l->lease_id, l->task.job_id, l->task.frame, l->task.pass, l->task.tile, worker_id}}});
  return l;
}

LeaseOutcome Ledger::renew(const std::string& lease_id, double now) {
  return scheduler_.renew(lease_id, now);
}

Ledger::Ticket Ledger::complete(JobRecord& job, const std::string& lease_id, const TaskRef& task,
                                const std::string& worker_id, double core_seconds,
                                const std::string& build_id, const std::string& cpu_kind,
                                double now, const std::vector<std::string>& log) {
  std::vector<StoreWrite> writes;
  writes.push_back(attempt(lease_id, task, worker_id, AttemptOutcome::Done, "", log, now));
  // The first merged result pins the job (the coordinator may have taken the pin already, under
  // its lock before the result was stored: pin_pending).
  if (job.pin_pending || job.build_id.empty() || job.cpu_kind.empty()) {
    if (job.build_id.empty()) job.build_id = build_id;
    if (job.cpu_kind.empty()) job.cpu_kind = cpu_kind;
    job.pin_pending = false;
    writes.push_back(store::SetBuild{job.id, job.build_id, job.cpu_kind});
  }
  writes.push_back(store::TaskEvent{job.id, task.frame, task.pass, task.tile, worker_id,
                                    TaskEventKind::Done, ""});
  writes.push_back(store::AddCoreSeconds{job.id, core_seconds});
  job.core_seconds += core_seconds;
  scheduler_.complete(lease_id, task, now);
  return journal_.append(std::move(writes));
}

void Ledger::not_needed(const std::string& lease_id, const TaskRef& task,
                        const std::string& worker_id, double now,
                        const std::vector<std::string>& log) {
  journal_.append({attempt(lease_id, task, worker_id, AttemptOutcome::NotNeeded,
                           "another result came first, or its frame or job stopped", log, now)});
  scheduler_.release(lease_id, task, now);  // ends the lease; the task is not done by it
}

Ledger::Ticket Ledger::refuse_result(const std::string& worker_id, const std::string& lease_id,
                                     const TaskRef& task, const std::string& why, double now,
                                     const std::vector<std::string>& log) {
  store::Attempt a = attempt(lease_id, task, worker_id, AttemptOutcome::Refused, why, log, now);
  scheduler_.refuse_result(lease_id, now);  // counted against the worker, not the job
  return journal_.append(
      {std::move(a), store::TaskEvent{task.job_id, task.frame, task.pass, task.tile, worker_id,
                                      TaskEventKind::ResultRefused, why}});
}

void Ledger::hold_for_verification(const std::string& lease_id, double now,
                                   const std::vector<std::string>& log) {
  if (std::optional<Scheduler::LeaseInfo> l = scheduler_.lease_info(lease_id))
    journal_.append({attempt(lease_id, l->task, l->worker_id, AttemptOutcome::Held,
                             "held until another worker's result agrees", log, now)});
  scheduler_.verify_again(lease_id, now);
}

void Ledger::expired(const std::string& lease_id, double now) {
  if (std::optional<Scheduler::LeaseInfo> l = scheduler_.lease_info(lease_id))
    journal_.append({attempt(lease_id, l->task, l->worker_id, AttemptOutcome::Expired,
                             "not renewed in time", {}, now)});
}

LeaseOutcome Ledger::fail(const std::string& lease_id, const std::string& worker_id,
                          const std::string& message, bool handed_back, double now, Ticket* ticket,
                          const std::vector<std::string>& log) {
  std::optional<Scheduler::LeaseInfo> info = scheduler_.lease_info(lease_id);
  std::optional<TaskRef> task = scheduler_.lease_task(lease_id);
  LeaseOutcome outcome = scheduler_.fail(lease_id, message, handed_back, now);
  *ticket = journal_.append({});
  if (outcome == LeaseOutcome::Ok && info)
    journal_.append({attempt(lease_id, info->task, info->worker_id,
                             handed_back ? AttemptOutcome::HandedBack : AttemptOutcome::Failed,
                             message, log, now)});
  if (outcome == LeaseOutcome::Ok && task && !handed_back)
    *ticket = journal_.append({store::TaskEvent{task->job_id, task->frame, task->pass, task->tile,
                                                worker_id, TaskEventKind::Failed, message}});
  return outcome;
}

Ledger::Ticket Ledger::frame_done(JobRecord& job, FrameRecord& frame, uint32_t passes) {
  std::vector<StoreWrite> writes;
  stopped_attempts(writes, job.id, frame.number, passes, "its frame needs no more passes", now());
  scheduler_.stop_frame(job.id, frame.number, passes);
  if (!frame.leases_dropped) {
    frame.leases_dropped = true;  // no late result of the frame is needed
    writes.push_back(store::DeleteLeases{job.id, frame.number});
  }
  return journal_.append(std::move(writes));
}

}  // namespace rf
