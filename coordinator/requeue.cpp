// Requeue (core.h): a job's frames rendered again from scratch, with a new scene version or with
// their own; and restoring what requeues left (each frame's scene version and run).
#include "coordinator/core_internal.h"
#include "coordinator/journal.h"
#include "coordinator/ledger.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <set>

#include "engine/digest.h"
#include "farm/frame_range.h"

namespace rf {

namespace fs = std::filesystem;
using core_detail::clip;
using core_detail::refuse;

void Coordinator::write_folder_versions(const JobRecord& job) const {
  const std::string path = options_.state_dir + "/jobs/" + job.id + "/versions.json";
  if (job.versions.empty()) {  // none (or a copy ahead of the store's record): no file
    std::error_code ec;
    fs::remove(path, ec);
    return;
  }
  write_file_atomic(path, encode_versions(job.versions) + "\n");
}

void Coordinator::apply_versions(JobRecord& job, JobVersions versions) {
  const std::string dir = options_.state_dir + "/jobs/" + job.id + "/";
  job.versions = std::move(versions);
  std::map<uint32_t, std::map<FrameNumber, FrameScene>> scenes;
  for (const auto& [number, r] : job.versions.frames) {
    auto it = job.by_number.find(number);
    if (it == job.by_number.end())
      throw std::runtime_error("its scene versions name frame " + std::to_string(number) +
                               ", which it does not have");
    FrameRecord& f = *it->second;
    if (r.version > 0) {
      auto v = scenes.find(r.version);
      if (v == scenes.end())
        v = scenes
                .emplace(r.version,
                         version_scenes(job, r.version, job.versions.added[r.version - 1], Caller{},
                                        true))
                .first;
      auto s = v->second.find(number);
      if (s == v->second.end())
        throw std::runtime_error("frame " + std::to_string(number) + " is not in scene version " +
                                 std::to_string(r.version));
      f.scene_path = s->second.scene_path;
      f.base = s->second.base;
    }
    f.version = r.version;
    f.run = r.run;
    f.checkpoint = std::make_unique<FrameCheckpoint>(dir + frame_folder(number, r.run));
  }
}

void Coordinator::remove_stale_folders(const JobRecord& job) const {
  const fs::path dir = options_.state_dir + "/jobs/" + job.id;
  std::set<std::string> keep;
  for (const auto& f : job.frames) keep.insert(frame_folder(f->number, f->run));
  for (uint32_t v = 0; v <= job.versions.added.size(); ++v) {
    keep.insert(bundle_folder(v));
    keep.insert(v == 0 ? "scenes.json" : "scenes-v" + std::to_string(v) + ".json");
  }
  std::error_code ec;
  std::vector<fs::path> stale;
  for (const auto& e : fs::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    bool ours = name.rfind("frame-", 0) == 0 || name.rfind("bundle-v", 0) == 0 ||
                name.rfind("scenes-v", 0) == 0;
    if (ours && !keep.count(name)) stale.push_back(e.path());
  }
  for (const fs::path& p : stale) fs::remove_all(p, ec);
  if (!stale.empty())
    spdlog::info("job {}: removed {} folders of runs or scene versions requeues replaced", job.id,
                 stale.size());
}

void Coordinator::requeue(const std::string& id, const std::string& frames,
                          const std::optional<SceneVersion>& scene, const std::string& request_id,
                          const Caller& caller) {
  // One requeue at a time: scene versions are numbered in the order they are stored.
  std::lock_guard serial(requeue_mu_);
  std::shared_ptr<JobRecord> job;
  std::set<FrameNumber> named;
  uint32_t version = 0;
  {
    std::lock_guard lock(mu_);
    job = find_for(id, caller);
    if (!request_id.empty() && job->versions.request_id == request_id) return;  // a repeat
    if (frames.empty())
      refuse(ErrorCode::InvalidArgument,
             "frames: name the frames to render again (a range such as 3 or 1-10)");
    named = core_detail::named_frames(*job, frames);
    if (job->frames.empty() || !job->bundle_problem.empty())
      refuse(ErrorCode::FailedPrecondition,
             "job " + id + " cannot run again: " +
                 (job->bundle_problem.empty() ? job->error : job->bundle_problem));
    if (scene) version = uint32_t(job->versions.added.size()) + 1;
  }
  const std::vector<FrameNumber> numbers(named.begin(), named.end());
  // The new scene is checked as a submit's is, off the lock (a child process parses it). What it
  // reads of the job (spec, tiles, passes) never changes after submit.
  std::optional<SceneVersion> added;
  std::map<FrameNumber, FrameScene> scenes;
  if (scene) {
    added = *scene;
    added->frames = frame_range_text(numbers);
    scenes = version_scenes(*job, version, *added, caller, false);
  }
  // The frames' locks (in the job's frame order, as retry takes them): no merge of an old run is
  // under way while the frames change.
  std::vector<std::unique_lock<std::mutex>> frame_locks;
  for (const auto& f : job->frames)
    if (named.count(f->number)) frame_locks.emplace_back(f->m);
  const std::string dir = options_.state_dir + "/jobs/" + id + "/";
  std::vector<std::string> replaced;
  Ledger::Ticket ticket = 0;
  {
    std::lock_guard lock(mu_);
    if (job->deleted) refuse(ErrorCode::NotFound, "no job '" + clip(id) + "'");
    const bool ended = terminal(job->state);
    JobVersions next = job->versions;
    if (added) next.added.push_back(*added);
    for (FrameNumber n : numbers) {
      const FrameRecord& f = *job->by_number.at(n);
      next.frames[n] = FrameRun{added ? version : f.version, f.run + 1};
    }
    next.request_id = request_id;
    // An ended job's unfinished frames that it does not name wait, as a retry's do; a running
    // job's held frames stay held.
    std::vector<FrameNumber> held;
    bool merged_elsewhere = false;
    for (const auto& f : job->frames) {
      if (named.count(f->number)) continue;
      if (ended ? !f->progress.done : f->held) held.push_back(f->number);
      merged_elsewhere |= f->progress.passes_merged > 0 || f->acc != nullptr;
    }
    std::sort(held.begin(), held.end());
    // The pin goes with the last merged result: a job requeued whole renders on today's farm.
    const bool release_pin = job->spec.build_id.empty() && !merged_elsewhere && !job->pin_pending &&
                             (!job->build_id.empty() || !job->cpu_kind.empty());
    // The new runs' checkpoint folders and the folder's record, before anything changes: a full
    // or unwritable disk refuses the requeue whole.
    std::map<FrameNumber, std::unique_ptr<FrameCheckpoint>> fresh;
    std::swap(job->versions, next);
    try {
      for (FrameNumber n : numbers)
        fresh[n] = std::make_unique<FrameCheckpoint>(
            dir + frame_folder(n, job->versions.frames.at(n).run));
      write_folder_versions(*job);  // before the store's row: the folder is never behind it
    } catch (const std::exception& e) {
      std::swap(job->versions, next);
      // A filesystem error's message would name the state directory: its cause only.
      const auto* fe = dynamic_cast<const fs::filesystem_error*>(&e);
      refuse(ErrorCode::Unavailable, std::string("cannot store the requeue now: ") +
                                         (fe ? fe->code().message() : e.what()));
    }
    ticket = ledger_->requeue(*job, numbers, held, encode_versions(job->versions), release_pin);
    if (added) reference_blobs(*job, version, +1);
    for (FrameNumber n : numbers) {
      FrameRecord& f = *job->by_number.at(n);
      replaced.push_back(dir + frame_folder(n, f.run));
      const FrameRun& r = job->versions.frames.at(n);
      if (added) {
        f.scene_path = scenes.at(n).scene_path;
        f.base = scenes.at(n).base;
      }
      f.version = r.version;
      f.run = r.run;
      f.checkpoint = std::move(fresh.at(n));
      f.acc.reset();
      f.progress = FrameProgress{};
      f.history.clear();
      f.history_stride = 1;
      f.progress.passes_total = job->passes;
      f.first_lease_at = -1;
      f.leases_dropped = false;
      for (auto it = verifying_.begin(); it != verifying_.end();)  // held results of the old run
        it = it->first.job_id == id && it->first.frame == n ? verifying_.erase(it) : std::next(it);
    }
    for (const auto& f : job->frames)
      f->held = std::binary_search(held.begin(), held.end(), f->number);
    write_folder_state(*job);
    spdlog::info("job {} requeued by {}: frames {} render again{}{}", id, caller.principal,
                 frame_range_text(numbers),
                 added ? " from scene version " + std::to_string(version) + " (" +
                             clip(added->scene_path) + ")"
                       : "",
                 held.empty() ? "" : ", frames " + frame_range_text(held) + " held");
    ++version_;
    changed_.notify_all();
  }
  frame_locks.clear();
  wait_stored(ticket, "the requeue");
  for (const std::string& old : replaced) {  // the store no longer names them
    std::error_code ec;
    fs::remove_all(old, ec);
  }
}

}  // namespace rf
