// Retention (core.h): a job removed by a client's `delete` or expired by `--keep-finished`, the
// memory ended jobs release, and the blobs no job references collected after a grace period.
#include "coordinator/core_internal.h"
#include "coordinator/journal.h"
#include "coordinator/ledger.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <set>

#include "engine/digest.h"
#include "engine/progress.h"
#include "farm/auth.h"

namespace rf {

namespace fs = std::filesystem;
using core_detail::clip;
using core_detail::refuse;

void Coordinator::delete_job(const std::string& id, bool force, const Caller& caller) {
  std::shared_ptr<JobRecord> job;
  auto check = [&](const JobRecord& j) {
    if (!terminal(j.state) && !force)
      refuse(ErrorCode::FailedPrecondition,
             "job " + id + " is " + (j.state == JobState::Queued ? "queued" : "running") +
                 "; cancel it first, or delete --force");
  };
  {
    std::lock_guard lock(mu_);
    job = find_for(id, caller);
    check(*job);
  }
  remove_job(job, check, 0, "deleted by " + caller.principal);
}

void Coordinator::remove_job(const std::shared_ptr<JobRecord>& job,
                             const std::function<void(const JobRecord&)>& check,
                             int64_t expired_unix, const std::string& why) {
  const std::string& id = job->id;
  // No merge of the job is in progress while it goes (merges take a frame's lock before mu_).
  std::vector<std::unique_lock<std::mutex>> frame_locks;
  for (auto& f : job->frames) frame_locks.emplace_back(f->m);
  const std::string dir = options_.state_dir + "/jobs/" + id;
  const std::string tomb = options_.state_dir + "/jobs/.deleted-" + id;
  Ledger::Ticket ticket = 0;
  {
    std::lock_guard lock(mu_);
    if (job->deleted) refuse(ErrorCode::NotFound, "no job '" + clip(id) + "'");
    check(*job);
    // The point of no return: a restart finishes the removal from the renamed folder (an expiry
    // with its time, which the folder carries).
    if (fs::exists(dir)) {
      try {
        if (expired_unix > 0) write_file_atomic(dir + "/expired", std::to_string(expired_unix));
        rename_durably(dir, tomb);
      } catch (const std::exception& e) {
        refuse(ErrorCode::Unavailable, std::string("cannot remove job ") + id +
                                           " now: " + e.what() + "; nothing was removed");
      }
    }
    job->deleted = true;
    ticket = ledger_->delete_job(*job, expired_unix);
    jobs_.erase(id);
    reference_blobs(*job, 0, -1);
    std::erase_if(requests_, [&](const auto& r) { return r.second == id; });
    std::erase_if(verifying_, [&](const auto& v) { return v.first.job_id == id; });
    spdlog::info("job {} ({}) {}", id, job_state_name(job->state), why);
    ++version_;
    changed_.notify_all();
  }
  for (auto& f : job->frames) f->acc.reset();
  frame_locks.clear();
  wait_stored(ticket, "the removal");
  std::error_code ec;
  fs::remove_all(tomb, ec);
  if (ec)
    spdlog::warn("job {}: {} not removed ({}); the next start removes it", id, tomb, ec.message());
}

void Coordinator::reference_blobs(const JobRecord& job, uint32_t from_version, int delta) {
  for (uint32_t v = from_version; v <= job.versions.added.size(); ++v) {
    std::set<std::string> once;  // a bundle may name one content under two paths
    for (const BundleEntry& f : job.files_of(v)) once.insert(f.sha256);
    for (const std::string& d : once) {
      int64_t& n = blob_refs_[d];
      n += delta;
      if (n <= 0) blob_refs_.erase(d);
    }
  }
}

std::string Coordinator::expired_message(const std::string& id, const Caller& caller) const {
  std::optional<Tombstone> t;
  try {
    t = store_->tombstone(id);
  } catch (const StoreError&) {
    return "";
  }
  if (!t || (!caller.all_tenants && t->tenant != caller.tenant)) return "";
  return "job " + clip(id) + " expired at " + format_utc_time(t->expired_unix) +
         ": finished jobs are kept for " + duration_text(options_.keep_finished_seconds) +
         " (--keep-finished), then their images, checkpoints and records are removed";
}

Coordinator::Collected Coordinator::collect(double unix_now) {
  Collected out;
  // 1. Finished jobs past --keep-finished expire (as a delete, with a tombstone).
  std::vector<std::shared_ptr<JobRecord>> expiring, ended;
  {
    std::lock_guard lock(mu_);
    for (const auto& [id, job] : jobs_) {
      if (!terminal(job->state)) continue;
      if (options_.keep_finished_seconds > 0 &&
          double(job->ended_unix) + options_.keep_finished_seconds <= unix_now)
        expiring.push_back(job);
      else if (job->released_at != job->endings)  // once per ending, not at every pass
        ended.push_back(job);
    }
  }
  for (const auto& job : expiring) {
    const int64_t ended_at = job->ended_unix;
    try {
      remove_job(
          job,
          [&](const JobRecord& j) {  // a retry or requeue since: it runs again
            if (!terminal(j.state) || j.ended_unix != ended_at)
              refuse(ErrorCode::FailedPrecondition, "runs again");
          },
          int64_t(unix_now),
          "expired: ended " + duration_text(unix_now - double(ended_at)) +
              " ago (--keep-finished " + duration_text(options_.keep_finished_seconds) + ")");
      ++out.jobs_expired;
    } catch (const CoordinatorError& e) {
      if (e.code != ErrorCode::FailedPrecondition && e.code != ErrorCode::NotFound)
        spdlog::warn("job {}: not expired now: {}", job->id, e.what());
    }
  }
  // 2. Ended jobs keep no accumulator: their images are in their checkpoints (fetch reads them).
  for (const auto& job : ended) {
    uint64_t endings = 0;
    {
      std::lock_guard lock(mu_);
      endings = job->endings;
    }
    for (auto& f : job->frames) {
      std::lock_guard frame_lock(f->m);
      std::lock_guard lock(mu_);
      if (terminal(job->state) && f->acc) {
        f->acc.reset();
        ++out.accumulators_released;
      }
    }
    std::lock_guard lock(mu_);
    if (terminal(job->state) && job->endings == endings) job->released_at = endings;
  }
  // 3. Blobs no job references (any scene version of any job the coordinator holds) and not
  // stored or asked for within the grace period. A submit or requeue being checked references
  // its blobs only once accepted: the grace period (far longer than a scene check may take)
  // covers it, as it covers the time between a client's MissingBlobs and its Submit.
  // The store is listed off the lock; only the reference counts are read under it.
  std::vector<BlobStore::Entry> stored_blobs = blobs_.list(), unused;
  uint64_t stored = 0;
  {
    std::lock_guard lock(mu_);
    for (BlobStore::Entry& b : stored_blobs) {
      stored += b.bytes;
      if (!blob_refs_.count(b.sha256) && b.used_unix + options_.blob_grace_seconds <= unix_now)
        unused.push_back(std::move(b));
    }
  }
  std::vector<StoreWrite> forget;
  for (const BlobStore::Entry& b : unused) {
    if (!blobs_.remove(b.sha256)) continue;
    stored -= b.bytes;
    forget.push_back(store::ForgetBlob{b.sha256});
    ++out.blobs_removed;
    out.blob_bytes_removed += b.bytes;
  }
  {
    std::lock_guard lock(mu_);
    if (!forget.empty()) journal_->append(std::move(forget));  // a lost row names a blob gone
    counters_.jobs_expired += out.jobs_expired;
    counters_.blobs_collected += out.blobs_removed;
    counters_.blob_bytes_collected += out.blob_bytes_removed;
    blob_store_bytes_ = stored;
  }
  if (out.jobs_expired || out.blobs_removed)
    spdlog::info("retention: {} jobs expired, {} blobs ({} bytes) no job references removed",
                 out.jobs_expired, out.blobs_removed, out.blob_bytes_removed);
  return out;
}

}  // namespace rf
