#include "coordinator/scheduler.h"

#include <algorithm>
#include <limits>
#include <tuple>

namespace rf {

Scheduler::JobState* Scheduler::job(const std::string& id) {
  auto it = jobs_.find(id);
  return it == jobs_.end() ? nullptr : &it->second;
}

const Scheduler::JobState* Scheduler::job(const std::string& id) const {
  auto it = jobs_.find(id);
  return it == jobs_.end() ? nullptr : &it->second;
}

Scheduler::FrameState* Scheduler::frame_of(JobState& j, FrameNumber frame) {
  auto it = j.frame_index.find(frame);
  return it == j.frame_index.end() ? nullptr : &j.frames[it->second];
}

const Scheduler::FrameState* Scheduler::frame_of(const JobState& j, FrameNumber frame) const {
  auto it = j.frame_index.find(frame);
  return it == j.frame_index.end() ? nullptr : &j.frames[it->second];
}

std::pair<Scheduler::JobState*, Scheduler::FrameState*> Scheduler::locate(const TaskRef& ref) {
  JobState* j = job(ref.job_id);
  FrameState* f = j ? frame_of(*j, ref.frame) : nullptr;
  if (!f || ref.pass >= j->passes || ref.tile >= j->tiles) return {nullptr, nullptr};
  return {j, f};
}

std::pair<const Scheduler::JobState*, const Scheduler::FrameState*> Scheduler::locate(
    const TaskRef& ref) const {
  const JobState* j = job(ref.job_id);
  const FrameState* f = j ? frame_of(*j, ref.frame) : nullptr;
  if (!f || ref.pass >= j->passes || ref.tile >= j->tiles) return {nullptr, nullptr};
  return {j, f};
}

bool Scheduler::needed(const JobState& j, const FrameState& f, uint32_t pass) const {
  return !j.failed && !j.cancelled && pass < f.passes_needed;
}

bool Scheduler::is_done(const FrameState& f, uint64_t number) const {
  if (f.open_tasks == 0) return true;  // every needed task is (the others are never asked)
  return !f.done.empty() && f.done[number];
}

void Scheduler::add_job(const std::string& job_id, const std::vector<FrameNumber>& frames,
                        uint32_t tiles, uint32_t passes, int priority, const std::string& tenant) {
  JobState& j = jobs_[job_id];
  j = JobState{};
  j.id = job_id, j.tenant = tenant, j.priority = priority, j.order = next_order_++;
  j.tiles = tiles, j.passes = passes;
  j.frames.reserve(frames.size());
  for (FrameNumber f : frames) {
    j.frame_index[f] = j.frames.size();
    j.frames.push_back({f, passes, uint64_t(tiles) * passes, 0, 0, {}, {}});
  }
}

bool Scheduler::excluded(const TaskRef& ref, const std::string& worker_id) const {
  auto it = tasks_.find(ref);
  return it != tasks_.end() &&
         (it->second.failed_workers.count(worker_id) || it->second.excluded.count(worker_id));
}

std::optional<uint64_t> Scheduler::first_for(const JobState& j, FrameState& f,
                                             const std::string& worker_id) {
  uint64_t limit = uint64_t(f.passes_needed) * j.tiles;
  auto ref_of = [&](uint64_t n) {
    return TaskRef{j.id, f.frame, uint32_t(n / j.tiles), uint32_t(n % j.tiles)};
  };
  std::optional<uint64_t> best;
  for (uint64_t n : f.waiting)
    if (!excluded(ref_of(n), worker_id)) {
      best = n;
      break;
    }
  // Done tasks at the front of the fresh ones are passed for good.
  while (f.fresh < limit && is_done(f, f.fresh)) ++f.fresh, --f.done_ahead;
  for (uint64_t n = f.fresh; n < limit && (!best || n < *best); ++n) {
    if (is_done(f, n) || excluded(ref_of(n), worker_id)) continue;
    best = n;
    break;
  }
  return best;
}

void Scheduler::count_live(const TaskRef& task, int delta) {
  JobState* j = job(task.job_id);
  if (!j) return;
  j->live_leases += uint64_t(int64_t(delta));
  uint64_t& t = tenant_leases_[j->tenant];
  t += uint64_t(int64_t(delta));
  if (t == 0) tenant_leases_.erase(j->tenant);
}

void Scheduler::end_lease(const std::string& id, LeaseState& l) {
  if (l.live) {
    expiry_.erase({l.expires_at, id});
    count_live(l.task, -1);
  }
  l.live = false;
  auto t = tasks_.find(l.task);
  if (t != tasks_.end() && t->second.leases.erase(id)) t->second.ended.insert(id);
}

void Scheduler::forget_task(const TaskRef& ref) {
  auto t = tasks_.find(ref);
  if (t == tasks_.end()) return;
  for (const std::set<std::string>* ids : {&t->second.leases, &t->second.ended})
    for (const std::string& id : *ids) {
      auto l = leases_.find(id);
      if (l == leases_.end()) continue;
      if (l->second.live) {
        expiry_.erase({l->second.expires_at, id});
        count_live(l->second.task, -1);
      }
      leases_.erase(l);
    }
  tasks_.erase(t);
}

void Scheduler::forget_tasks_from(const JobState& j, FrameNumber frame, uint32_t first_pass) {
  std::vector<TaskRef> refs;
  for (auto it = tasks_.lower_bound(TaskRef{j.id, frame, first_pass, 0});
       it != tasks_.end() && it->first.job_id == j.id && it->first.frame == frame; ++it)
    refs.push_back(it->first);
  for (const TaskRef& r : refs) forget_task(r);
}

void Scheduler::requeue_if_needed(const TaskRef& ref) {
  auto [j, f] = locate(ref);
  if (!f || !needed(*j, *f, ref.pass)) return;
  uint64_t n = uint64_t(ref.pass) * j->tiles + ref.tile;
  if (is_done(*f, n)) return;
  auto t = tasks_.find(ref);
  if (t != tasks_.end() && !t->second.leases.empty()) return;
  if (n < f->fresh) f->waiting.insert(n);
}

void Scheduler::cancel_job(const std::string& job_id) {
  JobState* j = job(job_id);
  if (!j) return;
  j->cancelled = true;
  drop_job_tasks(*j);
}

void Scheduler::remove_job(const std::string& job_id) {
  JobState* j = job(job_id);
  if (!j) return;
  drop_job_tasks(*j);
  jobs_.erase(job_id);
}

void Scheduler::reopen_job(const std::string& job_id) {
  JobState* j = job(job_id);
  if (!j) return;
  drop_job_tasks(*j);
  j->failed = j->cancelled = false;
  j->error.clear();
  j->worker_failures.clear();
  j->worker_frame.clear();
  for (FrameState& f : j->frames) reopen_frame(job_id, f.frame);
}

void Scheduler::reopen_frame(const std::string& job_id, FrameNumber frame) {
  JobState* j = job(job_id);
  FrameState* f = j ? frame_of(*j, frame) : nullptr;
  if (!f) return;
  forget_tasks_from(*j, frame, 0);
  *f = FrameState{frame, j->passes, uint64_t(j->tiles) * j->passes, 0, 0, {}, {}};
}

void Scheduler::forget_failures(const std::string& job_id) {
  JobState* j = job(job_id);
  if (!j) return;
  j->worker_failures.clear();
  auto it = tasks_.lower_bound(TaskRef{job_id, std::numeric_limits<FrameNumber>::min(), 0, 0});
  while (it != tasks_.end() && it->first.job_id == job_id) {
    it->second.failed_workers.clear();
    it->second.messages.clear();
    const TaskState& t = it->second;
    it = t.leases.empty() && t.ended.empty() && t.excluded.empty() ? tasks_.erase(it)
                                                                   : std::next(it);
  }
}

void Scheduler::set_paused(const std::string& job_id, bool paused) {
  if (JobState* j = job(job_id)) j->paused = paused;
}

void Scheduler::set_priority(const std::string& job_id, int priority) {
  if (JobState* j = job(job_id)) j->priority = priority;
}

void Scheduler::drop_job_tasks(JobState& j) {
  for (FrameState& f : j.frames) {
    forget_tasks_from(j, f.frame, 0);
    f.done = {};
    f.waiting = {};
  }
  j.worker_frame = {};  // affinity is for handing out its tasks: an entry per worker that had one
}

void Scheduler::expire(double now) {
  while (!expiry_.empty() && expiry_.begin()->first <= now) {
    std::string id = expiry_.begin()->second;
    LeaseState& l = leases_.at(id);
    end_lease(id, l);
    requeue_if_needed(l.task);
    if (options_.on_expired) options_.on_expired(id, l.worker_id, l.task);
  }
}

std::optional<Lease> Scheduler::lease(const std::string& worker_id, double now,
                                      const JobFilter& may) {
  expire(now);
  std::vector<JobState*> order;
  for (auto& [id, j] : jobs_)
    if (!j.failed && !j.cancelled && !j.paused && (!may || may(id))) order.push_back(&j);
  // Priority first; between equal priorities the fair share's measure, live leases (of the
  // tenant, then of the job); then submission.
  auto tenant_load = [&](const JobState* j) -> uint64_t {
    if (options_.share != FairShare::Tenants) return 0;
    auto it = tenant_leases_.find(j->tenant);
    return it == tenant_leases_.end() ? 0 : it->second;
  };
  auto job_load = [&](const JobState* j) -> uint64_t {
    return options_.share == FairShare::None ? 0 : j->live_leases;
  };
  std::sort(order.begin(), order.end(), [&](const JobState* a, const JobState* b) {
    if (a->priority != b->priority) return a->priority > b->priority;
    const uint64_t ta = tenant_load(a), tb = tenant_load(b);
    if (ta != tb) return ta < tb;
    const uint64_t ja = job_load(a), jb = job_load(b);
    if (ja != jb) return ja < jb;
    return a->order < b->order;
  });
  for (JobState* j : order) {
    auto wf = j->worker_failures.find(worker_id);
    if (wf != j->worker_failures.end() && wf->second >= options_.max_failures) continue;
    // The window: the first window_frames frames (in job order) that still need tasks. Each
    // one's first task this worker may get (a frame's tasks are numbered by pass, then tile),
    // then the least by (pass, not the worker's last frame, position in the job, tile).
    FrameState* best = nullptr;
    uint64_t best_number = 0;
    std::tuple<uint32_t, bool, size_t, uint32_t> best_key{};
    auto last = j->worker_frame.find(worker_id);
    size_t open = 0;
    for (size_t i = 0; i < j->frames.size() && open < options_.window_frames; ++i) {
      FrameState& f = j->frames[i];
      if (f.open_tasks == 0) continue;
      ++open;
      std::optional<uint64_t> n = first_for(*j, f, worker_id);
      if (!n) continue;
      const bool other = last == j->worker_frame.end() || last->second != f.frame;
      std::tuple<uint32_t, bool, size_t, uint32_t> key{uint32_t(*n / j->tiles), other, i,
                                                       uint32_t(*n % j->tiles)};
      if (!best || key < best_key) best = &f, best_number = *n, best_key = key;
    }
    if (!best) continue;
    FrameState& f = *best;
    if (best_number < f.fresh) {
      f.waiting.erase(best_number);
    } else {  // fresh tasks passed over (excluded for this worker) wait for the others
      for (uint64_t n = f.fresh; n < best_number; ++n)
        if (!is_done(f, n))
          f.waiting.insert(n);
        else
          --f.done_ahead;
      f.fresh = best_number + 1;
    }
    TaskRef ref{j->id, f.frame, uint32_t(best_number / j->tiles), uint32_t(best_number % j->tiles)};
    j->worker_frame[worker_id] = f.frame;
    std::string id = options_.lease_prefix + std::to_string(++next_lease_);
    leases_[id] = LeaseState{ref, worker_id, now + options_.lease_seconds, true, now};
    count_live(ref, +1);
    expiry_.insert({now + options_.lease_seconds, id});
    tasks_[ref].leases.insert(id);
    return Lease{id, ref, now + options_.lease_seconds};
  }
  return std::nullopt;
}

bool Scheduler::retired(const std::string& lease_id) const {
  const std::string& p = options_.lease_prefix;
  if (lease_id.size() <= p.size() || lease_id.size() > p.size() + 19 ||
      lease_id.compare(0, p.size(), p) != 0 || leases_.count(lease_id))
    return false;
  uint64_t n = 0;
  for (size_t i = p.size(); i < lease_id.size(); ++i) {
    char c = lease_id[i];
    if (c < '0' || c > '9' || (i == p.size() && c == '0')) return false;
    n = n * 10 + uint64_t(c - '0');
  }
  return n >= 1 && n <= next_lease_;
}

LeaseOutcome Scheduler::renew(const std::string& lease_id, double now) {
  expire(now);
  auto it = leases_.find(lease_id);
  if (it == leases_.end()) return retired(lease_id) ? LeaseOutcome::Ended : LeaseOutcome::NotFound;
  if (!it->second.live) return LeaseOutcome::Ended;
  expiry_.erase({it->second.expires_at, lease_id});
  it->second.expires_at = now + options_.lease_seconds;
  expiry_.insert({it->second.expires_at, lease_id});
  return LeaseOutcome::Ok;
}

CompleteOutcome Scheduler::complete(const std::string& lease_id, double now) {
  expire(now);
  auto it = leases_.find(lease_id);
  if (it == leases_.end())
    return retired(lease_id) ? CompleteOutcome::Duplicate : CompleteOutcome::NotFound;
  TaskRef task = it->second.task;
  end_lease(lease_id, it->second);
  return complete_task(task);
}

CompleteOutcome Scheduler::complete(const std::string& lease_id, const TaskRef& task, double now) {
  auto it = leases_.find(lease_id);
  if (it != leases_.end() && it->second.task == task) return complete(lease_id, now);
  expire(now);
  if (!locate(task).first) return CompleteOutcome::NotFound;
  return complete_task(task);
}

CompleteOutcome Scheduler::complete_task(const TaskRef& ref) {
  auto [j, f] = locate(ref);
  if (!f || !needed(*j, *f, ref.pass)) return CompleteOutcome::Duplicate;
  uint64_t n = uint64_t(ref.pass) * j->tiles + ref.tile;
  if (is_done(*f, n)) return CompleteOutcome::Duplicate;
  // First result wins, whichever lease it came from; the task's other leases end.
  forget_task(ref);
  f->waiting.erase(n);
  if (f->done.empty()) f->done.assign(uint64_t(j->passes) * j->tiles, false);
  f->done[n] = true;
  if (n >= f->fresh) ++f->done_ahead;
  if (--f->open_tasks == 0) {  // the frame is done: nothing of it is needed any more
    forget_tasks_from(*j, f->frame, 0);
    f->done = {};
    f->waiting = {};
  }
  return CompleteOutcome::Accepted;
}

void Scheduler::mark_done(const TaskRef& ref) {
  if (locate(ref).first) complete_task(ref);
}

void Scheduler::mark_passes_done(const std::string& job_id, FrameNumber frame, uint32_t passes) {
  JobState* j = job(job_id);
  if (!j) return;
  for (uint32_t p = 0; p < std::min(passes, j->passes); ++p)
    for (uint32_t t = 0; t < j->tiles; ++t) mark_done(TaskRef{job_id, frame, p, t});
}

void Scheduler::release(const std::string& lease_id, const TaskRef& task, double now) {
  expire(now);
  auto it = leases_.find(lease_id);
  if (it == leases_.end()) {  // retired, or issued before a restart
    requeue_if_needed(task);
    return;
  }
  TaskRef leased = it->second.task;
  if (it->second.live) end_lease(lease_id, it->second);
  requeue_if_needed(leased);
}

bool Scheduler::settled(const TaskRef& ref) const {
  auto [j, f] = locate(ref);
  return !f || !needed(*j, *f, ref.pass) || is_done(*f, uint64_t(ref.pass) * j->tiles + ref.tile);
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
  if (it == leases_.end()) return retired(lease_id) ? LeaseOutcome::Ended : LeaseOutcome::NotFound;
  if (!it->second.live) return LeaseOutcome::Ended;
  LeaseState l = it->second;
  end_lease(lease_id, it->second);
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
  TaskRef task = l.task;
  end_lease(lease_id, l);
  requeue_if_needed(task);
}

void Scheduler::restore_refusal(const std::string& job_id, const std::string& worker_id) {
  if (JobState* j = job(job_id)) ++j->worker_failures[worker_id];
}

void Scheduler::verify_again(const std::string& lease_id, double now) {
  expire(now);
  auto it = leases_.find(lease_id);
  if (it == leases_.end()) return;
  LeaseState& l = it->second;
  TaskRef task = l.task;
  tasks_[task].excluded.insert(l.worker_id);
  end_lease(lease_id, l);
  requeue_if_needed(task);
}

bool Scheduler::count_failure(const TaskRef& ref, const std::string& worker_id,
                              const std::string& message) {
  auto [j, f] = locate(ref);
  if (!f || j->failed || !needed(*j, *f, ref.pass) ||
      is_done(*f, uint64_t(ref.pass) * j->tiles + ref.tile))
    return false;
  TaskState& t = tasks_[ref];
  t.failed_workers.insert(worker_id);
  t.messages.push_back(worker_id + ": " + message);
  ++j->worker_failures[worker_id];
  if (int(t.failed_workers.size()) < options_.max_failures) return false;
  j->failed = true;
  j->error = "task frame " + std::to_string(ref.frame) + " pass " + std::to_string(ref.pass) +
             " tile " + std::to_string(ref.tile) + " failed on " +
             std::to_string(t.failed_workers.size()) + " workers:";
  for (const std::string& m : t.messages) j->error += "\n  " + m;
  drop_job_tasks(*j);
  return true;
}

std::optional<Scheduler::LeaseInfo> Scheduler::lease_info(const std::string& lease_id) const {
  auto it = leases_.find(lease_id);
  if (it == leases_.end()) return std::nullopt;
  const LeaseState& l = it->second;
  return LeaseInfo{lease_id, l.task, l.worker_id, l.leased_at};
}

std::vector<Scheduler::LeaseInfo> Scheduler::live_leases(const std::string& job_id,
                                                         std::optional<FrameNumber> frame,
                                                         uint32_t first_pass) const {
  std::vector<LeaseInfo> out;
  for (const auto& [id, l] : leases_)
    if (l.live && l.task.job_id == job_id &&
        (!frame || (l.task.frame == *frame && l.task.pass >= first_pass)))
      out.push_back({id, l.task, l.worker_id, l.leased_at});
  return out;
}

std::string Scheduler::lease_worker(const std::string& lease_id) const {
  auto it = leases_.find(lease_id);
  return it == leases_.end() ? "" : it->second.worker_id;
}

void Scheduler::restore_lease(const std::string& lease_id, const TaskRef& task,
                              const std::string& worker_id) {
  if (settled(task)) return;  // nothing more to accept under it
  leases_[lease_id] = LeaseState{task, worker_id, 0, false};
  tasks_[task].ended.insert(lease_id);
}

void Scheduler::restore_failure(const TaskRef& ref, const std::string& worker_id,
                                const std::string& message) {
  count_failure(ref, worker_id, message);
}

void Scheduler::stop_frame(const std::string& job_id, FrameNumber frame, uint32_t first_unneeded) {
  JobState* j = job(job_id);
  FrameState* f = j ? frame_of(*j, frame) : nullptr;
  if (!f || first_unneeded >= f->passes_needed) return;
  uint64_t limit = uint64_t(first_unneeded) * j->tiles;
  uint64_t old_limit = uint64_t(f->passes_needed) * j->tiles;
  if (f->open_tasks > 0) {
    for (uint64_t n = limit; n < old_limit; ++n)
      if (!is_done(*f, n)) --f->open_tasks;
  }
  forget_tasks_from(*j, frame, first_unneeded);
  f->waiting.erase(f->waiting.lower_bound(limit), f->waiting.end());
  f->passes_needed = first_unneeded;
  f->done_ahead = 0;
  for (uint64_t n = f->fresh; n < limit; ++n)
    if (is_done(*f, n)) ++f->done_ahead;
  if (f->open_tasks == 0) {
    f->done = {};
    f->waiting = {};
  }
}

bool Scheduler::job_failed(const std::string& job_id) const {
  auto it = jobs_.find(job_id);
  return it != jobs_.end() && it->second.failed;
}

std::string Scheduler::job_error(const std::string& job_id) const {
  auto it = jobs_.find(job_id);
  return it == jobs_.end() ? "" : it->second.error;
}

std::set<std::string> Scheduler::leased_jobs(
    const std::function<bool(const std::string& worker_id)>& whose) const {
  std::set<std::string> out;
  for (const auto& [id, l] : leases_)
    if (l.live && whose(l.worker_id)) out.insert(l.task.job_id);
  return out;
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

std::set<std::string> Scheduler::workers_with_live_leases() const {
  std::set<std::string> out;
  for (const auto& [id, l] : leases_)
    if (l.live) out.insert(l.worker_id);
  return out;
}

void Scheduler::forget_worker(const std::string& worker_id) {
  for (auto& [id, j] : jobs_) j.worker_frame.erase(worker_id);
}

std::vector<TaskRef> Scheduler::leased_to(const std::string& worker_id) const {
  std::vector<TaskRef> out;
  for (const auto& [id, l] : leases_)
    if (l.live && l.worker_id == worker_id) out.push_back(l.task);
  return out;
}

int Scheduler::failures_of(const std::string& worker_id) const {
  int n = 0;
  for (const auto& [id, j] : jobs_) {
    if (j.failed || j.cancelled) continue;
    if (auto it = j.worker_failures.find(worker_id); it != j.worker_failures.end()) n += it->second;
  }
  return n;
}

uint64_t Scheduler::queued_in(const JobState& j, const FrameState& f) const {
  if (f.open_tasks == 0) return 0;
  uint64_t limit = uint64_t(f.passes_needed) * j.tiles;
  uint64_t fresh = std::min(f.fresh, limit);
  return f.waiting.size() + (limit - fresh - std::min(f.done_ahead, limit - fresh));
}

size_t Scheduler::queued_tasks() const {
  uint64_t n = 0;
  for (const auto& [id, j] : jobs_)
    if (!j.failed && !j.cancelled)
      for (const FrameState& f : j.frames) n += queued_in(j, f);
  return size_t(n);
}

std::map<std::string, Scheduler::JobLoad> Scheduler::load_by_job() const {
  std::map<std::string, JobLoad> out;
  for (const auto& [id, j] : jobs_) {
    if (j.failed || j.cancelled) continue;
    JobLoad& load = out[id];
    for (const FrameState& f : j.frames) load.queued += queued_in(j, f);
  }
  for (const auto& [id, l] : leases_)
    if (l.live)
      if (auto it = out.find(l.task.job_id); it != out.end()) ++it->second.leased;
  return out;
}

}  // namespace rf
