#include "coordinator/scheduler.h"

#include <algorithm>
#include <tuple>

namespace rf {

Scheduler::JobState* Scheduler::job(const std::string& id) {
  auto it = jobs_.find(id);
  return it == jobs_.end() ? nullptr : &it->second;
}

Scheduler::FrameState* Scheduler::frame_of(JobState& j, uint32_t frame) {
  for (FrameState& f : j.frames)
    if (f.frame == frame) return &f;
  return nullptr;
}

bool Scheduler::needed(const JobState& j, const FrameState& f, uint32_t pass) const {
  return !j.failed && !j.cancelled && pass < f.passes_needed;
}

void Scheduler::add_job(const std::string& job_id, const std::vector<uint32_t>& frames,
                        uint32_t tiles, uint32_t passes, int priority) {
  JobState& j = jobs_[job_id];
  j = JobState{job_id, priority, next_order_++, tiles, passes, {}, {}, false, false, {}};
  for (uint32_t f : frames) {
    j.frames.push_back({f, passes, tiles * passes});
    for (uint32_t p = 0; p < passes; ++p)
      for (uint32_t t = 0; t < tiles; ++t) {
        TaskRef ref{job_id, f, p, t};
        tasks_[ref] = TaskState{};
        queue_.insert(ref);
      }
  }
}

void Scheduler::end_task_leases(TaskState& t) {
  for (const std::string& id : t.leases) {
    LeaseState& l = leases_[id];
    expiry_.erase({l.expires_at, id});
    l.live = false;
  }
  t.leases.clear();
}

void Scheduler::end_lease(const std::string& id, LeaseState& l) {
  if (l.live) expiry_.erase({l.expires_at, id});
  l.live = false;
  tasks_[l.task].leases.erase(id);
}

void Scheduler::requeue_if_needed(const TaskRef& ref) {
  TaskState& t = tasks_[ref];
  JobState* j = job(ref.job_id);
  FrameState* f = j ? frame_of(*j, ref.frame) : nullptr;
  if (!t.done && !t.stopped && t.leases.empty() && f && needed(*j, *f, ref.pass))
    queue_.insert(ref);
}

void Scheduler::cancel_job(const std::string& job_id) {
  JobState* j = job(job_id);
  if (!j) return;
  j->cancelled = true;
  drop_job_tasks(job_id);
}

void Scheduler::drop_job_tasks(const std::string& job_id) {
  for (auto it = queue_.lower_bound(TaskRef{job_id, 0, 0, 0});
       it != queue_.end() && it->job_id == job_id;)
    it = queue_.erase(it);
  for (auto& [ref, t] : tasks_)
    if (ref.job_id == job_id) end_task_leases(t);
}

void Scheduler::expire(double now) {
  while (!expiry_.empty() && expiry_.begin()->first <= now) {
    std::string id = expiry_.begin()->second;
    LeaseState& l = leases_.at(id);
    end_lease(id, l);
    requeue_if_needed(l.task);
  }
}

std::optional<Lease> Scheduler::lease(const std::string& worker_id, double now,
                                      const JobFilter& may) {
  expire(now);
  std::vector<JobState*> order;
  for (auto& [id, j] : jobs_)
    if (!j.failed && !j.cancelled && (!may || may(id))) order.push_back(&j);
  std::sort(order.begin(), order.end(), [](const JobState* a, const JobState* b) {
    return std::tie(b->priority, a->order) < std::tie(a->priority, b->order);
  });
  for (JobState* j : order) {
    auto wf = j->worker_failures.find(worker_id);
    if (wf != j->worker_failures.end() && wf->second >= options_.max_failures) continue;
    // The window: the first window_frames frames (in job order) that still need tasks.
    std::map<uint32_t, size_t> window;  // frame -> position in the job
    for (size_t i = 0; i < j->frames.size() && window.size() < options_.window_frames; ++i)
      if (j->frames[i].open_tasks > 0) window[j->frames[i].frame] = i;
    // Each open frame's first queued task this worker may get (the queue orders a frame's
    // tasks by pass, then tile), then the least by (pass, position in the job, tile).
    const TaskRef* best = nullptr;
    std::tuple<uint32_t, size_t, uint32_t> best_key{};
    for (const auto& [frame, position] : window) {
      for (auto it = queue_.lower_bound(TaskRef{j->id, frame, 0, 0});
           it != queue_.end() && it->job_id == j->id && it->frame == frame; ++it) {
        const TaskState& ts = tasks_[*it];
        if (ts.failed_workers.count(worker_id) || ts.excluded.count(worker_id)) continue;
        std::tuple<uint32_t, size_t, uint32_t> key{it->pass, position, it->tile};
        if (!best || key < best_key) best = &*it, best_key = key;
        break;
      }
    }
    if (!best) continue;
    TaskRef ref = *best;
    queue_.erase(ref);
    std::string id = options_.lease_prefix + std::to_string(++next_lease_);
    leases_[id] = LeaseState{ref, worker_id, now + options_.lease_seconds, true};
    expiry_.insert({now + options_.lease_seconds, id});
    tasks_[ref].leases.insert(id);
    return Lease{id, ref, now + options_.lease_seconds};
  }
  return std::nullopt;
}

LeaseOutcome Scheduler::renew(const std::string& lease_id, double now) {
  expire(now);
  auto it = leases_.find(lease_id);
  if (it == leases_.end()) return LeaseOutcome::NotFound;
  if (!it->second.live) return LeaseOutcome::Ended;
  expiry_.erase({it->second.expires_at, lease_id});
  it->second.expires_at = now + options_.lease_seconds;
  expiry_.insert({it->second.expires_at, lease_id});
  return LeaseOutcome::Ok;
}

CompleteOutcome Scheduler::complete(const std::string& lease_id, double now) {
  expire(now);
  auto it = leases_.find(lease_id);
  if (it == leases_.end()) return CompleteOutcome::NotFound;
  end_lease(lease_id, it->second);
  return complete_task(it->second.task);
}

CompleteOutcome Scheduler::complete(const std::string& lease_id, const TaskRef& task, double now) {
  auto it = leases_.find(lease_id);
  if (it != leases_.end() && it->second.task == task) return complete(lease_id, now);
  expire(now);
  if (!tasks_.count(task)) return CompleteOutcome::NotFound;
  return complete_task(task);
}

CompleteOutcome Scheduler::complete_task(const TaskRef& ref) {
  TaskState& t = tasks_[ref];
  JobState* j = job(ref.job_id);
  FrameState* f = j ? frame_of(*j, ref.frame) : nullptr;
  if (t.done || t.stopped || !f || !needed(*j, *f, ref.pass)) return CompleteOutcome::Duplicate;
  // First result wins, whichever lease it came from; the task's other leases end.
  t.done = true;
  end_task_leases(t);
  queue_.erase(ref);
  --f->open_tasks;
  return CompleteOutcome::Accepted;
}

void Scheduler::mark_done(const TaskRef& ref) {
  auto it = tasks_.find(ref);
  if (it == tasks_.end() || it->second.done) return;
  complete_task(ref);
}

std::optional<TaskRef> Scheduler::lease_task(const std::string& lease_id) const {
  auto it = leases_.find(lease_id);
  if (it == leases_.end()) return std::nullopt;
  return it->second.task;
}

LeaseOutcome Scheduler::fail(const std::string& lease_id, const std::string& message,
                             bool handed_back, double now) {
  expire(now);
  auto it = leases_.find(lease_id);
  if (it == leases_.end()) return LeaseOutcome::NotFound;
  if (!it->second.live) return LeaseOutcome::Ended;
  LeaseState& l = it->second;
  end_lease(lease_id, l);
  JobState* j = job(l.task.job_id);
  if (!handed_back && j && count_failure(l.task, l.worker_id, message)) return LeaseOutcome::Ok;
  requeue_if_needed(l.task);
  return LeaseOutcome::Ok;
}

void Scheduler::refuse_result(const std::string& lease_id, double now) {
  expire(now);
  auto it = leases_.find(lease_id);
  if (it == leases_.end()) return;
  LeaseState& l = it->second;
  JobState* j = job(l.task.job_id);
  if (j) ++j->worker_failures[l.worker_id];
  if (!l.live) return;
  end_lease(lease_id, l);
  requeue_if_needed(l.task);
}

void Scheduler::verify_again(const std::string& lease_id, double now) {
  expire(now);
  auto it = leases_.find(lease_id);
  if (it == leases_.end()) return;
  LeaseState& l = it->second;
  tasks_[l.task].excluded.insert(l.worker_id);
  end_lease(lease_id, l);
  requeue_if_needed(l.task);
}

bool Scheduler::count_failure(const TaskRef& ref, const std::string& worker_id,
                              const std::string& message) {
  JobState* j = job(ref.job_id);
  auto it = tasks_.find(ref);
  if (!j || it == tasks_.end() || j->failed) return false;
  TaskState& t = it->second;
  t.failed_workers.insert(worker_id);
  t.messages.push_back(worker_id + ": " + message);
  ++j->worker_failures[worker_id];
  if (int(t.failed_workers.size()) < options_.max_failures) return false;
  j->failed = true;
  j->error = "task frame " + std::to_string(ref.frame) + " pass " + std::to_string(ref.pass) +
             " tile " + std::to_string(ref.tile) + " failed on " +
             std::to_string(t.failed_workers.size()) + " workers:";
  for (const std::string& m : t.messages) j->error += "\n  " + m;
  drop_job_tasks(j->id);
  return true;
}

std::string Scheduler::lease_worker(const std::string& lease_id) const {
  auto it = leases_.find(lease_id);
  return it == leases_.end() ? "" : it->second.worker_id;
}

void Scheduler::restore_lease(const std::string& lease_id, const TaskRef& task,
                              const std::string& worker_id) {
  if (!tasks_.count(task)) return;
  leases_[lease_id] = LeaseState{task, worker_id, 0, false};
}

void Scheduler::restore_failure(const TaskRef& ref, const std::string& worker_id,
                                const std::string& message) {
  count_failure(ref, worker_id, message);
}

void Scheduler::stop_frame(const std::string& job_id, uint32_t frame, uint32_t first_unneeded) {
  JobState* j = job(job_id);
  FrameState* f = j ? frame_of(*j, frame) : nullptr;
  if (!f || first_unneeded >= f->passes_needed) return;
  for (uint32_t p = first_unneeded; p < f->passes_needed; ++p)
    for (uint32_t tile = 0; tile < j->tiles; ++tile) {
      TaskRef ref{job_id, frame, p, tile};
      TaskState& t = tasks_[ref];
      if (!t.done) --f->open_tasks;
      t.stopped = true;
      end_task_leases(t);
      queue_.erase(ref);
    }
  f->passes_needed = first_unneeded;
}

bool Scheduler::job_failed(const std::string& job_id) const {
  auto it = jobs_.find(job_id);
  return it != jobs_.end() && it->second.failed;
}

std::string Scheduler::job_error(const std::string& job_id) const {
  auto it = jobs_.find(job_id);
  return it == jobs_.end() ? "" : it->second.error;
}

bool Scheduler::work_left_for(const std::string& worker_id, const JobFilter& may) const {
  for (const auto& [id, j] : jobs_) {
    if (j.failed || j.cancelled || (may && !may(id))) continue;
    auto wf = j.worker_failures.find(worker_id);
    if (wf != j.worker_failures.end() && wf->second >= options_.max_failures) continue;
    for (const FrameState& f : j.frames)
      if (f.open_tasks > 0) return true;
  }
  return false;
}

size_t Scheduler::queued_tasks() const { return queue_.size(); }

}  // namespace rf
