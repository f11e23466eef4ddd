// The worker registry and leasing (core.h): registrations, leases, renewals and scene blobs.
#include "coordinator/core_internal.h"
#include "coordinator/journal.h"
#include "coordinator/ledger.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include "engine/digest.h"
#include "farm/tags.h"

namespace rf {

namespace fs = std::filesystem;
using core_detail::clip;
using core_detail::refuse;
using core_detail::unix_now;

// ---------------------------------------------------------------------------------------------
// Workers

// A registration no call has used for kUnusedWorkerSeconds (a worker that registered and died, or
// a client registering in a loop), and one that has been silent for 10 lease times (at least a
// minute) with no live lease (a worker killed, its machine gone: a live worker calls at least
// once a lease time, to lease, renew or upload), is forgotten, in memory, in the scheduler and in
// the store; a live worker that comes back is answered NOT_FOUND and registers again. Without
// this a farm whose workers come and go holds a record per worker it ever had, and per job it
// leased in (the soak's killed workers: bench/soak.sh). Outvoted workers are kept (their verdict
// is shown). Swept at most once a minute, at a registration.
void Coordinator::forget_unused_workers() {
  const double unused_expiry = std::max(kUnusedWorkerSeconds, 10 * options_.lease_seconds);
  const double silent_expiry = std::max(60.0, 10 * options_.lease_seconds);
  if (now() - last_worker_sweep_ < 60) return;
  last_worker_sweep_ = now();
  std::set<std::string> leasing = ledger_->scheduler().workers_with_live_leases();
  std::vector<std::string> gone;
  size_t silent = 0;
  for (const auto& [id, w] : workers_) {
    if (outvoted_.count(id) || leasing.count(id)) continue;
    auto seen = last_seen_.find(id);
    double last = seen != last_seen_.end() ? seen->second : w.registered_at;
    if (now() - std::max(last, w.registered_at) <= (w.used ? silent_expiry : unused_expiry))
      continue;
    gone.push_back(id);
    silent += w.used;
  }
  for (const std::string& id : gone) {
    workers_.erase(id);
    last_seen_.erase(id);
    ledger_->forget_worker(id);
    journal_->append({store::DeleteWorker{id}});
  }
  if (!gone.empty())
    spdlog::info("forgot {} worker registrations: {} unused for {:g} s, {} silent for {:g} s",
                 gone.size(), gone.size() - silent, unused_expiry, silent, silent_expiry);
}

Registration Coordinator::register_worker(const WorkerInfo& w, const Caller& caller) {
  if (w.tags.size() > kMaxTags)
    refuse(ErrorCode::InvalidArgument,
           "tags: " + std::to_string(w.tags.size()) + " tags; at most " + std::to_string(kMaxTags));
  for (const std::string& t : w.tags)
    if (std::string why = tag_problem(t); !why.empty())
      refuse(ErrorCode::InvalidArgument, "tags: " + why);
  std::string host;
  for (char c : w.hostname.substr(0, 64))  // part of an id that appears in logs and file rows
    if (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '.') host += c;
  if (host.empty()) host = "worker";
  Registration r;
  {
    std::lock_guard lock(mu_);
    r.worker_id = options_.instance + "-w" + std::to_string(next_worker_++) + "-" + host;
    forget_unused_workers();
  }
  r.lease_seconds = uint32_t(std::max(1.0, options_.lease_seconds));
  r.keepalive_seconds = uint32_t(std::max(1.0, options_.lease_seconds / 3));
  try {  // stored before the worker may use it, without the coordinator's lock
    journal_->write_ahead(
        {store::InsertWorker{{r.worker_id, caller.principal, w.build_id.substr(0, 256), "",
                              w.isa.substr(0, 256), w.tags}}});
  } catch (const StoreError& e) {
    refuse(ErrorCode::Unavailable, std::string("cannot store the registration now: ") + e.what());
  }
  std::lock_guard lock(mu_);
  WorkerInfo info{host, w.cores, w.build_id.substr(0, 256), w.isa.substr(0, 256), w.tags};
  workers_[r.worker_id] = {caller.principal, info.build_id, info.isa, info, now()};
  last_seen_[r.worker_id] = now();
  std::string tags;
  for (const std::string& t : w.tags) tags += " " + t;
  spdlog::info("worker {} registered by {}: {} cores, {}, {}, tags:{}", r.worker_id,
               caller.principal, w.cores, clip(w.build_id), clip(w.isa), tags);
  return r;
}

std::vector<WorkerStatus> Coordinator::workers(const Caller& caller, size_t limit,
                                               const std::string& after, bool* more) const {
  std::lock_guard lock(mu_);
  std::vector<WorkerStatus> out;
  if (more) *more = false;
  for (auto it = after.empty() ? workers_.begin() : workers_.upper_bound(after);
       it != workers_.end(); ++it) {
    if (out.size() == limit) {
      if (more) *more = true;
      break;
    }
    const auto& [id, w] = *it;
    WorkerStatus s;
    s.worker_id = id;
    if (caller.all_tenants) s.principal = w.principal;
    s.info = w.info;
    for (const TaskRef& t : ledger_->scheduler().leased_to(id)) {
      auto job = jobs_.find(t.job_id);
      const bool visible =
          caller.all_tenants || (job != jobs_.end() && job->second->tenant == caller.tenant);
      s.tasks.push_back(visible ? task_id_text(t) : "(another tenant's task)");
    }
    s.failures = ledger_->scheduler().failures_of(id);
    auto seen = last_seen_.find(id);
    s.seconds_since_contact = seen == last_seen_.end() ? -1 : now() - seen->second;
    if (auto o = outvoted_.find(id); o != outvoted_.end()) s.refused = o->second;
    out.push_back(std::move(s));
  }
  return out;
}

void Coordinator::check_worker(const std::string& worker_id, const Caller& caller) const {
  if (worker_id.empty()) refuse(ErrorCode::InvalidArgument, "worker_id is empty");
  auto it = workers_.find(worker_id);
  if (it == workers_.end())
    refuse(ErrorCode::NotFound, "no worker '" + clip(worker_id) + "' registered; register first");
  if (auto o = outvoted_.find(worker_id); o != outvoted_.end())
    refuse(ErrorCode::PermissionDenied, "worker " + worker_id + " is refused: " + o->second);
  if (it->second.principal != caller.principal) {
    spdlog::warn("refused: {} called as worker {}, registered by {}", caller.principal, worker_id,
                 it->second.principal);
    refuse(ErrorCode::PermissionDenied,
           "worker " + worker_id + " was registered with another token");
  }
  last_seen_[worker_id] = now();
  it->second.used = true;
}

bool Coordinator::check_lease(const std::string& worker_id, const std::string& lease_id,
                              const TaskRef* task) const {
  const Scheduler& scheduler = ledger_->scheduler();
  std::string holder = scheduler.lease_worker(lease_id);
  // A lease whose record is gone ended with its task settled (done, stopped, or its job over):
  // nothing sent under it will be merged, whoever sends it.
  if (holder.empty() && (scheduler.retired(lease_id) || (task && scheduler.settled(*task))))
    return false;
  if (holder.empty()) refuse(ErrorCode::NotFound, "no lease '" + clip(lease_id) + "'");
  if (holder != worker_id) {
    spdlog::warn("refused: worker {} used lease {}, held by {}", worker_id, lease_id, holder);
    refuse(ErrorCode::PermissionDenied, "lease " + lease_id + " is held by another worker");
  }
  if (task && !(*scheduler.lease_task(lease_id) == *task)) {
    spdlog::warn("refused: worker {} sent task {} under lease {}, which is for task {}", worker_id,
                 task_id_text(*task), lease_id, task_id_text(*scheduler.lease_task(lease_id)));
    refuse(ErrorCode::PermissionDenied, "lease " + lease_id + " is for another task");
  }
  return true;
}

LeaseResult Coordinator::lease(const std::string& worker_id, const Caller& caller,
                               uint32_t max_tasks) {
  // The call's time in the core, lock wait included, recorded on every way out.
  struct Timed {
    CoordinatorMetrics::Counters& c;
    std::chrono::steady_clock::time_point t0;
    ~Timed() {
      double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      ++c.lease_calls;
      c.lease_seconds += s;
      const auto& bounds = CoordinatorMetrics::kLeaseBuckets;
      for (size_t i = 0; i < std::size(bounds); ++i)
        if (s <= bounds[i]) {
          ++c.lease_buckets[i];
          break;
        }
    }
  };
  const auto t0 = std::chrono::steady_clock::now();
  std::lock_guard lock(mu_);
  Timed timed{counters_, t0};  // destroyed before the lock is released
  check_worker(worker_id, caller);
  if (closing_) refuse(ErrorCode::Unavailable, "the coordinator is shutting down");
  // A lease is stored (its row lets its holder's late result count after a restart): while the
  // store refuses writes, none is handed out.
  if (std::string problem = journal_->problem(); !problem.empty())
    refuse(ErrorCode::Unavailable,
           "the coordinator cannot store leases now (" + problem + "); retry later");
  LeaseResult out;
  // Only jobs that merge this worker's build and CPU kind (a job pinned to others is not its
  // work).
  const WorkerRecord& me = workers_.at(worker_id);
  Scheduler::JobFilter may = [&](const std::string& job_id) {
    std::shared_ptr<JobRecord> job = find(job_id);
    return job && pin_ok(*job, me.build_id, me.isa) &&
           satisfies_all(me.info.tags, job->spec.required_tags);
  };
  std::optional<Lease> l = ledger_->lease(worker_id, now(), may);
  if (!l) {
    out.no_more_work = !ledger_->scheduler().work_left_for(worker_id, may);
    return out;
  }
  std::shared_ptr<JobRecord> job = find(l->task.job_id);
  if (job->state == JobState::Queued) set_state(*job, JobState::Running, "");
  auto assign = [&](const Lease& l) {
    ++counters_.tasks_leased;
    FrameRecord* f = job->by_number.at(l.task.frame);
    if (f->first_lease_at < 0) f->first_lease_at = now();
    return TaskAssignment{l.task,
                          l.lease_id,
                          job->tiles[l.task.tile],
                          f->scene_path,
                          job->files_of(f->version),
                          job->spec.overrides,
                          f->base.scene_digest};
  };
  out.task = assign(*l);
  // Batched leases: more of the same job while its tasks are known to be short.
  uint32_t batch = 1;
  if (max_tasks > 1 && job->tasks_timed >= kTasksBeforeBatching) {
    double task_seconds =
        job->timed_core_seconds / double(job->tasks_timed) / double(std::max(1u, me.info.cores));
    double fits = task_seconds > 0 ? kLeaseBatchSeconds / task_seconds : double(max_tasks);
    batch = uint32_t(std::clamp(fits, 1.0, double(std::min(max_tasks, kMaxTasksPerLease))));
  }
  if (batch > 1) {
    Journal::Hold hold(*journal_);  // the batch's lease rows in one transaction
    Scheduler::JobFilter same_job = [&](const std::string& id) { return id == job->id; };
    while (out.more.size() + 1 < batch)
      if (std::optional<Lease> next = ledger_->lease(worker_id, now(), same_job))
        out.more.push_back(assign(*next));
      else
        break;
  }
  return out;
}

uint32_t Coordinator::renew(const std::string& worker_id, const std::string& lease_id,
                            const Caller& caller) {
  std::lock_guard lock(mu_);
  check_worker(worker_id, caller);
  check_lease(worker_id, lease_id, nullptr);
  switch (ledger_->renew(lease_id, now())) {
    case LeaseOutcome::Ok:
      return uint32_t(std::max(1.0, options_.lease_seconds));
    case LeaseOutcome::NotFound:
      refuse(ErrorCode::NotFound, "no lease '" + clip(lease_id) + "'");
    case LeaseOutcome::Ended:
      break;
  }
  refuse(ErrorCode::FailedPrecondition,
         "lease " + lease_id +
             " has ended (it expired, its task was completed by another lease, or its job "
             "stopped)");
}

std::string Coordinator::blob(const std::string& sha256, const Caller& caller) const {
  if (!is_sha256_hex(sha256))
    refuse(ErrorCode::InvalidArgument,
           "'" + clip(sha256) + "' is not a SHA-256 (64 lower-case hex digits)");
  if (!caller.all_tenants) {
    std::lock_guard lock(mu_);
    bool leased = false;
    for (const std::string& id : ledger_->scheduler().leased_jobs([&](const std::string& w) {
           auto it = workers_.find(w);
           return it != workers_.end() && it->second.principal == caller.principal;
         })) {
      std::shared_ptr<JobRecord> job = find(id);
      if (!job) continue;
      for (uint32_t v = 0; v <= job->versions.added.size(); ++v)
        for (const BundleEntry& f : job->files_of(v)) leased |= f.sha256 == sha256;
    }
    // The same answer as for a blob the store lacks: a digest query reveals nothing.
    if (!leased)
      refuse(ErrorCode::NotFound, "no blob " + sha256 + " in a job your workers hold a lease of");
  }
  std::optional<std::string> bytes = blobs_.get(sha256);
  if (!bytes)
    refuse(ErrorCode::NotFound, "no blob " + sha256 + " in a job your workers hold a lease of");
  return std::move(*bytes);
}

}  // namespace rf
