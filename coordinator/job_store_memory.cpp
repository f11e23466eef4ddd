// The job store in memory (job_store.h): the same records and the same answers as SQLite's, for
// the core's unit tests and the coordinator fuzzer. Nothing survives the object; a batch is
// applied whole (it is checked first: a job id inserted twice throws, as SQLite's key does).
#include <algorithm>
#include <map>
#include <mutex>
#include <set>

#include "coordinator/job_store.h"

namespace rf {

namespace {

class MemoryJobStore final : public JobStore {
 public:
  void write(const std::vector<StoreWrite>& batch) override {
    std::lock_guard lock(mu_);
    std::set<std::string> inserted;
    for (const StoreWrite& w : batch)
      if (auto* j = std::get_if<store::InsertJob>(&w))
        if (index_.count(j->job.id) || !inserted.insert(j->job.id).second)
          throw StoreError("memory store: job " + j->job.id + " exists");
    for (const StoreWrite& w : batch) std::visit([&](const auto& x) { apply(x); }, w);
  }

  uint64_t next_seq() const override {
    std::lock_guard lock(mu_);
    uint64_t seq = 0;
    for (const StoredJob& j : jobs_) seq = std::max(seq, j.seq);
    return seq + 1;
  }
  std::vector<StoredJob> jobs() const override {
    std::lock_guard lock(mu_);
    std::vector<StoredJob> out;
    for (const StoredJob& j : jobs_)
      if (!deleted_.count(j.id)) out.push_back(j);
    std::stable_sort(out.begin(), out.end(),
                     [](const StoredJob& a, const StoredJob& b) { return a.seq < b.seq; });
    return out;
  }
  std::vector<StoredWorker> workers() const override {
    std::lock_guard lock(mu_);
    std::vector<StoredWorker> out;
    for (const auto& [id, w] : workers_) out.push_back(w);
    return out;
  }
  bool blob_tenant(const std::string& tenant, const std::string& sha256) const override {
    std::lock_guard lock(mu_);
    return blob_tenants_.count({tenant, sha256}) > 0;
  }
  void for_each_lease(const std::string& job_id,
                      const std::function<void(const StoredLease&)>& f) const override {
    std::vector<StoredLease> mine;
    {
      std::lock_guard lock(mu_);
      for (const StoredLease& l : leases_)
        if (l.job_id == job_id) mine.push_back(l);
    }
    for (const StoredLease& l : mine) f(l);
  }
  std::vector<TaskFailure> failures(const std::string& job_id) const override {
    std::vector<TaskFailure> out = failure_history(job_id);
    std::erase_if(out, [](const TaskFailure& f) { return !f.counted; });
    return out;
  }
  std::vector<TaskFailure> failure_history(const std::string& job_id) const override {
    std::lock_guard lock(mu_);
    std::vector<TaskFailure> out;
    for (const Event& e : events_)
      if (e.job_id == job_id && e.kind == TaskEventKind::Failed)
        out.push_back({e.frame, e.pass, e.tile, e.worker_id, e.message, e.counted});
    return out;
  }
  std::vector<std::string> refused_workers(const std::string& job_id) const override {
    std::lock_guard lock(mu_);
    std::vector<std::string> out;
    for (const Event& e : events_)
      if (e.job_id == job_id && e.kind == TaskEventKind::ResultRefused && e.counted)
        out.push_back(e.worker_id);
    return out;
  }
  std::vector<StoredAttempt> attempts(const std::string& job_id, std::optional<FrameNumber> frame,
                                      const std::optional<TaskRef>& task, size_t limit,
                                      bool* more) const override {
    std::lock_guard lock(mu_);
    std::vector<StoredAttempt> out;
    *more = false;
    for (auto it = attempts_.rbegin(); it != attempts_.rend(); ++it) {
      const StoredAttempt& a = *it;
      if (a.job_id != job_id || (frame && a.frame != *frame) ||
          (task && (a.frame != task->frame || a.pass != task->pass || a.tile != task->tile)))
        continue;
      if (out.size() == limit) {
        *more = true;
        break;
      }
      out.push_back(a);
    }
    std::reverse(out.begin(), out.end());
    return out;
  }
  std::optional<Tombstone> tombstone(const std::string& job_id) const override {
    std::lock_guard lock(mu_);
    auto it = tombstones_.find(job_id);
    if (it == tombstones_.end()) return std::nullopt;
    return it->second;
  }
  uint64_t tasks_done(const std::string& job_id) const override {
    std::lock_guard lock(mu_);
    return uint64_t(std::count_if(events_.begin(), events_.end(), [&](const Event& e) {
      return e.job_id == job_id && e.kind == TaskEventKind::Done;
    }));
  }

