// Recovery (core.h): each job's folder record, restoring jobs from the store and their frames
// from checkpoints, jobs the store lost, and what an interrupted process left behind.
#include "coordinator/core_internal.h"
#include "coordinator/journal.h"
#include "coordinator/ledger.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <nlohmann/json.hpp>

#include "coordinator/spec_codec.h"
#include "engine/digest.h"

namespace rf {

namespace fs = std::filesystem;
using core_detail::clip;
using core_detail::refuse;
using core_detail::unix_now;

void Coordinator::write_folder_record(const StoredJob& j) const {
  std::string dir = options_.state_dir + "/jobs/" + j.id;
  write_file_atomic(dir + "/job.spec", j.spec ? encode_spec(*j.spec) : std::string());
  nlohmann::json meta = {
      {"id", j.id}, {"seq", j.seq}, {"tenant", j.tenant}, {"submitted_unix", j.submitted_unix}};
  write_file_atomic(dir + "/job.json", meta.dump() + "\n");
}

void Coordinator::write_folder_state(const JobRecord& job) const {
  std::vector<FrameNumber> held;
  for (const auto& f : job.frames)
    if (f->held) held.push_back(f->number);
  nlohmann::json st = {{"state", int(job.state)},
                       {"error", job.error},
                       {"paused", job.paused},
                       {"priority", job.priority},
                       {"held", held}};
  try {
    write_file_atomic(options_.state_dir + "/jobs/" + job.id + "/state.json", st.dump() + "\n");
  } catch (const std::exception& e) {  // the database holds it; the folder's copy is a backup
    spdlog::warn("job {}: {}", job.id, e.what());
  }
}

namespace {

// Temporary files of atomic writes (write_file_atomic: NAME.tmp.PID.N) that a process killed
// mid-write left behind: never renamed into place, so nothing reads them.
void remove_stale_temporaries(const std::string& dir) {
  std::error_code ec;
  std::vector<fs::path> stale;
  for (auto it = fs::recursive_directory_iterator(dir, ec); !ec && it != fs::end(it);
       it.increment(ec)) {
    const std::string name = it->path().filename().string();
    size_t at = name.rfind(".tmp.");
    if (at != std::string::npos && it->is_regular_file(ec) &&
        name.find_first_not_of("0123456789.", at + 5) == std::string::npos)
      stale.push_back(it->path());
  }
  for (const fs::path& p : stale) fs::remove(p, ec);
  if (!stale.empty())
    spdlog::info("removed {} temporary files of writes a stopped process left in {}", stale.size(),
                 dir);
}

}  // namespace

void Coordinator::finish_deletes() {
  std::error_code ec;
  for (const auto& entry : fs::directory_iterator(options_.state_dir + "/jobs", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(".deleted-", 0) != 0) continue;
    const std::string id = name.substr(9);
    int64_t expired_unix = 0;  // an expiry's time (retention.cpp), or a client's delete
    try {
      if (fs::exists(entry.path() / "expired"))
        expired_unix = std::stoll(read_file_bytes((entry.path() / "expired").string()));
    } catch (const std::exception&) {
      expired_unix = int64_t(unix_now());
    }
    journal_->write_ahead({store::DeleteJob{id, expired_unix}});
    std::error_code rm;
    fs::remove_all(entry.path(), rm);
    spdlog::info("job {}: finished its deletion, which a stop interrupted{}", id,
                 rm ? " (" + entry.path().string() + " not removed: " + rm.message() + ")" : "");
  }
}

void Coordinator::recover_folders() {
  remove_stale_temporaries(options_.state_dir + "/jobs");
  remove_stale_temporaries(options_.state_dir + "/blobs");
  std::error_code ec;
  std::vector<std::string> lost;
  for (const auto& entry : fs::directory_iterator(options_.state_dir + "/jobs", ec)) {
    std::string id = entry.path().filename().string();
    if (id.rfind(".submit-", 0) == 0) {  // a submit being checked when the process ended
      fs::remove_all(entry.path(), ec);
      continue;
    }
    unsigned long long n = 0;
    char extra = 0;
    if (!entry.is_directory() || std::sscanf(id.c_str(), "j%llu%c", &n, &extra) != 1) continue;
    next_seq_ = std::max<uint64_t>(next_seq_, n + 1);  // never reuse an id
    if (jobs_.count(id)) {
      if (!fs::exists(entry.path() / "job.spec")) {  // a folder from before folder records
        const JobRecord& job = *jobs_.at(id);
        try {
          write_folder_record(
              {id, job.seq, job.spec, 0, "", job.submitted_unix, 0, job.tenant, ""});
        } catch (const std::exception& e) {
          spdlog::warn("job {}: {}", id, e.what());
        }
      }
      const JobRecord& job = *jobs_.at(id);
      if (terminal(job.state) && !fs::exists(entry.path() / "state.json")) write_folder_state(job);
      continue;
    }
    if (!fs::exists(entry.path() / "job.spec") || !fs::exists(entry.path() / "job.json")) {
      spdlog::info("removing {}: a submit that never finished", entry.path().string());
      fs::remove_all(entry.path(), ec);
      continue;
    }
    StoredJob stored;
    try {
      stored.id = id;
      stored.spec = decode_spec(read_file_bytes((entry.path() / "job.spec").string()));
      nlohmann::json meta =
          nlohmann::json::parse(read_file_bytes((entry.path() / "job.json").string()));
      stored.seq = meta.at("seq").get<uint64_t>();
      stored.tenant = meta.at("tenant").get<std::string>();
      stored.submitted_unix = meta.at("submitted_unix").get<int64_t>();
      stored.state = int(JobState::Queued);
      if (fs::exists(entry.path() / "state.json")) {
        nlohmann::json st =
            nlohmann::json::parse(read_file_bytes((entry.path() / "state.json").string()));
        stored.state = st.at("state").get<int>();
        stored.error = st.at("error").get<std::string>();
        stored.paused = st.value("paused", false);  // absent in records of earlier builds
        if (st.contains("priority")) stored.priority = st.at("priority").get<int>();
        if (st.contains("held")) stored.held = st.at("held").get<std::vector<FrameNumber>>();
      }
      if (fs::exists(entry.path() / "versions.json")) {
        stored.versions = read_file_bytes((entry.path() / "versions.json").string());
        while (!stored.versions.empty() && stored.versions.back() == '\n')
          stored.versions.pop_back();
        decode_versions(stored.versions);  // throws for a damaged record
      }
    } catch (const std::exception& e) {
      spdlog::error(
          "job {}: not in the job database, and its folder record is unreadable ({}); "
          "left in {} for the operator",
          id, e.what(), entry.path().string());
      continue;
    }
    spdlog::warn(
        "job {}: missing from the job database (lost: truncated, or its WAL removed); "
        "recovered from its folder with the passes its checkpoints hold",
        id);
    // The row as a submit makes it, then what the folder records beside it.
    std::vector<StoreWrite> rows{store::InsertJob{stored},
                                 store::SetPaused{stored.id, stored.paused},
                                 store::Retry{stored.id, stored.held, false},
                                 store::SetVersions{stored.id, stored.versions}};
    if (stored.priority) rows.push_back(store::SetPriority{stored.id, *stored.priority});
    journal_->write_ahead(std::move(rows));
    restore(stored);
    lost.push_back(id);
  }
  if (!lost.empty()) {
    std::string ids;
    for (const std::string& id : lost) ids += " " + id;
    spdlog::warn("recovered {} jobs from their folders:{}", lost.size(), ids);
  }
}

std::unique_ptr<FrameAccumulator> Coordinator::make_accumulator(const JobRecord& job,
                                                                const FrameRecord& f) const {
  ProgressiveOptions options = job.merge_options();
  options.memory_budget = options_.frame_memory;
  options.spill_dir = f.checkpoint->dir();
  auto acc = std::make_unique<FrameAccumulator>(f.base, job.tiles, job.splats, options);
  if (acc->tiled())
    spdlog::info(
        "job {} frame {}: {}x{} kept in tiles on disk ({:.1f} MiB of planes; "
        "--frame-memory {:.1f} MiB)",
        job.id, f.number, f.base.width, f.base.height,
        double(uint64_t(f.base.width) * uint64_t(f.base.height) *
               FrameAccumulator::bytes_per_pixel(f.base.aovs)) /
            double(1 << 20),
        double(options_.frame_memory) / double(1 << 20));
  return acc;
}

// Rebuilds a frame's accumulator from its checkpoint.
Coordinator::LoadedFrame Coordinator::load_frame(const JobRecord& job, FrameRecord& f) const {
  LoadedFrame out;
  // The prefix first, then each logged result as it is read: never a pass of results at once.
  FrameCheckpoint::Loaded loaded = f.checkpoint->load_prefix();
  if (loaded.prefix) {
    out.acc = make_accumulator(job, f);
    try {
      out.acc->resume_from(*loaded.prefix);
    } catch (const std::exception& e) {
      spdlog::warn("job {} frame {}: checkpoint not used: {}", job.id, f.number, e.what());
      out.acc = make_accumulator(job, f);
    }
    loaded.prefix.reset();  // closed before it is rewritten
  }
  auto add = [&](FrameCheckpoint::TaskResult&& t) {
    if (t.tile >= job.tiles.size()) return;
    if (!out.acc) out.acc = make_accumulator(job, f);
    try {
      if (out.acc->add(std::move(t.buffer)) != FrameAccumulator::AddResult::Dropped)
        out.done.push_back(TaskRef{job.id, f.number, t.pass, t.tile});
    } catch (const std::exception& e) {
      spdlog::warn("job {} frame {} task {}/{}: not used: {}", job.id, f.number, t.pass, t.tile,
                   e.what());
    }
  };
  std::set<std::pair<uint32_t, uint32_t>> have;
  for (const FrameCheckpoint::TaskResult& t : loaded.tasks) have.insert({t.pass, t.tile});
  for (FrameCheckpoint::TaskResult& t : loaded.tasks) add(std::move(t));
  loaded.tasks.clear();
  f.checkpoint->load_log(out.acc ? out.acc->passes_merged() : 0, std::move(have), add,
                         loaded.problems);
  for (const std::string& p : loaded.problems)
    spdlog::warn("job {} frame {}: {} (its tasks will be rendered again)", job.id, f.number, p);
  if (!out.acc) return out;
  if (out.acc->passes_merged() > 0) f.checkpoint->save_prefix(*out.acc);
  return out;
}

void Coordinator::adopt_frame(JobRecord& job, FrameRecord& f, LoadedFrame loaded) {
  if (!loaded.acc) return;
  f.acc = std::move(loaded.acc);
  for (const TaskRef& t : loaded.done) ledger_->restore_done(t);
  ledger_->restore_passes(job.id, f.number, f.acc->passes_merged());
  publish_frame(job, f);
}

void Coordinator::restore(const StoredJob& stored) {
  const std::optional<JobSpec>& spec = stored.spec;
  if (!spec) return restore_failed(stored, "its stored spec does not parse");
  if (!spec->request_id.empty()) requests_[{stored.tenant, spec->request_id}] = stored.id;
  std::shared_ptr<JobRecord> job;
  try {
    job = build_job(stored.id, stored.seq, *spec, Caller{}, true);
    // Requeued frames: their scene versions and runs, as the store has them (the commit point);
    // the folder's copy is made to agree, and folders of replaced runs go.
    if (!stored.versions.empty()) apply_versions(*job, decode_versions(stored.versions));
    try {
      write_folder_versions(*job);
    } catch (const std::exception& e) {
      spdlog::warn("job {}: {}", job->id, e.what());
    }
    remove_stale_folders(*job);
    job->state = JobState(stored.state);
    job->error = stored.error;
    job->ended_unix = stored.ended_unix;
    if (terminal(job->state)) job->endings = 1;  // its frames' accumulators go at the next pass
    if (terminal(job->state) && job->ended_unix == 0) {
      // Ended under a build before retention: its keep time counts from this start.
      job->ended_unix = int64_t(unix_now());
      journal_->append({store::SetState{job->id, stored.state, stored.error, job->ended_unix}});
    }
    job->submitted_unix = stored.submitted_unix;
    job->core_seconds = stored.core_seconds;
    job->tenant = stored.tenant;
    if (job->build_id.empty()) job->build_id = stored.build_id;
    job->cpu_kind = stored.cpu_kind;
    job->paused = stored.paused;
    job->priority = stored.priority.value_or(spec->priority);
    for (FrameNumber n : stored.held)
      if (auto it = job->by_number.find(n); it != job->by_number.end()) it->second->held = true;
    if (!job->bundle_problem.empty() && !terminal(job->state))
      set_state(*job, JobState::Failed,
                "the coordinator could not restore its scene bundle: " + job->bundle_problem +
                    "; the passes merged before are kept (fetch)");
    Ledger::Trail trail;
    if (!terminal(job->state)) {
      trail.leases = store_->leases(job->id);
      trail.refused_workers = store_->refused_workers(job->id);
      trail.failures = store_->failures(job->id);
    }
    ledger_->restore_job(*job, trail);
    if (!terminal(job->state) && ledger_->scheduler().job_failed(job->id))
      set_state(*job, JobState::Failed, ledger_->scheduler().job_error(job->id));
    for (auto& f : job->frames) resume_frame(*job, *f);
    // A job stored by a build before the CPU kind pin, whose checkpoints hold merged passes: their
    // kind is its pin (a frame merges results of one kind only), when they agree on one.
    if (!terminal(job->state) && job->cpu_kind.empty()) {
      std::string kind;
      bool one = true;
      for (auto& f : job->frames) {
        if (!f->acc || f->acc->passes_merged() == 0) continue;
        const std::string& k = f->acc->info().header.isa;
        if (k.empty() || k.rfind("mixed:", 0) == 0 || (!kind.empty() && k != kind)) one = false;
        kind = k;
      }
      if (one && !kind.empty()) {
        job->cpu_kind = kind;
        journal_->append({store::SetBuild{job->id, job->build_id, kind}});
        spdlog::info("job {}: pinned to the CPU kind its merged passes were rendered on ({})",
                     job->id, kind);
      }
    }
  } catch (const std::exception& e) {  // bad_alloc included: one job never stops the others
    if (job) ledger_->drop_job(job->id);
    return restore_failed(stored, e.what());
  }
  jobs_[job->id] = job;
  reference_blobs(*job, 0, +1);
  spdlog::info("restored job {} ({}), {} tasks done in the database", job->id,
               job_state_name(job->state), store_->tasks_done(job->id));
}

void Coordinator::restore_failed(const StoredJob& stored, const std::string& why) {
  auto job = std::make_shared<JobRecord>();
  job->id = stored.id;
  job->seq = stored.seq;
  if (stored.spec) job->spec = *stored.spec;
  job->submitted_unix = stored.submitted_unix;
  job->core_seconds = stored.core_seconds;
  job->tenant = stored.tenant;
  job->state = JobState(stored.state);
  job->error = stored.error;
  jobs_[job->id] = job;
  reference_blobs(*job, 0, +1);
  spdlog::error("job {}: cannot be restored: {}", stored.id, why);
  if (!terminal(job->state))
    set_state(*job, JobState::Failed, "the coordinator could not restore it: " + why);
}

}  // namespace rf
