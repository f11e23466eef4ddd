// Intake (core.h): blobs, submission checks and limits, the scene check, and a job's frames.
#include "coordinator/core_internal.h"
#include "coordinator/journal.h"
#include "coordinator/ledger.h"

#include <spdlog/spdlog.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <set>

#include "coordinator/spec_codec.h"
#include "engine/build_info.h"
#include "engine/digest.h"
#include "engine/work_units.h"
#include "farm/frame_range.h"
#include "farm/tags.h"

namespace rf {

namespace fs = std::filesystem;
using core_detail::clip;
using core_detail::refuse;
using core_detail::unix_now;

namespace {

constexpr int kDefaultTileSize = 128;  // big enough that per-task costs stay small

// How the engine splits and checks one frame of a job: the engine calls the coordinator makes,
// in one place.
struct FramePlan {
  BufferHeader base;  // what every task buffer of the frame must match
  TileGrid tiles;
  bool splats = false;
  uint32_t passes = 0;
  double noise_target = 0;
  uint64_t spp_per_pass = 0;
};

FramePlan plan_frame(const SceneSummary& scene, FrameNumber frame, int tile_size) {
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

void Coordinator::lay_out_bundle(const JobSpec& spec, const std::string& bundle_dir,
                                 const Caller& caller, bool restoring) const {
  check_bundle(
      spec, [&](const std::string& d) { return blob_visible(d, caller); }, restoring);
  try {
    blobs_.materialize(spec.files, bundle_dir);
  } catch (const BlobError& e) {
    refuse(ErrorCode::InvalidArgument, e.what());
  } catch (const fs::filesystem_error& e) {  // its message would name the state directory
    refuse(ErrorCode::Unavailable, "cannot lay out the bundle: " + e.code().message());
  }
}

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
  job->priority = spec.priority;
  std::string bundle_dir = options_.state_dir + "/jobs/" + id + "/bundle";
  try {
    lay_out_bundle(spec, bundle_dir, caller, restoring);
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

// The summary of each scene file of `spec` (a job's, or a requeue's scene version): from the
// scene check (a child process, never this one), or when restoring from the job folder's copy of
// its answer (`cache`) if this build wrote it.
std::map<std::string, SceneSummary> Coordinator::scene_summaries(
    const JobRecord& job, const JobSpec& spec, const std::string& bundle_dir,
    const std::string& cache, const std::string& bundle_problem, bool restoring) const {
  std::vector<std::string> paths = job_scene_paths(spec);
  for (const std::string& path : paths) {
    bool in_bundle = false;
    for (const BundleEntry& e : spec.files) in_bundle |= e.path == path;
    if (!in_bundle)
      refuse(ErrorCode::InvalidArgument,
             "scene file '" + clip(path) + "' is not in the submitted bundle");
  }
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
    if (!bundle_problem.empty()) refuse(ErrorCode::InvalidArgument, bundle_problem);
    summaries = options_.scene_checker(bundle_dir, spec);
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

namespace {

// Frame `number` of a job of `frame_count` frames split as the spec says, refused when over a
// limit.
FramePlan checked_plan(const SceneSummary& scene, FrameNumber number, int tile_size,
                       size_t frame_count, const JobLimits& limits) {
  uint64_t pixels = uint64_t(scene.width) * uint64_t(scene.height);
  if (pixels > limits.pixels_per_frame)
    refuse(ErrorCode::ResourceExhausted,
           "frame " + std::to_string(number) + ": " + std::to_string(scene.width) + "x" +
               std::to_string(scene.height) + " is " + std::to_string(pixels) +
               " pixels; the limit pixels_per_frame is " + std::to_string(limits.pixels_per_frame));
  if (scene.spp > limits.spp)
    refuse(ErrorCode::ResourceExhausted,
           "spp " + std::to_string(scene.spp) +
               " is over the limit spp = " + std::to_string(limits.spp));
  FramePlan plan = plan_frame(scene, number, tile_size);
  if (plan.tiles.size() > limits.tiles_per_frame)
    refuse(ErrorCode::ResourceExhausted,
           "frame " + std::to_string(number) + ": " + std::to_string(plan.tiles.size()) +
               " tiles of " + std::to_string(tile_size) + " pixels; the limit tiles_per_frame is " +
               std::to_string(limits.tiles_per_frame) + " (use a larger --tile-size)");
  uint64_t tasks = uint64_t(frame_count) * plan.passes * plan.tiles.size();
  if (tasks > limits.tasks_per_job)
    refuse(ErrorCode::ResourceExhausted,
           std::to_string(frame_count) + " frames x " + std::to_string(plan.passes) + " passes x " +
               std::to_string(plan.tiles.size()) + " tiles = " + std::to_string(tasks) +
               " tasks; the limit tasks_per_job is " + std::to_string(limits.tasks_per_job));
  return plan;
}

int tile_size_of(const JobSpec& spec) {
  return spec.tile_size ? int(spec.tile_size) : kDefaultTileSize;
}

}  // namespace

// Splits every frame of the job; all must agree on resolution and passes.
void Coordinator::add_frames(JobRecord& job, const std::string& bundle_dir, bool restoring) {
  const JobSpec& spec = job.spec;
  std::vector<FrameNumber> frames;
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
  int tile_size = tile_size_of(spec);
  if (tile_size < 8 || tile_size > 4096)
    refuse(ErrorCode::InvalidArgument,
           "tile_size: " + std::to_string(tile_size) + " is outside 8..4096");
  if (frames.empty()) frames.push_back(0);  // a job without a frame range renders frame 0
  std::map<std::string, SceneSummary> scene_of = scene_summaries(
      job, spec, bundle_dir, options_.state_dir + "/jobs/" + job.id + "/scenes.json",
      job.bundle_problem, restoring);
  for (FrameNumber number : frames) {
    auto f = std::make_unique<FrameRecord>();
    f->number = number;
    f->scene_path = expand_frame_pattern(spec.scene_path, number);
    FramePlan plan =
        checked_plan(scene_of.at(f->scene_path), number, tile_size, frames.size(), limits);
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
    f->checkpoint = std::make_unique<FrameCheckpoint>(options_.state_dir + "/jobs/" + job.id + "/" +
                                                      frame_folder(number, 0));
    job.by_number[number] = f.get();
    job.frames.push_back(std::move(f));
  }
}

std::map<FrameNumber, Coordinator::FrameScene> Coordinator::version_scenes(
    const JobRecord& job, uint32_t version, const SceneVersion& scene, const Caller& caller,
    bool restoring) const {
  JobSpec spec = job.spec;
  spec.scene_path = scene.scene_path;
  spec.files = scene.files;
  spec.frames = scene.frames;
  if (spec.scene_path.empty()) refuse(ErrorCode::InvalidArgument, "scene_path is empty");
  check_limits(spec);
  std::vector<FrameNumber> frames;
  try {
    frames = parse_frame_range(spec.frames);
  } catch (const FrameRangeError& e) {
    refuse(ErrorCode::InvalidArgument, std::string("frames: ") + e.what());
  }
  const std::string dir = options_.state_dir + "/jobs/" + job.id + "/";
  const std::string bundle_dir = dir + bundle_folder(version);
  if (!restoring) {
    std::error_code ec;  // a requeue a crash interrupted may have left it
    fs::remove_all(bundle_dir, ec);
  }
  lay_out_bundle(spec, bundle_dir, caller, restoring);
  std::map<std::string, SceneSummary> scene_of = scene_summaries(
      job, spec, bundle_dir, dir + "scenes-v" + std::to_string(version) + ".json", "", restoring);
  std::map<FrameNumber, FrameScene> out;
  for (FrameNumber number : frames) {
    FrameScene fs_{expand_frame_pattern(spec.scene_path, number), {}};
    FramePlan plan = checked_plan(scene_of.at(fs_.scene_path), number, tile_size_of(spec),
                                  job.frames.size(), options_.limits);
    if (plan.tiles != job.tiles || plan.passes != job.passes || plan.splats != job.splats ||
        plan.spp_per_pass != job.spp_per_pass || plan.noise_target != job.noise_target)
      refuse(ErrorCode::InvalidArgument,
             "frame " + std::to_string(number) + " (" + clip(fs_.scene_path) +
                 ") of the new scene differs from the job in resolution, passes, samples per "
                 "pass, noise target or integrator kind; a requeued scene keeps the job's (submit "
                 "a new job to change them)");
    fs_.base = plan.base;
    out.emplace(number, std::move(fs_));
  }
  return out;
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
  if (spec.required_tags.size() > kMaxTags)
    refuse(ErrorCode::InvalidArgument,
           "required_tags: " + std::to_string(spec.required_tags.size()) +
               " worker tags; at most " + std::to_string(kMaxTags));
  for (const std::string& r : spec.required_tags)
    if (std::string why = requirement_problem(r); !why.empty())
      refuse(ErrorCode::InvalidArgument, "required_tags: " + why);
  if (spec.files.size() > l.bundle_files)
    refuse(ErrorCode::ResourceExhausted, "the bundle has " + std::to_string(spec.files.size()) +
                                             " files; the limit bundle_files is " +
                                             std::to_string(l.bundle_files));
  for (const BundleEntry& f : spec.files)
    too_long("a bundle path", f.path, l.path_bytes, "path_bytes");
}

// ---------------------------------------------------------------------------------------------
// Jobs

bool Coordinator::blob_visible(const std::string& sha256, const Caller& caller) const {
  if (!blobs_.has(sha256)) return false;
  if (caller.all_tenants) return true;
  std::lock_guard lock(mu_);
  return store_->blob_tenant(caller.tenant, sha256);
}

std::vector<std::string> Coordinator::missing_blobs(const std::vector<std::string>& sha256,
                                                    const Caller& caller) const {
  std::vector<std::string> missing;
  for (const std::string& d : sha256) {
    if (!is_sha256_hex(d))
      refuse(ErrorCode::InvalidArgument, "'" + d + "' is not a SHA-256 (64 lower-case hex)");
    if (!blob_visible(d, caller))
      missing.push_back(d);
    else
      blobs_.touch(d);  // a submit naming it may follow: its grace period starts now
  }
  return missing;
}

std::string Coordinator::put_blob(std::string_view bytes, const Caller& caller) {
  std::string digest = blobs_.put(bytes);
  if (!caller.tenant.empty()) {
    try {  // stored before the upload is acknowledged (and before a submit may name it)
      journal_->write_ahead({store::AddBlobTenant{caller.tenant, digest}});
    } catch (const StoreError& e) {
      refuse(ErrorCode::Unavailable, std::string("cannot store the upload now: ") + e.what());
    }
  }
  return digest;
}

std::string Coordinator::submitted_before(const JobSpec& spec, const Caller& caller,
                                          std::unique_lock<std::mutex>& lock) const {
  if (spec.request_id.empty()) return "";
  const std::pair<std::string, std::string> key{caller.tenant, spec.request_id};
  auto it = requests_.find(key);
  if (it == requests_.end()) return "";
  // The first submit of this request is storing its job: its answer, once it has one.
  std::string id = it->second;
  changed_.wait(lock, [&] { return jobs_.count(id) || !requests_.count(key); });
  it = requests_.find(key);
  if (it == requests_.end()) return "";  // that submit failed: this one is the first now
  std::shared_ptr<JobRecord> job = find(it->second);
  if (job && !(job->spec == spec))
    refuse(ErrorCode::InvalidArgument, "request_id '" + clip(spec.request_id) +
                                           "' already made job " + it->second +
                                           " from a different spec");
  return it->second;
}

std::string Coordinator::submit(const JobSpec& spec, const Caller& caller) {
  std::string staging;
  {
    std::unique_lock lock(mu_);
    if (std::string id = submitted_before(spec, caller, lock); !id.empty()) {
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
  const std::pair<std::string, std::string> key{caller.tenant, spec.request_id};
  std::string id;
  uint64_t seq = 0;
  {
    std::unique_lock lock(mu_);
    // The same request, retried while this one was being built: the first to get here wins.
    if (std::string first = submitted_before(spec, caller, lock); !first.empty()) {
      remove(staging);
      return first;
    }
    seq = next_seq_++;
    char buf[32];
    std::snprintf(buf, sizeof buf, "j%06llu", (unsigned long long)seq);
    id = buf;
    if (!spec.request_id.empty()) requests_[key] = id;  // a retry meanwhile waits for this one
  }
  // Stored before it is known: the folder's record first (a folder without it is a submit that
  // never finished), then the store's row, written ahead, without the coordinator's lock.
  auto forget = [&] {
    std::lock_guard lock(mu_);
    if (!spec.request_id.empty()) requests_.erase(key);
    changed_.notify_all();
  };
  std::error_code ec;
  fs::rename(jobs_dir + staging, jobs_dir + id, ec);
  if (ec) {
    remove(staging);
    forget();
    refuse(ErrorCode::Unavailable, "cannot store the job: " + ec.message());
  }
  job->id = id;
  job->seq = seq;
  for (auto& f : job->frames)
    f->checkpoint =
        std::make_unique<FrameCheckpoint>(jobs_dir + id + "/frame-" + std::to_string(f->number));
  StoredJob record{id, seq,           spec, int(JobState::Queued), "", job->submitted_unix,
                   0,  caller.tenant, ""};
  try {
    write_folder_record(record);
    journal_->write_ahead({store::InsertJob{record}});
  } catch (const std::exception& e) {
    remove(id);
    forget();
    refuse(ErrorCode::Unavailable, std::string("cannot store the job: ") + e.what());
  }
  std::lock_guard lock(mu_);
  ledger_->add_job(*job);
  jobs_[id] = job;
  reference_blobs(*job, 0, +1);
  ++version_;
  changed_.notify_all();
  spdlog::info("job {} submitted by {}{}: {} frames x {} passes x {} tiles ({})", id,
               caller.principal, caller.tenant.empty() ? "" : " (tenant " + caller.tenant + ")",
               job->frames.size(), job->passes, job->tiles.size(), job->frames[0]->base.integrator);
  return id;
}

}  // namespace rf