 private:
  StoredJob* job(const std::string& id) {
    auto it = index_.find(id);
    return it == index_.end() ? nullptr : &jobs_[it->second];
  }
  void apply(const store::InsertJob& w) {
    index_[w.job.id] = jobs_.size();
    jobs_.push_back(w.job);
  }
  void apply(const store::SetState& w) {
    if (StoredJob* j = job(w.job_id))
      j->state = w.state, j->error = w.error, j->ended_unix = w.ended_unix;
  }
  void apply(const store::AddCoreSeconds& w) {
    if (StoredJob* j = job(w.job_id)) j->core_seconds += w.seconds;
  }
  void apply(const store::SetBuild& w) {
    if (StoredJob* j = job(w.job_id)) j->build_id = w.build_id, j->cpu_kind = w.cpu_kind;
  }
  void apply(const store::SetPaused& w) {
    if (StoredJob* j = job(w.job_id)) j->paused = w.paused;
  }
  void apply(const store::SetPriority& w) {
    if (StoredJob* j = job(w.job_id)) j->priority = w.priority;
  }
  void apply(const store::Retry& w) {
    if (StoredJob* j = job(w.job_id)) j->held = w.held;
    if (w.forget_failures)
      for (Event& e : events_)
        if (e.job_id == w.job_id && e.kind != TaskEventKind::Done) e.counted = false;
  }
  void apply(const store::SetVersions& w) {
    if (StoredJob* j = job(w.job_id)) j->versions = w.versions;
  }
  void apply(const store::Attempt& w) { attempts_.push_back(w.attempt); }
  void apply(const store::DeleteJob& w) {
    deleted_.insert(w.job_id);
    if (StoredJob* j = job(w.job_id); j && w.expired_unix > 0)
      tombstones_[w.job_id] = {w.expired_unix, j->tenant};
    std::erase_if(attempts_, [&](const StoredAttempt& a) { return a.job_id == w.job_id; });
    std::erase_if(events_, [&](const Event& e) { return e.job_id == w.job_id; });
    std::erase_if(leases_, [&](const StoredLease& l) { return l.job_id == w.job_id; });
  }
  void apply(const store::TaskEvent& w) { events_.push_back({w, true}); }
  void apply(const store::InsertWorker& w) { workers_[w.worker.id] = w.worker; }
  void apply(const store::RefuseWorker& w) {
    if (auto it = workers_.find(w.worker_id); it != workers_.end()) it->second.refused = w.why;
  }
  void apply(const store::DeleteWorker& w) { workers_.erase(w.worker_id); }
  void apply(const store::AddBlobTenant& w) { blob_tenants_.insert({w.tenant, w.sha256}); }
  void apply(const store::ForgetBlob& w) {
    std::erase_if(blob_tenants_, [&](const auto& t) { return t.second == w.sha256; });
  }
  void apply(const store::InsertLease& w) {
    std::erase_if(leases_, [&](const StoredLease& l) { return l.lease_id == w.lease.lease_id; });
    leases_.push_back(w.lease);
  }
  void apply(const store::DeleteLeases& w) {
    std::erase_if(leases_, [&](const StoredLease& l) {
      return l.job_id == w.job_id && (!w.frame || l.frame == *w.frame);
    });
  }

  mutable std::mutex mu_;
  std::vector<StoredJob> jobs_;
  std::map<std::string, size_t> index_;
  std::set<std::string> deleted_;  // their rows stay (next_seq), unlisted
  std::map<std::string, Tombstone> tombstones_;  // of those, the ones retention expired
  std::vector<StoredAttempt> attempts_;
  struct Event : store::TaskEvent {
    bool counted = true;
  };
  std::vector<Event> events_;
  std::map<std::string, StoredWorker> workers_;
  std::set<std::pair<std::string, std::string>> blob_tenants_;
  std::vector<StoredLease> leases_;
};

}  // namespace

std::unique_ptr<JobStore> memory_store() { return std::make_unique<MemoryJobStore>(); }

}  // namespace rf
