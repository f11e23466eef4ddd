// Results (core.h): a task's result checked, made durable and merged into its frame, verified
// against another worker's, refused or failed; a frame's and a job's end.
#include "coordinator/core_internal.h"
#include "coordinator/journal.h"
#include "coordinator/ledger.h"

#include <spdlog/spdlog.h>

#include <filesystem>

#include "engine/buffer_file.h"
#include "engine/digest.h"
#include "farm/frame_range.h"

namespace rf {

namespace fs = std::filesystem;
using core_detail::clip;
using core_detail::ended_verb;
using core_detail::refuse;
using core_detail::unix_now;

std::set<FrameNumber> core_detail::named_frames(const JobRecord& job, const std::string& frames) {
  std::set<FrameNumber> named;
  if (frames.empty()) {
    for (FrameNumber n : job.frame_numbers()) named.insert(n);
    return named;
  }
  try {
    for (FrameNumber n : parse_frame_range(frames)) {
      if (!job.by_number.count(n))
        refuse(ErrorCode::InvalidArgument,
               "frames: job " + job.id + " has no frame " + std::to_string(n));
      named.insert(n);
    }
  } catch (const FrameRangeError& e) {
    refuse(ErrorCode::InvalidArgument, std::string("frames: ") + e.what());
  }
  return named;
}

// A point for the frame's history when its prefix grew. Full, it keeps every other point and
// doubles the stride, so a frame of any number of passes keeps at most kHistoryPoints spread
// over its whole life, and the last point is always the latest prefix.
static void note_history(FrameRecord& f) {
  const uint32_t passes = f.progress.passes_merged;
  if (passes == 0 || (!f.history.empty() && f.history.back().passes >= passes)) return;
  ProgressPoint p{
      double(unix_now()), passes,
      passes >= 2 && std::isfinite(f.progress.rel_mse) ? float(f.progress.rel_mse) : 0.0f};
  // The previous point stays only if it is on the stride (or the first): the last point
  // always moves to the latest prefix.
  if (f.history.size() >= 2 && f.history.back().passes % f.history_stride != 0)
    f.history.back() = p;
  else
    f.history.push_back(p);
  if (f.history.size() >= kHistoryPoints) {
    f.history_stride *= 2;
    std::vector<ProgressPoint> kept;
    for (size_t i = 0; i < f.history.size(); ++i)
      if (i == 0 || i + 1 == f.history.size() || f.history[i].passes % f.history_stride == 0)
        kept.push_back(f.history[i]);
    f.history = std::move(kept);
  }
}

// After a merge or a restore: the frame's figures, the scheduler's stop, the job's completion.
void Coordinator::publish_frame(JobRecord& job, FrameRecord& f) {
  if (f.acc) f.progress = frame_progress(*f.acc, job.passes, job.noise_target, -1);
  note_history(f);
  if (f.progress.done) ledger_->frame_done(job, f, f.progress.passes_merged);
  bool all_done = f.progress.done;  // an unfinished frame: no need to look at the others
  std::vector<FrameNumber> held;
  for (auto& g : job.frames) {
    if (!all_done) break;  // (a job of 10,000 frames looked at each at every result)
    if (g->held && !g->progress.done)
      held.push_back(g->number);
    else
      all_done &= g->progress.done;
  }
  if (all_done && !terminal(job.state)) {
    if (held.empty())
      set_state(job, JobState::Completed, "");
    else
      set_state(job, JobState::Failed,
                "frames " + frame_range_text(held) +
                    " were left out of a retry and are not rendered; `retry` renders them");
  }
  ++version_;
  changed_.notify_all();
}

uint64_t Coordinator::set_state(JobRecord& job, JobState s, const std::string& err) {
  Ledger::Ticket ticket = ledger_->set_state(job, s, err);
  if (terminal(s)) {
    write_folder_state(job);
    for (auto it = verifying_.begin(); it != verifying_.end();)  // held results go with it
      it = it->first.job_id == job.id ? verifying_.erase(it) : std::next(it);
    spdlog::info("job {} {}{}", job.id, job_state_name(s), err.empty() ? "" : ": " + err);
  }
  ++version_;
  changed_.notify_all();
  return ticket;
}

void Coordinator::cancel(const std::string& id, const Caller& caller) {
  std::shared_ptr<JobRecord> job;
  Ledger::Ticket ticket = 0;
  {
    std::lock_guard lock(mu_);
    job = find_for(id, caller);
    if (job->state == JobState::Cancelled) return;  // idempotent: a second or retried cancel
    if (terminal(job->state))
      refuse(ErrorCode::FailedPrecondition, "job " + id + " has already " + ended_verb(job->state) +
                                                "; there is nothing to cancel");
    ticket = set_state(*job, JobState::Cancelled, "cancelled by " + caller.principal);
  }
  wait_stored(ticket, "the cancellation");
  // Its merged passes are in the checkpoints (fetch reads them there): the accumulators go,
  // unless a retry came meanwhile and made the frames its own again.
  for (auto& f : job->frames) {
    std::lock_guard frame_lock(f->m);
    std::lock_guard lock(mu_);
    if (job->state == JobState::Cancelled) f->acc.reset();
  }
}

void Coordinator::change_setting(const std::string& id, const Caller& caller,
                                 const std::string& action, const std::string& refused_because,
                                 const std::function<bool(const JobRecord&)>& unchanged,
                                 const std::function<uint64_t(JobRecord&)>& change) {
  Ledger::Ticket ticket = 0;
  {
    std::lock_guard lock(mu_);
    std::shared_ptr<JobRecord> job = find_for(id, caller);
    if (terminal(job->state))
      refuse(ErrorCode::FailedPrecondition,
             "job " + id + " has already " + ended_verb(job->state) + "; " + refused_because);
    if (unchanged(*job)) return;  // idempotent: a second or retried call
    ticket = change(*job);
    write_folder_state(*job);
    spdlog::info("job {} {} by {}", job->id, action, caller.principal);
    ++version_;
    changed_.notify_all();
  }
  wait_stored(ticket, "the change (" + action + ")");
}

void Coordinator::set_paused(const std::string& id, bool paused, const Caller& caller) {
  change_setting(
      id, caller, paused ? "paused" : "resumed",
      std::string("there is nothing to ") + (paused ? "pause" : "resume"),
      [&](const JobRecord& j) { return j.paused == paused; },
      [&](JobRecord& j) { return ledger_->set_paused(j, paused); });
}

void Coordinator::set_priority(const std::string& id, int priority, const Caller& caller) {
  change_setting(
      id, caller, "given priority " + std::to_string(priority), "its priority no longer matters",
      [&](const JobRecord& j) { return j.priority == priority; },
      [&](JobRecord& j) { return ledger_->set_priority(j, priority); });
}

void Coordinator::retry(const std::string& id, const std::string& frames, const Caller& caller) {
  std::shared_ptr<JobRecord> job;
  JobState was = JobState::Queued;
  std::vector<FrameRecord*> reopen;
  std::vector<FrameNumber> held;
  {
    std::lock_guard lock(mu_);
    job = find_for(id, caller);
    was = job->state;
    if (was == JobState::Completed)
      refuse(ErrorCode::FailedPrecondition,
             "job " + id +
                 " has completed; there is nothing to retry (`requeue` renders frames "
                 "again)");
    if (job->frames.empty() || !job->bundle_problem.empty())
      refuse(ErrorCode::FailedPrecondition,
             "job " + id + " cannot run again: " +
                 (job->bundle_problem.empty() ? job->error : job->bundle_problem));
    const std::set<FrameNumber> named = core_detail::named_frames(*job, frames);
    const bool ended = terminal(was);
    for (const auto& f : job->frames) {
      if (f->progress.done || !(ended || f->held)) continue;  // done, or running already
      if (named.count(f->number))
        reopen.push_back(f.get());
      else
        held.push_back(f->number);
    }
    std::sort(held.begin(), held.end());
    if (reopen.empty()) {
      if (!ended) return;  // what it names runs already: a second or retried call
      refuse(ErrorCode::FailedPrecondition, "job " + id + ": frames " +
                                                frame_range_text({named.begin(), named.end()}) +
                                                " are done; there is nothing to retry");
    }
  }
  // Each frame's checkpoint is read under its own lock (merges take it before mu_), off mu_.
  std::vector<std::unique_lock<std::mutex>> frame_locks;
  std::vector<LoadedFrame> loaded;
  for (FrameRecord* f : reopen) {
    frame_locks.emplace_back(f->m);
    loaded.push_back(load_frame(*job, *f));
  }
  Ledger::Ticket ticket = 0;
  {
    std::lock_guard lock(mu_);
    if (job->deleted) refuse(ErrorCode::NotFound, "no job '" + clip(id) + "'");
    bool same = job->state == was;
    for (FrameRecord* f : reopen) same &= terminal(was) || f->held;
    if (!same) return;  // another retry (or a cancel) came between: it stands
    std::vector<FrameNumber> numbers;
    for (FrameRecord* f : reopen) numbers.push_back(f->number);
    ticket = ledger_->retry(*job, numbers, held);
    for (const auto& f : job->frames)
      f->held = std::binary_search(held.begin(), held.end(), f->number);
    for (size_t i = 0; i < reopen.size(); ++i) {
      reopen[i]->leases_dropped = false;
      reopen[i]->first_lease_at = -1;
      reopen[i]->acc.reset();  // the checkpoint holds every merged result
      adopt_frame(*job, *reopen[i], std::move(loaded[i]));
    }
    write_folder_state(*job);
    spdlog::info("job {} retried by {}: frames {} queued{}", job->id, caller.principal,
                 frame_range_text(numbers),
                 held.empty() ? "" : ", frames " + frame_range_text(held) + " held");
    ++version_;
    changed_.notify_all();
  }
  frame_locks.clear();
  wait_stored(ticket, "the retry");
}

// Decodes a result where it lies and checks it belongs to its task: the task's tile, its one
// pass, and the frame's header (scene digest, seed, frame, integrator, settings, resolution).
EncodedBuffer Coordinator::checked_buffer(const JobRecord& job, const BufferHeader& base,
                                          TaskResult& r) const {
  std::string task_id = task_id_text(r.task);
  EncodedBuffer encoded;
  try {
    encoded = EncodedBuffer(std::move(r.buffer), "sample buffer of task " + task_id);
  } catch (const std::exception& e) {
    refuse(ErrorCode::InvalidArgument, e.what());
  }
  const BufferView buffer = encoded.view();
  const Rect& rect = job.tiles[r.task.tile];
  if (!(buffer.rect == rect))
    refuse(ErrorCode::InvalidArgument,
           "task " + task_id + ": buffer covers " + std::to_string(buffer.rect.w) + "x" +
               std::to_string(buffer.rect.h) + " at " + std::to_string(buffer.rect.x0) + "," +
               std::to_string(buffer.rect.y0) + ", not the task's tile");
  if (!(buffer.header->passes == PassSet::range(r.task.pass, r.task.pass + 1)))
    refuse(ErrorCode::InvalidArgument, "task " + task_id + ": buffer holds passes " +
                                           buffer.header->passes.to_string() + ", not pass " +
                                           std::to_string(r.task.pass));
  if (std::string why = merge_incompatibility(base, *buffer.header); !why.empty())
    refuse(ErrorCode::InvalidArgument, "task " + task_id + ": " + why);
  if (std::string why = task_buffer_problem(buffer, job.spp_per_pass); !why.empty())
    refuse(ErrorCode::InvalidArgument, "task " + task_id + ": " + why);
  return encoded;
}

// The ledger's verdict on a durable result: the task done (its rows to the journal), or, when it
// is settled already, its lease ended.
bool Coordinator::record_result(JobRecord& job, const TaskResult& r, const BufferHeader& h) {
  if (ledger_->scheduler().settled(r.task)) {
    ledger_->not_needed(r.lease_id, r.task, r.worker_id, now(), r.log);
    return false;  // another result came first, or the job was cancelled or failed meanwhile
  }
  ledger_->complete(job, r.lease_id, r.task, r.worker_id, h.core_seconds, h.build_id, h.isa, now(),
                    r.log);
  return true;
}

void Coordinator::wait_stored(uint64_t ticket, const std::string& what) const {
  if (journal_->wait(ticket, kStoreWaitSeconds)) return;
  refuse(ErrorCode::Unavailable, "the coordinator cannot store " + what + " now (" +
                                     journal_->problem() + "); it is kept and stored when the " +
                                     "disk takes it: retry later");
}

bool Coordinator::check_upload(const std::string& worker_id, const std::string& lease_id,
                               const TaskRef& task, const Caller& caller) const {
  std::lock_guard lock(mu_);
  check_worker(worker_id, caller);
  std::shared_ptr<JobRecord> job = find_or_throw(task.job_id);
  if (!job->by_number.count(task.frame) || task.tile >= job->tiles.size() ||
      task.pass >= job->passes)
    refuse(ErrorCode::NotFound, "job " + job->id + " has no task " + task_id_text(task));
  return check_lease(worker_id, lease_id, &task) && !ledger_->scheduler().settled(task);
}

void Coordinator::refuse_upload(const std::string& worker_id, const std::string& lease_id,
                                const TaskRef& task, const std::string& why,
                                const std::vector<std::string>& log) {
  spdlog::warn("refused the result of task {} from worker {}: {}", task_id_text(task),
               clip(worker_id), why);
  std::lock_guard lock(mu_);
  ++counters_.results_refused;
  if (!find(task.job_id)) return;  // deleted meanwhile: nothing of it is recorded any more
  ledger_->refuse_result(worker_id, lease_id, task, why, now(), bounded_log(log));
}

// A result between its check and its merge: decoded, its record written to the frame's log
// (unflushed), its key marked as storing.
struct Coordinator::StagedResult {
  TaskResult r;
  std::shared_ptr<JobRecord> job;
  FrameRecord* f = nullptr;
  uint32_t run = 0;
  EncodedBuffer buffer;
  std::pair<uint32_t, uint32_t> key;
  std::unique_ptr<GroupSync::Writer> writer;  // announced before the write (group_sync.h)
};

bool Coordinator::complete(TaskResult r, const Caller& caller) {
  std::unique_ptr<StagedResult> s;
  if (std::optional<bool> answered = stage_result(std::move(r), caller, s)) return *answered;
  std::string flush_error;
  try {
    s->writer->sync();
  } catch (const std::exception& e) {
    flush_error = e.what();
  }
  uint64_t ticket = 0;
  bool merged = commit_result(*s, flush_error, ticket);
  wait_stored(ticket, "the result's record");
  return merged;
}

std::vector<Coordinator::ResultOutcome> Coordinator::complete_batch(std::vector<TaskResult> results,
                                                                    const Caller& caller) {
  std::vector<ResultOutcome> out(results.size());
  std::vector<std::pair<size_t, std::unique_ptr<StagedResult>>> staged;
  for (size_t i = 0; i < results.size(); ++i) {
    try {
      std::unique_ptr<StagedResult> s;
      if (std::optional<bool> answered = stage_result(std::move(results[i]), caller, s)) {
        out[i].accepted = *answered;
        continue;
      }
      s->writer.reset();  // written: the one sync below covers it
      staged.emplace_back(i, std::move(s));
    } catch (const CoordinatorError& e) {
      out[i].error = e;
    }
  }
  if (staged.empty()) return out;
  std::string flush_error;
  try {
    results_sync_->sync();  // after every write above: one flush for the batch
  } catch (const std::exception& e) {
    flush_error = e.what();
  }
  uint64_t ticket = 0;
  {
    Journal::Hold hold(*journal_);  // the batch's rows in one transaction
    for (auto& [i, s] : staged) {
      try {
        out[i].accepted = commit_result(*s, flush_error, ticket);
      } catch (const CoordinatorError& e) {
        out[i].error = e;
      }
    }
  }
  try {
    wait_stored(ticket, "the results' records");
  } catch (const CoordinatorError& e) {
    for (auto& [i, s] : staged)
      if (!out[i].error) out[i] = {false, e};
  }
  return out;
}

std::optional<bool> Coordinator::stage_result(TaskResult r, const Caller& caller,
                                              std::unique_ptr<StagedResult>& staged) {
  if (!check_upload(r.worker_id, r.lease_id, r.task, caller)) return false;  // not needed
  std::shared_ptr<JobRecord> job;
  FrameRecord* f = nullptr;
  BufferHeader base;  // the frame's, taken under mu_: a requeue may change it
  uint32_t run = 0;
  {
    std::lock_guard lock(mu_);
    job = find_or_throw(r.task.job_id);
    f = job->by_number.at(r.task.frame);
    base = f->base;
    run = f->run;
  }
  EncodedBuffer buffer;
  try {
    buffer = checked_buffer(*job, base, r);
  } catch (const CoordinatorError& e) {
    {
      std::lock_guard lock(mu_);  // its frame was requeued since check_upload: not needed
      if (ledger_->scheduler().retired(r.lease_id)) return false;
    }
    refuse_upload(r.worker_id, r.lease_id, r.task, e.what(), r.log);
    throw;
  }
  std::unique_lock frame_lock(f->m);  // one merge and checkpoint at a time per frame
  {
    std::lock_guard lock(mu_);
    if (job->deleted) refuse(ErrorCode::NotFound, "no job '" + clip(job->id) + "'");
    // Requeued while this result was checked: it is of the frame's old run, whose lease ended.
    if (f->run != run) return false;
    // A worker registered by an earlier build has no kind on record: its result says it.
    if (auto w = workers_.find(r.worker_id); w != workers_.end() && w->second.isa.empty())
      w->second.isa = w->second.info.isa = buffer.header().isa;
    // The pin is checked, and taken by a job not yet pinned, here: under mu_ and before the
    // result is stored, so results of two kinds racing on two frames are never both kept.
    // Another build's or kind's result (the job was pinned while the task was out) is not the
    // worker's fault: its task goes back to the queue for a worker of the pin, uncounted.
    if (std::string why = pin_problem(*job, buffer.header()); !why.empty()) {
      Ledger::Ticket ticket = 0;
      ledger_->fail(r.lease_id, r.worker_id, why, /*handed_back=*/true, now(), &ticket, r.log);
      spdlog::info("result of task {} from worker {} not merged: {}", task_id_text(r.task),
                   r.worker_id, why);
      refuse(ErrorCode::FailedPrecondition, why);
    }
    if (job->build_id.empty() || job->cpu_kind.empty()) {
      if (job->build_id.empty()) job->build_id = buffer.header().build_id;
      if (job->cpu_kind.empty()) job->cpu_kind = buffer.header().isa;
      job->pin_pending = true;  // stored with the first merged result (Ledger::complete)
    }
  }
  if (!f->acc) {
    {
      std::lock_guard lock(mu_);
      // Merged and checkpointed already, or its job ended meanwhile.
      if (f->progress.done || ledger_->scheduler().settled(r.task)) return false;
    }
    f->acc = make_accumulator(*job, *f);
  }
  if (!f->acc->task_needed(buffer.rect(), r.task.pass)) {  // merged already, or beyond the stop
    std::lock_guard lock(mu_);
    ledger_->not_needed(r.lease_id, r.task, r.worker_id, now(), r.log);
    return false;
  }
  if (verified(r.task)) {
    std::lock_guard lock(mu_);
    if (!verify(*job, r, buffer)) return true;  // taken, and held until another result agrees
  }
  const std::pair<uint32_t, uint32_t> key{r.task.pass, r.task.tile};
  if (f->storing.count(key)) {  // another result of the task is being stored: it will be merged
    std::lock_guard lock(mu_);
    ledger_->not_needed(r.lease_id, r.task, r.worker_id, now(), r.log);
    return false;
  }
  // Durable first: the task's result (its record in the frame's checkpoint log, the record of
  // which tasks an image holds), then the ledger's transition and its rows, then the answer once
  // they are stored. The record is appended unflushed under the frame's lock, and flushed with
  // the other results that arrive meanwhile (group commit: results_sync_) with no lock held.
  auto writer = std::make_unique<GroupSync::Writer>(*results_sync_);  // a flush waits for it
  try {
    f->checkpoint->save_task(r.task.pass, r.task.tile, buffer.bytes());
  } catch (const std::exception& e) {
    // The coordinator's fault (disk full, unwritable state): never the worker's. It retries.
    std::lock_guard lock(mu_);
    storage_failed(e.what());
    refuse(ErrorCode::Unavailable,
           std::string("the coordinator cannot store results now (") + e.what() + "); retry later");
  }
  f->storing.insert(key);
  staged = std::make_unique<StagedResult>(
      StagedResult{std::move(r), job, f, run, std::move(buffer), key, std::move(writer)});
  return std::nullopt;
}

bool Coordinator::commit_result(StagedResult& s, const std::string& flush_error, uint64_t& ticket) {
  JobRecord* job = s.job.get();
  FrameRecord* f = s.f;
  const TaskResult& r = s.r;
  std::unique_lock frame_lock(f->m);
  f->storing.erase(s.key);
  if (!flush_error.empty()) {
    // Its record stays in the log, recorded nowhere else: after a restart it counts as a merged
    // result (as a result stored just before a crash does); here its task is leased again.
    std::lock_guard lock(mu_);
    storage_failed(flush_error);
    refuse(ErrorCode::Unavailable,
           "the coordinator cannot store results now (" + flush_error + "); retry later");
  }
  {
    std::lock_guard lock(mu_);
    // Deleted, or requeued (its old run's folder goes), while the file was flushed.
    if (job->deleted) refuse(ErrorCode::NotFound, "no job '" + clip(job->id) + "'");
    if (f->run != s.run) return false;
    if (journal_->problem().empty()) storage_ok();
    if (!record_result(*job, r, s.buffer.header())) return false;
    ++counters_.tasks_completed;
    counters_.samples_merged += s.buffer.view().total_samples();
    counters_.bytes_merged += s.buffer.bytes().size();
    counters_.core_seconds += s.buffer.header().core_seconds;
    ++job->tasks_timed;
    job->timed_core_seconds += s.buffer.header().core_seconds;
  }
  // The merge and the prefix checkpoint hold this frame's lock only: leases, renewals and other
  // frames' merges go on meanwhile.
  // (No accumulator: the frame ended while the file was flushed, its image in its checkpoint.)
  bool merged = f->acc && f->acc->add(std::move(s.buffer)) == FrameAccumulator::AddResult::Merged;
  if (merged) {
    try {  // the task files stay until a prefix holding them is durable
      f->checkpoint->save_prefix(*f->acc);
    } catch (const std::exception& e) {
      std::lock_guard lock(mu_);
      storage_failed(e.what());
    }
  }
  std::lock_guard lock(mu_);
  publish_frame(*job, *f);
  if (f->progress.done) f->acc.reset();  // its image lives in the checkpoint now
  ticket = journal_->append({});         // the last write queued: this result's and the rest
  return true;
}

bool Coordinator::verified(const TaskRef& task) const {
  double f = options_.verify_fraction;
  if (f <= 0) return false;
  if (f >= 1) return true;
  // A fixed choice per task, so a restart verifies the same tasks.
  uint64_t h = std::stoull(sha256_hex(task_id_text(task)).substr(0, 15), nullptr, 16);
  return double(h) / double(uint64_t(1) << 60) < f;
}

bool Coordinator::verify(JobRecord& job, const TaskResult& r, const EncodedBuffer& buffer) {
  std::vector<std::pair<std::string, EncodedBuffer>>& held = verifying_[r.task];
  for (const auto& [worker, other] : held) {
    if (worker == r.worker_id || !same_samples(other.view(), buffer.view())) continue;
    for (const auto& [liar, theirs] : held) {
      if (same_samples(theirs.view(), buffer.view())) continue;
      std::string why = "its result of task " + task_id_text(r.task) +
                        " differed from those of workers " + worker + " and " + r.worker_id;
      outvoted_[liar] = why;
      journal_->append({store::RefuseWorker{liar, why}});
      spdlog::error("worker {} (registered by {}) outvoted: {}; it is refused from now on", liar,
                    workers_.at(liar).principal, why);
    }
    verifying_.erase(r.task);
    return true;
  }
  held.emplace_back(r.worker_id, buffer);
  if (held.size() >= 3) {  // three workers, no two agreeing: not a liar, the engine is not
    std::string why = "task " + task_id_text(r.task) + ": the results of " +
                      std::to_string(held.size()) +
                      " workers all differ, against the determinism contract";
    verifying_.erase(r.task);
    set_state(job, JobState::Failed, why);
    return false;
  }
  spdlog::info("task {}: result of {} held until another worker's agrees", task_id_text(r.task),
               r.worker_id);
  ledger_->hold_for_verification(r.lease_id, now(), r.log);
  return false;
}

void Coordinator::fail(const TaskFailureReport& report, const Caller& caller) {
  Ledger::Ticket ticket = 0;
  {
    std::lock_guard lock(mu_);
    check_worker(report.worker_id, caller);
    check_lease(report.worker_id, report.lease_id, nullptr);
    std::optional<TaskRef> task = ledger_->scheduler().lease_task(report.lease_id);
    std::string message = printable(report.message.substr(0, 4096));  // part of the job's error
    switch (ledger_->fail(report.lease_id, report.worker_id, message, report.handed_back, now(),
                          &ticket, bounded_log(report.log))) {
      case LeaseOutcome::NotFound:
        refuse(ErrorCode::NotFound, "no lease '" + clip(report.lease_id) + "'");
      case LeaseOutcome::Ended:
        refuse(ErrorCode::FailedPrecondition, "lease " + report.lease_id + " has ended");
      case LeaseOutcome::Ok:
        break;
    }
    ++(report.handed_back ? counters_.tasks_handed_back : counters_.tasks_failed);
    if (task && !report.handed_back)
      spdlog::warn("task {} failed on {}: {}", task_id_text(*task), report.worker_id,
                   clip(message));
    if (task && ledger_->scheduler().job_failed(task->job_id)) {
      std::shared_ptr<JobRecord> job = find(task->job_id);
      if (job && !terminal(job->state))
        ticket = set_state(*job, JobState::Failed, ledger_->scheduler().job_error(job->id));
    }
  }
  wait_stored(ticket, "the failure");
}

}  // namespace rf
