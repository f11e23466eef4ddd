// The Coordinator facade (core.h): construction, the job list and status, fetch, storage
// health and metrics. Intake, recovery, workers and leases, and results are in their own files.
#include "coordinator/core_internal.h"
#include "coordinator/journal.h"
#include "coordinator/ledger.h"

#include <spdlog/spdlog.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "engine/buffer_file.h"
#include "engine/digest.h"
#include "farm/tags.h"

namespace rf {

namespace fs = std::filesystem;
using core_detail::clip;
using core_detail::refuse;
using core_detail::unix_now;

namespace {

CoreOptions with_defaults(CoreOptions o) {
  if (!o.scene_checker)
    throw std::invalid_argument("CoreOptions::scene_checker is required (scene_check.h)");
  if (o.instance.empty())
    o.instance = sha256_hex(std::to_string(unix_now()) + std::to_string(::getpid())).substr(0, 8);
  if (!o.clock) {
    auto start = std::chrono::steady_clock::now();
    o.clock = [start] {
      return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    };
  }
  return o;
}

}  // namespace

bool terminal(JobState s) {
  return s == JobState::Completed || s == JobState::Failed || s == JobState::Cancelled;
}

const char* job_state_name(JobState s) {
  switch (s) {
    case JobState::Queued:
      return "JOB_QUEUED";
    case JobState::Running:
      return "JOB_RUNNING";
    case JobState::Completed:
      return "JOB_COMPLETED";
    case JobState::Failed:
      return "JOB_FAILED";
    case JobState::Cancelled:
      return "JOB_CANCELLED";
  }
  return "JOB_STATE_UNSPECIFIED";
}

Coordinator::Coordinator(CoreOptions o)
    : options_(with_defaults(std::move(o))),
      lock_(options_.state_dir),
      blobs_(options_.state_dir + "/blobs"),  // creates the state directory too
      store_(options_.store ? options_.store
                            : open_sqlite_store(options_.state_dir + "/jobs.sqlite")),
      journal_(std::make_unique<Journal>(
          *store_,
          [this](const std::string& problem) {
            std::lock_guard lock(mu_);  // the journal's writer thread, holding no lock of its own
            problem.empty() ? storage_ok() : storage_failed(problem);
          })),
      results_sync_(std::make_unique<GroupSync>(options_.state_dir)),
      ledger_(std::make_unique<Ledger>(
          SchedulerOptions{
              options_.lease_seconds, options_.max_failures, options_.window_frames,
              options_.instance + "-L", options_.share,
              [this](const std::string& lease, const std::string& worker, const TaskRef& task) {
                ++counters_.leases_expired;  // the scheduler is driven under mu_
                spdlog::warn("lease {} of worker {} on task {} expired: not renewed for {:g} s",
                             lease, worker, task_id_text(task), options_.lease_seconds);
                ledger_->expired(lease, now());
              }},
          *journal_, options_.clock, unix_now() - options_.clock())) {
  counters_.lease_buckets.assign(std::size(CoordinatorMetrics::kLeaseBuckets), 0);
  next_seq_ = store_->next_seq();
  for (const StoredWorker& w : store_->workers()) {
    // A worker of before the restart has the sweep's time from now to call.
    workers_[w.id] = {w.principal, w.build_id, w.isa, WorkerInfo{"", 0, w.build_id, w.isa, w.tags},
                      now()};
    if (!w.refused.empty()) outvoted_[w.id] = w.refused;
  }
  finish_deletes();
  for (const StoredJob& j : store_->jobs()) restore(j);
  recover_folders();
}

Coordinator::~Coordinator() {
  // The journal stores what is queued and stops its writer (which may lock mu_) before the rest
  // goes.
  ledger_.reset();
  journal_.reset();
}

bool Coordinator::pin_ok(const JobRecord& job, const std::string& build_id,
                         const std::string& cpu_kind) const {
  return (job.build_id.empty() || job.build_id == build_id) &&
         (job.cpu_kind.empty() || cpu_kind.empty() || job.cpu_kind == cpu_kind);
}

std::string Coordinator::pin_problem(const JobRecord& job, const BufferHeader& h) const {
  if (!job.build_id.empty() && job.build_id != h.build_id)
    return "job " + job.id + " merges results of build '" + job.build_id + "'; this one is from '" +
           clip(h.build_id) + "'";
  if (!job.cpu_kind.empty() && job.cpu_kind != h.isa)
    return "job " + job.id + " merges results of CPU kind '" + job.cpu_kind +
           "' (the determinism contract holds per build and CPU kind); this one is from '" +
           clip(h.isa) + "'";
  return "";
}

std::shared_ptr<JobRecord> Coordinator::find(const std::string& id) const {
  auto it = jobs_.find(id);
  return it == jobs_.end() ? nullptr : it->second;
}

std::shared_ptr<JobRecord> Coordinator::find_or_throw(const std::string& id) const {
  std::shared_ptr<JobRecord> job = find(id);
  if (!job) refuse(ErrorCode::NotFound, "no job '" + clip(id) + "'");
  return job;
}

std::shared_ptr<JobRecord> Coordinator::find_for(const std::string& id,
                                                 const Caller& caller) const {
  std::shared_ptr<JobRecord> job = find(id);
  // Another tenant's job is refused as a missing one: the answer tells no tenant which ids exist.
  if (!job || (!caller.all_tenants && job->tenant != caller.tenant)) {
    if (std::string expired = job ? "" : expired_message(id, caller); !expired.empty())
      refuse(ErrorCode::NotFound, expired);
    refuse(ErrorCode::NotFound, "no job '" + clip(id) + "'");
  }
  return job;
}

// The last merge's figures, with the ETA from this frame's time per pass in this run so far;
// none (-1) while nothing renders it: its job ended (cancelled, failed) or paused, or it is held.
FrameStatus Coordinator::frame_status(const JobRecord& job, const FrameRecord& f) const {
  FrameStatus s{f.number, f.progress, f.version, f.run};
  FrameProgress& p = s.progress;
  double seconds = f.first_lease_at < 0 ? -1 : now() - f.first_lease_at;
  p.eta_seconds =
      p.done ? 0
      : terminal(job.state) || job.paused || f.held
          ? -1
          : eta_seconds(p.passes_merged, p.passes_total, p.rel_mse, job.noise_target, seconds);
  return s;
}

std::string Coordinator::waiting_for(const JobRecord& job) const {
  for (const auto& [id, w] : workers_)
    if (!outvoted_.count(id) && pin_ok(job, w.build_id, w.isa) &&
        satisfies_all(w.info.tags, job.spec.required_tags))
      return "";
  if (workers_.empty()) return "no worker is registered";
  std::string needs;
  for (const std::string& r : job.spec.required_tags) needs += (needs.empty() ? "tags " : " ") + r;
  if (!job.build_id.empty()) needs += (needs.empty() ? "" : "; ") + ("build " + job.build_id);
  if (!job.cpu_kind.empty()) needs += (needs.empty() ? "" : "; ") + ("CPU kind " + job.cpu_kind);
  return "no registered worker has what it needs: " + needs;
}

JobStatus Coordinator::status_of(const JobRecord& job) const {
  JobStatus s;
  s.job_id = job.id;
  s.name = job.spec.name;
  s.tenant = job.tenant;
  s.build_id = job.build_id;
  s.cpu_kind = job.cpu_kind;
  s.state = job.state;
  s.error = job.error;
  if (!terminal(job.state) && !storage_problem_.empty())
    s.error = "waiting for the coordinator's storage: " + storage_problem_;
  s.core_seconds = job.core_seconds;
  s.noise_target = job.noise_target;
  s.submitted_unix = job.submitted_unix;
  s.paused = job.paused;
  s.priority = job.priority;
  s.settings = job.spec.overrides;
  s.scene_path = job.spec.scene_path;
  s.tile_size = job.spec.tile_size;
  s.required_tags = job.spec.required_tags;
  if (terminal(job.state)) s.ended_unix = job.ended_unix;
  if (!terminal(job.state) && !job.paused) s.waiting_for = waiting_for(job);
  for (const auto& f : job.frames) {
    s.frames.push_back(frame_status(job, *f));
    if (f->held && !f->progress.done) s.held.push_back(f->number);
  }
  return s;
}

std::vector<JobStatus> Coordinator::list(const Caller& caller, size_t limit,
                                         const std::string& after, bool* more) const {
  std::lock_guard lock(mu_);
  uint64_t after_seq = 0;
  if (!after.empty()) after_seq = find_for(after, caller)->seq;
  std::vector<const JobRecord*> order;
  for (auto& [id, j] : jobs_)
    if ((caller.all_tenants || j->tenant == caller.tenant) && j->seq > after_seq)
      order.push_back(j.get());
  std::sort(order.begin(), order.end(), [](auto* a, auto* b) { return a->seq < b->seq; });
  if (more) *more = order.size() > limit;
  if (order.size() > limit) order.resize(limit);
  std::vector<JobStatus> out;
  for (const JobRecord* j : order) out.push_back(status_of(*j));
  return out;
}

JobStatus Coordinator::status(const std::string& id, const Caller& caller) const {
  std::lock_guard lock(mu_);
  return status_of(*find_for(id, caller));
}

std::optional<JobStatus> Coordinator::next_status(const std::string& id, uint64_t& seen,
                                                  double timeout, const Caller& caller) const {
  std::unique_lock lock(mu_);
  std::shared_ptr<JobRecord> job = find_for(id, caller);
  if (seen == version_) {
    if (closing_) refuse(ErrorCode::Unavailable, "the coordinator is shutting down");
    changed_.wait_for(lock, std::chrono::duration<double>(timeout));
    if (seen == version_) return std::nullopt;
  }
  seen = version_;
  return status_of(*job);
}

FrameImage Coordinator::fetch(const std::string& job_id, FrameNumber frame,
                              const Caller& caller) const {
  FrameImage image;
  std::shared_ptr<JobRecord> job;
  FrameRecord* f = nullptr;
  {
    std::lock_guard lock(mu_);
    job = find_for(job_id, caller);
    auto it = job->by_number.find(frame);
    if (it == job->by_number.end())
      refuse(ErrorCode::NotFound, "job " + job->id + " has no frame " + std::to_string(frame));
    f = it->second;
    image.status = frame_status(*job, *f);
  }
  std::lock_guard frame_lock(f->m);
  if (f->acc && f->acc->passes_merged() > 0 && !f->acc->tiled()) {
    image.buffer = encode_buffer(f->acc->frame());
  } else {  // its checkpoint (a frame kept in tiles saves its prefix at every pass merged)
    std::string path = f->checkpoint->dir() + "/prefix.rfb";
    if (!fs::exists(path))
      refuse(ErrorCode::FailedPrecondition, "frame " + std::to_string(f->number) + " of job " +
                                                job->id + " has no complete pass yet");
    auto file = std::make_shared<FrameImage::File>();
    file->fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    struct stat st {};
    if (file->fd < 0 || ::fstat(file->fd, &st) != 0)
      refuse(ErrorCode::Unavailable, path + ": cannot read: " + std::strerror(errno));
    file->size = uint64_t(st.st_size);
    if (options_.frame_memory > 0 && file->size > options_.frame_memory)
      image.file = std::move(file);
    else
      image.buffer = read_file_bytes(path);
  }
  return image;
}

FrameHistory Coordinator::frame_history(const std::string& job_id, FrameNumber frame,
                                        const Caller& caller) const {
  std::lock_guard lock(mu_);
  std::shared_ptr<JobRecord> job = find_for(job_id, caller);
  auto it = job->by_number.find(frame);
  if (it == job->by_number.end())
    refuse(ErrorCode::NotFound, "job " + job->id + " has no frame " + std::to_string(frame));
  return {frame_status(*job, *it->second), job->noise_target, it->second->history};
}

FrameImage::File::~File() {
  if (fd >= 0) ::close(fd);
}

std::string Coordinator::storage_problem() const {
  std::lock_guard lock(mu_);
  return storage_problem_;
}

void Coordinator::set_storage_listener(std::function<void(const std::string&)> listener) {
  std::lock_guard lock(mu_);
  storage_listener_ = std::move(listener);
}

void Coordinator::storage_failed(const std::string& why) {
  if (storage_problem_.empty())
    spdlog::error("cannot store results: {}; refusing them UNAVAILABLE until it can", why);
  bool changed = storage_problem_ != why;
  storage_problem_ = why;
  if (changed && storage_listener_) storage_listener_(why);
  ++version_;
  changed_.notify_all();
}

void Coordinator::storage_ok() {
  if (storage_problem_.empty()) return;
  spdlog::info("results are stored again (was: {})", storage_problem_);
  storage_problem_.clear();
  if (storage_listener_) storage_listener_("");
  ++version_;
  changed_.notify_all();
}

TaskLog Coordinator::task_log(const std::string& job_id, std::optional<FrameNumber> frame,
                              const std::string& task_id, uint32_t limit,
                              const Caller& caller) const {
  std::optional<TaskRef> task;
  if (!task_id.empty()) {
    task = parse_task_id(task_id);
    if (!task || task->job_id != job_id)
      refuse(ErrorCode::InvalidArgument, "task '" + clip(task_id) + "' is not a task id of job " +
                                             clip(job_id) + " (JOB/FRAME/PASS/TILE)");
    if (frame && *frame != task->frame)
      refuse(ErrorCode::InvalidArgument,
             "task " + task_id + " is not of frame " + std::to_string(*frame));
  }
  limit = limit == 0 ? 100 : std::min<uint32_t>(limit, 10000);
  TaskLog out;
  std::vector<Scheduler::LeaseInfo> live;
  double unix_offset = 0;
  uint64_t ticket = 0;
  {
    std::lock_guard lock(mu_);
    std::shared_ptr<JobRecord> job = find_for(job_id, caller);
    if (frame && !job->by_number.count(*frame))
      refuse(ErrorCode::NotFound, "job " + job->id + " has no frame " + std::to_string(*frame));
    live = ledger_->scheduler().live_leases(job_id, task ? task->frame : frame);
    unix_offset = unix_now() - now();
    ticket = journal_->append({});  // the attempts ended so far, queued for the store
  }
  wait_stored(ticket, "the task log");
  // The store answers on its own connection: a long history is read without the lock.
  out.attempts = store_->attempts(job_id, frame, task, limit, &out.more);
  for (const Scheduler::LeaseInfo& l : live) {
    if (task && !(l.task == *task)) continue;
    out.attempts.push_back({l.task.job_id,
                            l.task.frame,
                            l.task.pass,
                            l.task.tile,
                            l.lease_id,
                            l.worker_id,
                            l.leased_at < 0 ? 0 : l.leased_at + unix_offset,
                            0,
                            AttemptOutcome::Running,
                            "",
                            {}});
  }
  return out;
}

CoordinatorMetrics Coordinator::metrics() const {
  std::lock_guard lock(mu_);
  CoordinatorMetrics m;
  m.counters = counters_;
  m.counters.calls_refused = refused_calls_;
  m.counters.refusal_lines_suppressed = suppressed_refusal_lines_;
  m.counters.result_flushes = results_sync_->flushes();
  m.counters.store_commits = journal_->batches();
  m.storage_ok = storage_problem_.empty();
  m.blob_store_bytes = blob_store_bytes_;
  m.pools[kAnyPool];  // always shown, 0 when idle
  for (const auto& [id, w] : workers_) m.workers_registered += !outvoted_.count(id);
  for (const auto& [id, seen] : last_seen_)
    m.workers_connected += now() - seen <= options_.lease_seconds && !outvoted_.count(id);
  std::map<std::string, Scheduler::JobLoad> load = ledger_->scheduler().load_by_job();
  for (const auto& [id, job] : jobs_) {
    ++m.jobs_by_state[size_t(job->state)];
    if (terminal(job->state)) continue;
    CoordinatorMetrics::Job j;
    j.job_id = id;
    if (auto it = load.find(id); it != load.end()) {
      j.tasks_queued = it->second.queued;
      j.tasks_leased = it->second.leased;
    }
    (job->paused ? m.tasks_paused : m.tasks_queued) += j.tasks_queued;
    m.tasks_leased += j.tasks_leased;
    const std::string pool = pool_of(job->spec.required_tags);
    CoordinatorMetrics::Pool& p = m.pools[pool.empty() ? kAnyPool : pool];
    if (!job->paused) p.tasks_queued += j.tasks_queued;
    p.tasks_leased += j.tasks_leased;
    for (const auto& f : job->frames)
      if (!f->progress.done && f->progress.passes_merged > 0)
        j.frames.push_back(frame_status(*job, *f));
    m.jobs.push_back(std::move(j));
  }
  return m;
}

void Coordinator::shut_down() {
  std::lock_guard lock(mu_);
  closing_ = true;
  changed_.notify_all();
}

}  // namespace rf
