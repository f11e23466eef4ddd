#include "coordinator/core.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>

#include "coordinator/checkpoint.h"
#include "engine/buffer_file.h"
#include "engine/build_info.h"
#include "engine/digest.h"
#include "engine/frame_accumulator.h"
#include "engine/render.h"
#include "engine/work_units.h"
#include "farm/convert.h"
#include "farm/frame_range.h"

namespace rf {

namespace fs = std::filesystem;

namespace {

constexpr int kDefaultTileSize = 128;  // big enough that per-task costs stay small

// A client-supplied string as it may appear in a message or a log line: at most 64 bytes.
std::string clip(const std::string& s) {
  if (s.size() <= 64) return printable(s);
  return printable(s.substr(0, 48)) + "...(" + std::to_string(s.size()) + " bytes)";
}

[[noreturn]] void refuse(ErrorCode code, const std::string& message) {
  throw CoordinatorError(code, message);
}

double unix_now() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

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

// How the engine splits and checks one frame of a job: the engine calls the coordinator makes,
// in one place.
struct FramePlan {
  BufferHeader base;  // what every task buffer of the frame must match
  std::vector<Rect> tiles;
  bool splats = false;
  uint32_t passes = 0;
  double noise_target = 0;
  uint64_t spp_per_pass = 0;
};

FramePlan plan_frame(const SceneSummary& scene, uint32_t frame, int tile_size) {
  return {frame_header(scene, frame, PassSet{}),
          work_units(scene, tile_size),
          scene.splats,
          scene.passes,
          scene.noise_target,
          scene.spp_per_pass};
}

// Every file of the spec's bundle has a safe path, listed once and not also a folder of another
// file, and a digest whose content was uploaded.
void check_bundle(const JobSpec& spec, const std::function<bool(const std::string&)>& uploaded,
                  bool restoring) {
  std::set<std::string> files, folders;
  for (const BundleEntry& f : spec.files) {
    try {
      check_bundle_path(f.path);
    } catch (const BlobError& e) {
      refuse(ErrorCode::InvalidArgument, std::string("files: ") + e.what());
    }
    std::string path = fs::path(f.path).lexically_normal().generic_string();
    if (!files.insert(path).second)
      refuse(ErrorCode::InvalidArgument, "files: '" + clip(f.path) + "' is listed twice");
    for (size_t slash = path.find('/'); slash != std::string::npos;
         slash = path.find('/', slash + 1))
      folders.insert(path.substr(0, slash));
  }
  for (const std::string& p : files)
    if (folders.count(p))
      refuse(ErrorCode::InvalidArgument,
             "files: '" + clip(p) + "' is both a file and the folder of another file");
  for (const BundleEntry& f : spec.files) {
    if (!is_sha256_hex(f.sha256))
      refuse(ErrorCode::InvalidArgument,
             "files: '" + f.path + "' has no valid SHA-256 (64 lower-case hex digits)");
    if (!uploaded(f.sha256))
      refuse(ErrorCode::InvalidArgument,
             restoring ? "files: the content of '" + clip(f.path) + "' (" + f.sha256 +
                             ") is missing from the coordinator's blob store (STATE/blobs: "
                             "deleted or damaged while the job was stored)"
                       : "files: the content of '" + clip(f.path) + "' (" + f.sha256 +
                             ") was not uploaded");
  }
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

// One frame of a job: its merge state, durable checkpoint and progress figures.
struct FrameRecord {
  uint32_t number = 0;
  std::string scene_path;                 // in the bundle
  BufferHeader base;                      // what every task buffer of this frame must match
  std::mutex m;                           // serializes merges and checkpoints of this frame
  std::unique_ptr<FrameAccumulator> acc;  // created on the first result; dropped when done
  std::unique_ptr<FrameCheckpoint> checkpoint;
  // Under the coordinator's mutex: the figures of the last merge (the ETA is taken when
  // reported), and when the frame's first task was leased in this run.
  FrameProgress progress;
  double first_lease_at = -1;
  bool leases_dropped = false;  // its lease rows were deleted when it was done
};

struct JobRecord {
  std::string id;
  uint64_t seq = 0;
  JobSpec spec;
  JobState state = JobState::Queued;
  std::string error;
  int64_t submitted_unix = 0;
  double core_seconds = 0;
  std::string tenant;
  std::string build_id;  // results of this build only; empty: the first merged result's
  std::string bundle_problem;  // restored without its bundle (its blobs are gone): why
  std::vector<Rect> tiles;
  bool splats = false;
  uint32_t passes = 0;
  uint64_t spp_per_pass = 0;
  double noise_target = 0;
  std::vector<std::unique_ptr<FrameRecord>> frames;
  std::map<uint32_t, FrameRecord*> by_number;

  ProgressiveOptions merge_options() const { return {0, passes, noise_target}; }
  std::vector<uint32_t> frame_numbers() const {
    std::vector<uint32_t> out;
    for (const auto& f : frames) out.push_back(f->number);
    return out;
  }
};

bool JobLimits::set(const std::string& name, uint64_t value) {
  std::map<std::string, uint64_t*> fields = {{"pixels_per_frame", &pixels_per_frame},
                                             {"tiles_per_frame", &tiles_per_frame},
                                             {"tasks_per_job", &tasks_per_job},
                                             {"frames_per_job", &frames_per_job},
                                             {"spp", &spp},
                                             {"name_bytes", &name_bytes},
                                             {"path_bytes", &path_bytes},
                                             {"bundle_files", &bundle_files},
                                             {"parse_memory_mb", &scene_check.memory_mb},
                                             {"parse_cpu_seconds", &scene_check.cpu_seconds},
                                             {"parse_wall_seconds", &scene_check.wall_seconds},
                                             {"parse_children", &scene_check.children}};
  auto it = fields.find(name);
  if (it != fields.end()) {
    if (name.rfind("parse_", 0) == 0 && value == 0)
      throw std::invalid_argument(name + " must be at least 1");
    if (name == "parse_memory_mb" && (value < 1024 || value > (uint64_t(1) << 40)))
      throw std::invalid_argument(name +
                                  " must be between 1024 and 2^40 MiB (the binary maps about 440 "
                                  "MiB before it reads a scene)");
    *it->second = value;
    return true;
  }
  if (name.rfind("import_", 0) == 0 && scene_check.import.set(name.substr(7), value)) return true;
  return false;
}

std::vector<std::string> JobLimits::names() {
  std::vector<std::string> out = {"pixels_per_frame",
                                  "tiles_per_frame",
                                  "tasks_per_job",
                                  "frames_per_job",
                                  "spp",
                                  "name_bytes",
                                  "path_bytes",
                                  "bundle_files",
                                  "parse_memory_mb",
                                  "parse_cpu_seconds",
                                  "parse_wall_seconds",
                                  "parse_children"};
  for (const std::string& n : ImportLimits::names()) out.push_back("import_" + n);
  return out;
}

Coordinator::Coordinator(CoreOptions o)
    : options_(with_defaults(std::move(o))),
      lock_(options_.state_dir),
      blobs_(options_.state_dir + "/blobs"),  // creates the state directory too
      store_(options_.state_dir + "/jobs.sqlite"),
      scheduler_(SchedulerOptions{
          options_.lease_seconds, options_.max_failures, options_.window_frames,
          options_.instance + "-L",
          [this](const std::string& lease, const std::string& worker, const TaskRef& task) {
            ++counters_.leases_expired;  // the scheduler is driven under mu_
            spdlog::warn("lease {} of worker {} on task {} expired: not renewed for {:g} s", lease,
                         worker, task_id_text(task), options_.lease_seconds);
          }}) {
  counters_.lease_buckets.assign(std::size(CoordinatorMetrics::kLeaseBuckets), 0);
  next_seq_ = store_.next_seq();
  for (const JobStore::StoredWorker& w : store_.workers()) {
    // A worker of before the restart has the sweep's time from now to call.
    workers_[w.id] = {w.principal, w.build_id, now()};
    if (!w.refused.empty()) outvoted_[w.id] = w.refused;
  }
  for (const StoredJob& j : store_.jobs()) restore(j);
  recover_folders();
}

void Coordinator::write_folder_record(const StoredJob& j) const {
  std::string dir = options_.state_dir + "/jobs/" + j.id;
  write_file_atomic(dir + "/job.spec", j.spec);
  nlohmann::json meta = {
      {"id", j.id}, {"seq", j.seq}, {"tenant", j.tenant}, {"submitted_unix", j.submitted_unix}};
  write_file_atomic(dir + "/job.json", meta.dump() + "\n");
}

void Coordinator::write_folder_state(const JobRecord& job) const {
  nlohmann::json st = {{"state", int(job.state)}, {"error", job.error}};
  try {
    write_file_atomic(options_.state_dir + "/jobs/" + job.id + "/state.json", st.dump() + "\n");
  } catch (const std::exception& e) {  // the database holds it; the folder's copy is a backup
    spdlog::warn("job {}: {}", job.id, e.what());
  }
}

// Temporary files of atomic writes (write_file_atomic: NAME.tmp.PID.N) that a process killed
// mid-write left behind: never renamed into place, so nothing reads them.
static void remove_stale_temporaries(const std::string& dir) {
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
          write_folder_record({id, job.seq, encode_job_spec(job.spec), 0, "", job.submitted_unix, 0,
                               job.tenant, ""});
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
      stored.spec = read_file_bytes((entry.path() / "job.spec").string());
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
    store_.insert_job(stored);
    if (stored.state != int(JobState::Queued)) store_.set_state(id, stored.state, stored.error);
    restore(stored);
    lost.push_back(id);
  }
  if (!lost.empty()) {
    std::string ids;
    for (const std::string& id : lost) ids += " " + id;
    spdlog::warn("recovered {} jobs from their folders:{}", lost.size(), ids);
  }
}

Coordinator::~Coordinator() = default;

// Validates a spec against the stored blobs and makes the job's record.
std::shared_ptr<JobRecord> Coordinator::build_job(const std::string& id, uint64_t seq,
                                                  const JobSpec& spec, const Caller& caller,
                                                  bool restoring) {
  auto job = std::make_shared<JobRecord>();
  job->id = id;
  job->seq = seq;
  job->spec = spec;
  if (spec.scene_path.empty()) refuse(ErrorCode::InvalidArgument, "scene_path is empty");
  check_limits(spec);
  job->build_id = spec.build_id;
  std::string bundle_dir = options_.state_dir + "/jobs/" + id + "/bundle";
  try {
    check_bundle(
        spec, [&](const std::string& d) { return blob_visible(d, caller); }, restoring);
    try {
      blobs_.materialize(spec.files, bundle_dir);
    } catch (const BlobError& e) {
      refuse(ErrorCode::InvalidArgument, e.what());
    } catch (const fs::filesystem_error& e) {  // its message would name the state directory
      refuse(ErrorCode::Unavailable, "cannot lay out the bundle: " + e.code().message());
    }
  } catch (const CoordinatorError& e) {
    // A stored job whose blobs are gone (the blob store deleted or damaged under a stopped
    // coordinator) keeps its frames when its scene summaries are in its folder: restore() fails
    // it with the reason, and fetch still serves the passes its checkpoints hold.
    if (!restoring) throw;
    job->bundle_problem = e.what();
  }
  add_frames(*job, bundle_dir, restoring);
  return job;
}

// The summary of each scene file of the job: from the scene check (a child process, never this
// one), or when restoring from the job folder's copy of its answer if this build wrote it.
std::map<std::string, SceneSummary> Coordinator::scene_summaries(const JobRecord& job,
                                                                 const std::string& bundle_dir,
                                                                 bool restoring) const {
  std::vector<std::string> paths = job_scene_paths(job.spec);
  for (const std::string& path : paths) {
    bool in_bundle = false;
    for (const BundleEntry& e : job.spec.files) in_bundle |= e.path == path;
    if (!in_bundle)
      refuse(ErrorCode::InvalidArgument,
             "scene file '" + clip(path) + "' is not in the submitted bundle");
  }
  const std::string cache = options_.state_dir + "/jobs/" + job.id + "/scenes.json";
  std::vector<SceneSummary> summaries;
  if (restoring && fs::exists(cache)) {
    try {
      nlohmann::json j = nlohmann::json::parse(read_file_bytes(cache));
      if (j.at("build").get<std::string>() == build_id() && j.at("scenes").size() == paths.size())
        for (const nlohmann::json& s : j.at("scenes")) summaries.push_back(summary_from_json(s));
    } catch (const std::exception& e) {
      spdlog::warn("job {}: {} not used ({}); checking its scenes again", job.id, cache, e.what());
      summaries.clear();
    }
  }
  if (summaries.empty()) {
    if (!job.bundle_problem.empty()) refuse(ErrorCode::InvalidArgument, job.bundle_problem);
    summaries = options_.scene_checker(bundle_dir, job.spec);
    if (summaries.size() != paths.size())
      refuse(ErrorCode::Internal, "the scene check answered " + std::to_string(summaries.size()) +
                                      " scenes for " + std::to_string(paths.size()));
    nlohmann::json j = {{"build", build_id()}, {"scenes", nlohmann::json::array()}};
    for (const SceneSummary& s : summaries) j["scenes"].push_back(to_json(s));
    try {
      write_file_atomic(cache, j.dump() + "\n");
    } catch (const std::exception& e) {  // only a restart's shortcut is lost
      spdlog::warn("job {}: {}", job.id, e.what());
    }
  }
  std::map<std::string, SceneSummary> out;
  for (size_t i = 0; i < paths.size(); ++i) out.emplace(paths[i], summaries[i]);
  return out;
}

// Splits every frame of the job; all must agree on resolution and passes.
void Coordinator::add_frames(JobRecord& job, const std::string& bundle_dir, bool restoring) {
  const JobSpec& spec = job.spec;
  std::vector<uint32_t> frames;
  if (!spec.frames.empty()) {
    try {
      frames = parse_frame_range(spec.frames);
    } catch (const FrameRangeError& e) {
      refuse(ErrorCode::InvalidArgument, std::string("frames: ") + e.what());
    }
  }
  const JobLimits& limits = options_.limits;
  if (frames.size() > limits.frames_per_job)
    refuse(ErrorCode::ResourceExhausted, "frames: " + std::to_string(frames.size()) +
                                             " frames; the limit frames_per_job is " +
                                             std::to_string(limits.frames_per_job));
  int tile_size = spec.tile_size ? int(spec.tile_size) : kDefaultTileSize;
  if (tile_size < 8 || tile_size > 4096)
    refuse(ErrorCode::InvalidArgument,
           "tile_size: " + std::to_string(tile_size) + " is outside 8..4096");
  if (frames.empty()) frames.push_back(0);  // a job without a frame range renders frame 0
  std::map<std::string, SceneSummary> scene_of = scene_summaries(job, bundle_dir, restoring);
  for (uint32_t number : frames) {
    auto f = std::make_unique<FrameRecord>();
    f->number = number;
    f->scene_path = expand_frame_pattern(spec.scene_path, number);
    const SceneSummary& scene = scene_of.at(f->scene_path);
    uint64_t pixels = uint64_t(scene.width) * uint64_t(scene.height);
    if (pixels > limits.pixels_per_frame)
      refuse(ErrorCode::ResourceExhausted,
             "frame " + std::to_string(number) + ": " + std::to_string(scene.width) + "x" +
                 std::to_string(scene.height) + " is " + std::to_string(pixels) +
                 " pixels; the limit pixels_per_frame is " +
                 std::to_string(limits.pixels_per_frame));
    if (scene.spp > limits.spp)
      refuse(ErrorCode::ResourceExhausted,
             "spp " + std::to_string(scene.spp) +
                 " is over the limit spp = " + std::to_string(limits.spp));
    FramePlan plan = plan_frame(scene, number, tile_size);
    if (plan.tiles.size() > limits.tiles_per_frame)
      refuse(ErrorCode::ResourceExhausted,
             "frame " + std::to_string(number) + ": " + std::to_string(plan.tiles.size()) +
                 " tiles of " + std::to_string(tile_size) +
                 " pixels; the limit tiles_per_frame is " + std::to_string(limits.tiles_per_frame) +
                 " (use a larger --tile-size)");
    uint64_t tasks = uint64_t(frames.size()) * plan.passes * plan.tiles.size();
    if (tasks > limits.tasks_per_job)
      refuse(ErrorCode::ResourceExhausted,
             std::to_string(frames.size()) + " frames x " + std::to_string(plan.passes) +
                 " passes x " + std::to_string(plan.tiles.size()) +
                 " tiles = " + std::to_string(tasks) + " tasks; the limit tasks_per_job is " +
                 std::to_string(limits.tasks_per_job));
    f->base = plan.base;
    if (job.frames.empty()) {
      job.tiles = plan.tiles;
      job.splats = plan.splats;
      job.passes = plan.passes;
      job.noise_target = plan.noise_target;
      job.spp_per_pass = plan.spp_per_pass;
    } else if (plan.tiles != job.tiles || plan.passes != job.passes) {
      refuse(ErrorCode::InvalidArgument,
             "frame " + std::to_string(number) + " (" + f->scene_path +
                 ") differs from the first frame in resolution or passes; one job renders "
                 "frames of one size and pass count");
    }
    f->progress.passes_total = job.passes;
    f->checkpoint = std::make_unique<FrameCheckpoint>(options_.state_dir + "/jobs/" + job.id +
                                                      "/frame-" + std::to_string(number));
    job.by_number[number] = f.get();
    job.frames.push_back(std::move(f));
  }
}

// Rebuilds a frame's accumulator from its checkpoint; the scheduler learns which tasks are in.
void Coordinator::resume_frame(JobRecord& job, FrameRecord& f) {
  FrameCheckpoint::Loaded loaded = f.checkpoint->load();
  for (const std::string& p : loaded.problems)
    spdlog::warn("job {} frame {}: {} (its tasks will be rendered again)", job.id, f.number, p);
  if (!loaded.prefix && loaded.tasks.empty()) return;
  f.acc = std::make_unique<FrameAccumulator>(f.base, job.tiles, job.splats, job.merge_options());
  if (loaded.prefix) {
    try {
      f.acc->resume_from(std::move(*loaded.prefix));
    } catch (const std::exception& e) {
      spdlog::warn("job {} frame {}: checkpoint not used: {}", job.id, f.number, e.what());
      f.acc =
          std::make_unique<FrameAccumulator>(f.base, job.tiles, job.splats, job.merge_options());
    }
  }
  for (FrameCheckpoint::TaskResult& t : loaded.tasks) {
    if (t.tile >= job.tiles.size()) continue;
    try {
      if (f.acc->add(std::move(t.buffer)) != FrameAccumulator::AddResult::Dropped)
        scheduler_.mark_done(TaskRef{job.id, f.number, t.pass, t.tile});
    } catch (const std::exception& e) {
      spdlog::warn("job {} frame {} task {}/{}: not used: {}", job.id, f.number, t.pass, t.tile,
                   e.what());
    }
  }
  scheduler_.mark_passes_done(job.id, f.number, f.acc->passes_merged());
  if (f.acc->passes_merged() > 0) f.checkpoint->save_prefix(f.acc->frame());
  publish_frame(job, f);
}

void Coordinator::restore(const StoredJob& stored) {
  std::optional<JobSpec> spec = decode_job_spec(stored.spec);
  if (!spec) return restore_failed(stored, "its stored spec does not parse");
  if (!spec->request_id.empty()) requests_[{stored.tenant, spec->request_id}] = stored.id;
  std::shared_ptr<JobRecord> job;
  try {
    job = build_job(stored.id, stored.seq, *spec, Caller{}, true);
    job->state = JobState(stored.state);
    job->error = stored.error;
    job->submitted_unix = stored.submitted_unix;
    job->core_seconds = stored.core_seconds;
    job->tenant = stored.tenant;
    if (job->build_id.empty()) job->build_id = stored.build_id;
    if (!job->bundle_problem.empty() && !terminal(job->state))
      set_state(*job, JobState::Failed,
                "the coordinator could not restore its scene bundle: " + job->bundle_problem +
                    "; the passes merged before are kept (fetch)");
    scheduler_.add_job(job->id, job->frame_numbers(), uint32_t(job->tiles.size()), job->passes,
                       spec->priority);
    if (terminal(job->state)) {
      scheduler_.cancel_job(job->id);
    } else {
      // Leases from before the restart, ended: their holders' late results are still accepted.
      store_.for_each_lease(job->id, [&](const StoredLease& l) {
        scheduler_.restore_lease(l.lease_id, TaskRef{job->id, l.frame, l.pass, l.tile},
                                 l.worker_id);
      });
      // Refused results before the restart still count against their workers.
      for (const std::string& worker : store_.refused_workers(job->id))
        scheduler_.restore_refusal(job->id, worker);
      // Failures before the restart still count toward failing a task (and skipping a worker).
      for (const JobStore::TaskFailure& e : store_.failures(job->id))
        scheduler_.restore_failure(TaskRef{job->id, e.frame, e.pass, e.tile}, e.worker_id,
                                   e.message);
      if (scheduler_.job_failed(job->id))
        set_state(*job, JobState::Failed, scheduler_.job_error(job->id));
    }
    for (auto& f : job->frames) resume_frame(*job, *f);
  } catch (const std::exception& e) {  // bad_alloc included: one job never stops the others
    if (job) scheduler_.cancel_job(job->id);
    return restore_failed(stored, e.what());
  }
  jobs_[job->id] = job;
  spdlog::info("restored job {} ({}), {} tasks done in the database", job->id,
               job_state_name(job->state), store_.tasks_done(job->id));
}

void Coordinator::restore_failed(const StoredJob& stored, const std::string& why) {
  auto job = std::make_shared<JobRecord>();
  job->id = stored.id;
  job->seq = stored.seq;
  if (std::optional<JobSpec> spec = decode_job_spec(stored.spec)) job->spec = *spec;
  job->submitted_unix = stored.submitted_unix;
  job->core_seconds = stored.core_seconds;
  job->tenant = stored.tenant;
  job->state = JobState(stored.state);
  job->error = stored.error;
  jobs_[job->id] = job;
  spdlog::error("job {}: cannot be restored: {}", stored.id, why);
  if (!terminal(job->state))
    set_state(*job, JobState::Failed, "the coordinator could not restore it: " + why);
}

void Coordinator::check_limits(const JobSpec& spec) const {
  const JobLimits& l = options_.limits;
  auto too_long = [&](const std::string& what, const std::string& s, uint64_t limit,
                      const char* name) {
    if (s.size() > limit)
      refuse(ErrorCode::InvalidArgument, what + " is " + std::to_string(s.size()) +
                                             " bytes; the limit " + name + " is " +
                                             std::to_string(limit));
  };
  too_long("name", spec.name, l.name_bytes, "name_bytes");
  too_long("scene_path", spec.scene_path, l.path_bytes, "path_bytes");
  too_long("frames", spec.frames, l.path_bytes, "path_bytes");
  too_long("build_id", spec.build_id, l.name_bytes, "name_bytes");
  too_long("request_id", spec.request_id, l.name_bytes, "name_bytes");
  for (const auto& [what, text] : {std::pair<const char*, const std::string*>{"name", &spec.name},
                                   {"scene_path", &spec.scene_path},
                                   {"frames", &spec.frames},
                                   {"build_id", &spec.build_id},
                                   {"request_id", &spec.request_id}})
    if (std::string why = text_problem(*text); !why.empty())
      refuse(ErrorCode::InvalidArgument,
             std::string(what) + ": " + why +
                 " (names and paths are printed in terminals and logs: control characters and "
                 "bytes that are not UTF-8 are refused)");
  if (spec.files.size() > l.bundle_files)
    refuse(ErrorCode::ResourceExhausted, "the bundle has " + std::to_string(spec.files.size()) +
                                             " files; the limit bundle_files is " +
                                             std::to_string(l.bundle_files));
  for (const BundleEntry& f : spec.files)
    too_long("a bundle path", f.path, l.path_bytes, "path_bytes");
}

bool Coordinator::build_ok(const JobRecord& job, const std::string& build_id) const {
  return job.build_id.empty() || job.build_id == build_id;
}

// ---------------------------------------------------------------------------------------------
// Jobs

bool Coordinator::blob_visible(const std::string& sha256, const Caller& caller) const {
  if (!blobs_.has(sha256)) return false;
  if (caller.all_tenants) return true;
  std::lock_guard lock(mu_);
  return store_.blob_tenant(caller.tenant, sha256);
}

std::vector<std::string> Coordinator::missing_blobs(const std::vector<std::string>& sha256,
                                                    const Caller& caller) const {
  std::vector<std::string> missing;
  for (const std::string& d : sha256) {
    if (!is_sha256_hex(d))
      refuse(ErrorCode::InvalidArgument, "'" + d + "' is not a SHA-256 (64 lower-case hex)");
    if (!blob_visible(d, caller)) missing.push_back(d);
  }
  return missing;
}

std::string Coordinator::put_blob(std::string_view bytes, const Caller& caller) {
  std::string digest = blobs_.put(bytes);
  if (!caller.tenant.empty()) {
    std::lock_guard lock(mu_);
    store_.add_blob_tenant(caller.tenant, digest);
  }
  return digest;
}

std::string Coordinator::submitted_before(const JobSpec& spec, const Caller& caller) const {
  if (spec.request_id.empty()) return "";
  auto it = requests_.find({caller.tenant, spec.request_id});
  if (it == requests_.end()) return "";
  std::shared_ptr<JobRecord> job = find(it->second);
  if (job && encode_job_spec(job->spec) != encode_job_spec(spec))
    refuse(ErrorCode::InvalidArgument, "request_id '" + clip(spec.request_id) +
                                           "' already made job " + it->second +
                                           " from a different spec");
  return it->second;
}

std::string Coordinator::submit(const JobSpec& spec, const Caller& caller) {
  std::string staging;
  {
    std::lock_guard lock(mu_);
    if (std::string id = submitted_before(spec, caller); !id.empty()) {
      spdlog::info("submit by {} repeated request {}: job {}", caller.principal,
                   clip(spec.request_id), id);
      return id;
    }
    // Checked in a folder of its own: the job takes its id once it is accepted, so a refused
    // submit leaves no gap in the ids (recover_folders removes such folders after a crash).
    staging = ".submit-" + options_.instance + "-" + std::to_string(next_staging_++);
  }
  const std::string jobs_dir = options_.state_dir + "/jobs/";
  auto remove = [&](const std::string& name) {
    std::error_code ec;  // a refused job leaves nothing behind
    fs::remove_all(jobs_dir + name, ec);
  };
  std::shared_ptr<JobRecord> job;
  try {
    job = build_job(staging, 0, spec, caller);
  } catch (...) {
    remove(staging);
    throw;
  }
  job->submitted_unix = int64_t(unix_now());
  job->tenant = caller.tenant;
  std::lock_guard lock(mu_);
  // The same request, retried while this one was being built: the first to get here wins.
  if (std::string first = submitted_before(spec, caller); !first.empty()) {
    remove(staging);
    return first;
  }
  uint64_t seq = next_seq_++;
  char buf[32];
  std::snprintf(buf, sizeof buf, "j%06llu", (unsigned long long)seq);
  std::string id = buf;
  std::error_code ec;
  fs::rename(jobs_dir + staging, jobs_dir + id, ec);
  if (ec) {
    remove(staging);
    refuse(ErrorCode::Unavailable, "cannot store the job: " + ec.message());
  }
  job->id = id;
  job->seq = seq;
  for (auto& f : job->frames)
    f->checkpoint =
        std::make_unique<FrameCheckpoint>(jobs_dir + id + "/frame-" + std::to_string(f->number));
  StoredJob record{id,
                   seq,
                   encode_job_spec(spec),
                   int(JobState::Queued),
                   "",
                   job->submitted_unix,
                   0,
                   caller.tenant,
                   ""};
  try {
    write_folder_record(record);  // first: a folder without it is a submit that never finished
    store_.insert_job(record);
  } catch (const std::exception& e) {
    remove(id);
    refuse(ErrorCode::Unavailable, std::string("cannot store the job: ") + e.what());
  }
  if (!spec.request_id.empty()) requests_[{caller.tenant, spec.request_id}] = id;
  scheduler_.add_job(id, job->frame_numbers(), uint32_t(job->tiles.size()), job->passes,
                     spec.priority);
  jobs_[id] = job;
  ++version_;
  changed_.notify_all();
  spdlog::info("job {} submitted by {}{}: {} frames x {} passes x {} tiles ({})", id,
               caller.principal, caller.tenant.empty() ? "" : " (tenant " + caller.tenant + ")",
               job->frames.size(), job->passes, job->tiles.size(), job->frames[0]->base.integrator);
  return id;
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
  if (!job || (!caller.all_tenants && job->tenant != caller.tenant))
    refuse(ErrorCode::NotFound, "no job '" + clip(id) + "'");
  return job;
}

// The last merge's figures, with the ETA from this frame's time per pass in this run so far.
FrameStatus Coordinator::frame_status(const JobRecord& job, const FrameRecord& f) const {
  FrameStatus s{f.number, f.progress};
  FrameProgress& p = s.progress;
  double seconds = f.first_lease_at < 0 ? -1 : now() - f.first_lease_at;
  p.eta_seconds =
      p.done ? 0
             : eta_seconds(p.passes_merged, p.passes_total, p.rel_mse, job.noise_target, seconds);
  return s;
}

JobStatus Coordinator::status_of(const JobRecord& job) const {
  JobStatus s;
  s.job_id = job.id;
  s.name = job.spec.name;
  s.tenant = job.tenant;
  s.build_id = job.build_id;
  s.state = job.state;
  s.error = job.error;
  if (!terminal(job.state) && !storage_problem_.empty())
    s.error = "waiting for the coordinator's storage: " + storage_problem_;
  s.core_seconds = job.core_seconds;
  s.submitted_unix = job.submitted_unix;
  for (const auto& f : job.frames) s.frames.push_back(frame_status(job, *f));
  return s;
}

// After a merge or a restore: the frame's figures, the scheduler's stop, the job's completion.
void Coordinator::publish_frame(JobRecord& job, FrameRecord& f) {
  if (f.acc)
    f.progress = frame_progress(f.acc->frame(), job.passes, f.acc->done(),
                                f.acc->stopped_on_target(), job.noise_target, -1);
  if (f.progress.done) {
    scheduler_.stop_frame(job.id, f.number, f.progress.passes_merged);
    if (!f.leases_dropped) store_.delete_leases(job.id, f.number);  // no late result is needed
    f.leases_dropped = true;
  }
  bool all_done = true;
  for (auto& g : job.frames) all_done &= g->progress.done;
  if (all_done && !terminal(job.state)) set_state(job, JobState::Completed, "");
  ++version_;
  changed_.notify_all();
}

void Coordinator::set_state(JobRecord& job, JobState s, const std::string& err) {
  job.state = s;
  job.error = err;
  store_.set_state(job.id, int(s), err);
  if (terminal(s)) {
    write_folder_state(job);
    store_.delete_leases(job.id);
    scheduler_.cancel_job(job.id);  // frees its tasks and leases (a no-op once all are done)
    for (auto it = verifying_.begin(); it != verifying_.end();)
      it = it->first.job_id == job.id ? verifying_.erase(it) : std::next(it);
  }
  if (terminal(s))
    spdlog::info("job {} {}{}", job.id, job_state_name(s), err.empty() ? "" : ": " + err);
  ++version_;
  changed_.notify_all();
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

void Coordinator::cancel(const std::string& id, const Caller& caller) {
  std::shared_ptr<JobRecord> job;
  {
    std::lock_guard lock(mu_);
    job = find_for(id, caller);
    if (job->state == JobState::Cancelled) return;  // idempotent: a second or retried cancel
    if (terminal(job->state))
      refuse(ErrorCode::FailedPrecondition,
             "job " + id + " has already " +
                 (job->state == JobState::Completed ? "completed" : "failed") +
                 "; there is nothing to cancel");
    scheduler_.cancel_job(id);
    set_state(*job, JobState::Cancelled, "cancelled by " + caller.principal);
  }
  // Its merged passes are in the checkpoints (fetch reads them there): the accumulators go.
  for (auto& f : job->frames) {
    std::lock_guard frame_lock(f->m);
    f->acc.reset();
  }
}

FrameImage Coordinator::fetch(const std::string& job_id, uint32_t frame,
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
  if (f->acc && f->acc->passes_merged() > 0) {
    image.buffer = encode_buffer(f->acc->frame());
  } else {
    std::string path = f->checkpoint->dir() + "/prefix.rfb";
    if (!fs::exists(path))
      refuse(ErrorCode::FailedPrecondition, "frame " + std::to_string(f->number) + " of job " +
                                                job->id + " has no complete pass yet");
    image.buffer = read_file_bytes(path);
  }
  return image;
}

// ---------------------------------------------------------------------------------------------
// Workers

// A registration no call has used for kUnusedWorkerSeconds (a worker that registered and died, or
// a client registering in a loop) is forgotten, in memory and in the store; a live worker that
// comes back is answered NOT_FOUND and registers again. Swept at most once a minute, at a
// registration.
void Coordinator::forget_unused_workers() {
  const double expiry = std::max(kUnusedWorkerSeconds, 10 * options_.lease_seconds);
  if (now() - last_worker_sweep_ < 60) return;
  last_worker_sweep_ = now();
  std::vector<std::string> gone;
  for (const auto& [id, w] : workers_) {
    if (!w.used && !outvoted_.count(id) && now() - w.registered_at > expiry) gone.push_back(id);
  }
  for (const std::string& id : gone) {
    workers_.erase(id);
    last_seen_.erase(id);
    store_.delete_worker(id);
  }
  if (!gone.empty())
    spdlog::info("forgot {} worker registrations unused for {:g} s", gone.size(), expiry);
}

Registration Coordinator::register_worker(const WorkerInfo& w, const Caller& caller) {
  std::lock_guard lock(mu_);
  std::string host;
  for (char c : w.hostname.substr(0, 64))  // part of an id that appears in logs and file rows
    if (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '.') host += c;
  if (host.empty()) host = "worker";
  Registration r;
  r.worker_id = options_.instance + "-w" + std::to_string(next_worker_++) + "-" + host;
  r.lease_seconds = uint32_t(std::max(1.0, options_.lease_seconds));
  r.keepalive_seconds = uint32_t(std::max(1.0, options_.lease_seconds / 3));
  forget_unused_workers();
  store_.insert_worker({r.worker_id, caller.principal, w.build_id.substr(0, 256)});
  workers_[r.worker_id] = {caller.principal, w.build_id.substr(0, 256), now()};
  last_seen_[r.worker_id] = now();
  spdlog::info("worker {} registered by {}: {} cores, {}, {}", r.worker_id, caller.principal,
               w.cores, clip(w.build_id), clip(w.isa));
  return r;
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
  std::string holder = scheduler_.lease_worker(lease_id);
  // A lease whose record is gone ended with its task settled (done, stopped, or its job over):
  // nothing sent under it will be merged, whoever sends it.
  if (holder.empty() && (scheduler_.retired(lease_id) || (task && scheduler_.settled(*task))))
    return false;
  if (holder.empty()) refuse(ErrorCode::NotFound, "no lease '" + clip(lease_id) + "'");
  if (holder != worker_id) {
    spdlog::warn("refused: worker {} used lease {}, held by {}", worker_id, lease_id, holder);
    refuse(ErrorCode::PermissionDenied, "lease " + lease_id + " is held by another worker");
  }
  if (task && !(*scheduler_.lease_task(lease_id) == *task)) {
    spdlog::warn("refused: worker {} sent task {} under lease {}, which is for task {}", worker_id,
                 task_id_text(*task), lease_id, task_id_text(*scheduler_.lease_task(lease_id)));
    refuse(ErrorCode::PermissionDenied, "lease " + lease_id + " is for another task");
  }
  return true;
}

LeaseResult Coordinator::lease(const std::string& worker_id, const Caller& caller) {
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
  LeaseResult out;
  // Only jobs that merge this worker's build (a job pinned to another build is not its work).
  const std::string& build = workers_.at(worker_id).build_id;
  Scheduler::JobFilter may = [&](const std::string& job_id) {
    std::shared_ptr<JobRecord> job = find(job_id);
    return job && build_ok(*job, build);
  };
  std::optional<Lease> l = scheduler_.lease(worker_id, now(), may);
  if (!l) {
    out.no_more_work = !scheduler_.work_left_for(worker_id, may);
    return out;
  }
  try {
    store_.insert_lease(
        {l->lease_id, l->task.job_id, l->task.frame, l->task.pass, l->task.tile, worker_id});
  } catch (const std::exception& e) {  // the coordinator's storage, not the worker's doing
    scheduler_.fail(l->lease_id, "", /*handed_back=*/true, now());
    storage_failed(e.what());
    refuse(ErrorCode::Unavailable,
           std::string("the coordinator cannot store leases now (") + e.what() + "); retry later");
  }
  ++counters_.tasks_leased;
  std::shared_ptr<JobRecord> job = find(l->task.job_id);
  FrameRecord* f = job->by_number.at(l->task.frame);
  if (f->first_lease_at < 0) f->first_lease_at = now();
  if (job->state == JobState::Queued) set_state(*job, JobState::Running, "");
  out.task =
      TaskAssignment{l->task,         l->lease_id,         job->tiles[l->task.tile], f->scene_path,
                     job->spec.files, job->spec.overrides, f->base.scene_digest};
  return out;
}

uint32_t Coordinator::renew(const std::string& worker_id, const std::string& lease_id,
                            const Caller& caller) {
  std::lock_guard lock(mu_);
  check_worker(worker_id, caller);
  check_lease(worker_id, lease_id, nullptr);
  switch (scheduler_.renew(lease_id, now())) {
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
    for (const std::string& id : scheduler_.leased_jobs([&](const std::string& w) {
           auto it = workers_.find(w);
           return it != workers_.end() && it->second.principal == caller.principal;
         })) {
      std::shared_ptr<JobRecord> job = find(id);
      if (!job) continue;
      for (const BundleEntry& f : job->spec.files) leased |= f.sha256 == sha256;
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

// Decodes a result and checks it belongs to its task: the task's tile, its one pass, and the
// frame's header (scene digest, seed, frame, integrator, settings, resolution).
SampleBuffer Coordinator::checked_buffer(const JobRecord& job, const FrameRecord& f,
                                         const TaskResult& r) const {
  std::string task_id = task_id_text(r.task);
  SampleBuffer buffer;
  try {
    buffer = decode_buffer(r.buffer, "sample buffer of task " + task_id);
  } catch (const std::exception& e) {
    refuse(ErrorCode::InvalidArgument, e.what());
  }
  const Rect& rect = job.tiles[r.task.tile];
  if (!(buffer.rect == rect))
    refuse(ErrorCode::InvalidArgument,
           "task " + task_id + ": buffer covers " + std::to_string(buffer.rect.w) + "x" +
               std::to_string(buffer.rect.h) + " at " + std::to_string(buffer.rect.x0) + "," +
               std::to_string(buffer.rect.y0) + ", not the task's tile");
  if (!(buffer.header.passes == PassSet::range(r.task.pass, r.task.pass + 1)))
    refuse(ErrorCode::InvalidArgument, "task " + task_id + ": buffer holds passes " +
                                           buffer.header.passes.to_string() + ", not pass " +
                                           std::to_string(r.task.pass));
  if (std::string why = merge_incompatibility(f.base, buffer.header); !why.empty())
    refuse(ErrorCode::InvalidArgument, "task " + task_id + ": " + why);
  if (std::string why = task_buffer_problem(buffer, job.spp_per_pass); !why.empty())
    refuse(ErrorCode::InvalidArgument, "task " + task_id + ": " + why);
  return buffer;
}

// The scheduler's verdict on a durable result and, when it is the first, the database row.
// The row goes first: if the database cannot take it, the scheduler has not counted the task
// done, and the worker's retry finds it still open.
bool Coordinator::record_result(JobRecord& job, const TaskResult& r, double core_seconds,
                                const std::string& build_id) {
  if (!build_ok(job, build_id)) return false;  // another build's result was merged meanwhile
  if (scheduler_.settled(r.task)) {
    scheduler_.complete(r.lease_id, r.task, now());  // ends the lease
    return false;  // another result came first, or the job was cancelled or failed meanwhile
  }
  try {
    if (job.build_id.empty()) store_.set_build(job.id, build_id);
    store_.task_done(job.id, r.task.frame, r.task.pass, r.task.tile, r.worker_id);
    store_.add_core_seconds(job.id, core_seconds);
  } catch (const std::exception& e) {
    storage_failed(e.what());
    refuse(ErrorCode::Unavailable,
           std::string("the coordinator cannot store results now (") + e.what() + "); retry later");
  }
  if (job.build_id.empty()) job.build_id = build_id;  // the first merged result pins the job
  job.core_seconds += core_seconds;
  scheduler_.complete(r.lease_id, r.task, now());
  storage_ok();
  return true;
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

bool Coordinator::check_upload(const std::string& worker_id, const std::string& lease_id,
                               const TaskRef& task, const Caller& caller) const {
  std::lock_guard lock(mu_);
  check_worker(worker_id, caller);
  std::shared_ptr<JobRecord> job = find_or_throw(task.job_id);
  if (!job->by_number.count(task.frame) || task.tile >= job->tiles.size() ||
      task.pass >= job->passes)
    refuse(ErrorCode::NotFound, "job " + job->id + " has no task " + task_id_text(task));
  return check_lease(worker_id, lease_id, &task) && !scheduler_.settled(task);
}

void Coordinator::refuse_upload(const std::string& worker_id, const std::string& lease_id,
                                const TaskRef& task, const std::string& why) {
  spdlog::warn("refused the result of task {} from worker {}: {}", task_id_text(task),
               clip(worker_id), why);
  std::lock_guard lock(mu_);
  ++counters_.results_refused;
  scheduler_.refuse_result(lease_id, now());  // counted against the worker, not the job
  store_.result_refused(task.job_id, task.frame, task.pass, task.tile, worker_id, why);
}

bool Coordinator::complete(const TaskResult& r, const Caller& caller) {
  if (!check_upload(r.worker_id, r.lease_id, r.task, caller)) return false;  // not needed
  std::shared_ptr<JobRecord> job;
  FrameRecord* f = nullptr;
  {
    std::lock_guard lock(mu_);
    job = find_or_throw(r.task.job_id);
    f = job->by_number.at(r.task.frame);
  }
  SampleBuffer buffer;
  try {
    buffer = checked_buffer(*job, *f, r);
    std::lock_guard lock(mu_);
    if (!build_ok(*job, buffer.header.build_id))
      refuse(ErrorCode::FailedPrecondition, "job " + job->id + " merges results of build '" +
                                                job->build_id + "'; this one is from '" +
                                                clip(buffer.header.build_id) + "'");
  } catch (const CoordinatorError& e) {
    refuse_upload(r.worker_id, r.lease_id, r.task, e.what());
    throw;
  }
  std::lock_guard frame_lock(f->m);  // one merge and checkpoint at a time per frame
  if (!f->acc) {
    {
      std::lock_guard lock(mu_);
      // Merged and checkpointed already, or its job ended meanwhile.
      if (f->progress.done || scheduler_.settled(r.task)) return false;
    }
    f->acc =
        std::make_unique<FrameAccumulator>(f->base, job->tiles, job->splats, job->merge_options());
  }
  if (!f->acc->task_needed(buffer.rect, r.task.pass)) {  // merged already, or beyond the stop
    std::lock_guard lock(mu_);
    scheduler_.complete(r.lease_id, r.task, now());
    return false;
  }
  if (verified(r.task)) {
    std::lock_guard lock(mu_);
    if (!verify(*job, r, buffer)) return true;  // taken, and held until another result agrees
  }
  // Durable first: the task's result, then the database, then the answer.
  try {
    f->checkpoint->save_task(r.task.pass, r.task.tile, buffer);
  } catch (const std::exception& e) {
    // The coordinator's fault (disk full, unwritable state): never the worker's. It retries.
    std::lock_guard lock(mu_);
    storage_failed(e.what());
    refuse(ErrorCode::Unavailable,
           std::string("the coordinator cannot store results now (") + e.what() + "); retry later");
  }
  {
    std::lock_guard lock(mu_);
    if (!record_result(*job, r, buffer.header.core_seconds, buffer.header.build_id)) return false;
    ++counters_.tasks_completed;
    counters_.samples_merged += buffer.total_samples();
    counters_.bytes_merged += r.buffer.size();
    counters_.core_seconds += buffer.header.core_seconds;
  }
  // The merge and the prefix checkpoint hold this frame's lock only: leases, renewals and other
  // frames' merges go on meanwhile.
  bool merged = f->acc->add(std::move(buffer)) == FrameAccumulator::AddResult::Merged;
  if (merged) {
    try {  // the task files stay until a prefix holding them is durable
      f->checkpoint->save_prefix(f->acc->frame());
    } catch (const std::exception& e) {
      std::lock_guard lock(mu_);
      storage_failed(e.what());
    }
  }
  std::lock_guard lock(mu_);
  publish_frame(*job, *f);
  if (f->progress.done) f->acc.reset();  // its image lives in the checkpoint now
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

bool Coordinator::verify(JobRecord& job, const TaskResult& r, const SampleBuffer& buffer) {
  std::vector<std::pair<std::string, SampleBuffer>>& held = verifying_[r.task];
  for (const auto& [worker, other] : held) {
    if (worker == r.worker_id || !same_samples(other, buffer)) continue;
    for (const auto& [liar, theirs] : held) {
      if (same_samples(theirs, buffer)) continue;
      std::string why = "its result of task " + task_id_text(r.task) +
                        " differed from those of workers " + worker + " and " + r.worker_id;
      outvoted_[liar] = why;
      store_.refuse_worker(liar, why);
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
    scheduler_.cancel_job(job.id);
    set_state(job, JobState::Failed, why);
    return false;
  }
  spdlog::info("task {}: result of {} held until another worker's agrees", task_id_text(r.task),
               r.worker_id);
  scheduler_.verify_again(r.lease_id, now());
  return false;
}

void Coordinator::fail(const TaskFailureReport& report, const Caller& caller) {
  std::lock_guard lock(mu_);
  check_worker(report.worker_id, caller);
  check_lease(report.worker_id, report.lease_id, nullptr);
  std::optional<TaskRef> task = scheduler_.lease_task(report.lease_id);
  std::string message = printable(report.message.substr(0, 4096));  // part of the job's error
  switch (scheduler_.fail(report.lease_id, message, report.handed_back, now())) {
    case LeaseOutcome::NotFound:
      refuse(ErrorCode::NotFound, "no lease '" + report.lease_id + "'");
    case LeaseOutcome::Ended:
      refuse(ErrorCode::FailedPrecondition, "lease " + report.lease_id + " has ended");
    case LeaseOutcome::Ok:
      break;
  }
  ++(report.handed_back ? counters_.tasks_handed_back : counters_.tasks_failed);
  if (task && !report.handed_back) {
    // Recorded under the id the scheduler counted it under (the lease's worker).
    store_.task_failed(task->job_id, task->frame, task->pass, task->tile, report.worker_id,
                       message);
    spdlog::warn("task {} failed on {}: {}", task_id_text(*task), report.worker_id, clip(message));
  }
  if (task && scheduler_.job_failed(task->job_id)) {
    std::shared_ptr<JobRecord> job = find(task->job_id);
    if (job && !terminal(job->state))
      set_state(*job, JobState::Failed, scheduler_.job_error(job->id));
  }
}

CoordinatorMetrics Coordinator::metrics() const {
  std::lock_guard lock(mu_);
  CoordinatorMetrics m;
  m.counters = counters_;
  m.counters.calls_refused = refused_calls_;
  m.counters.refusal_lines_suppressed = suppressed_refusal_lines_;
  m.storage_ok = storage_problem_.empty();
  for (const auto& [id, w] : workers_) m.workers_registered += !outvoted_.count(id);
  for (const auto& [id, seen] : last_seen_)
    m.workers_connected += now() - seen <= options_.lease_seconds && !outvoted_.count(id);
  std::map<std::string, Scheduler::JobLoad> load = scheduler_.load_by_job();
  for (const auto& [id, job] : jobs_) {
    ++m.jobs_by_state[size_t(job->state)];
    if (terminal(job->state)) continue;
    CoordinatorMetrics::Job j;
    j.job_id = id;
    if (auto it = load.find(id); it != load.end()) {
      j.tasks_queued = it->second.queued;
      j.tasks_leased = it->second.leased;
    }
    m.tasks_queued += j.tasks_queued;
    m.tasks_leased += j.tasks_leased;
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
