#include "coordinator/service.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <condition_variable>
#include <ctime>
#include <filesystem>
#include <map>
#include <mutex>

#include "coordinator/checkpoint.h"
#include "coordinator/job_store.h"
#include "coordinator/scheduler.h"
#include "engine/digest.h"
#include "engine/progressive.h"
#include "engine/render.h"
#include "farm/blob_store.h"
#include "farm/chunking.h"
#include "farm/convert.h"
#include "farm/frame_range.h"
#include "proto/rayfarm.grpc.pb.h"

namespace rf {

namespace fs = std::filesystem;
namespace pb = rayfarm::v1;
using grpc::ServerContext;
using grpc::Status;
using grpc::StatusCode;

namespace {

constexpr int kDefaultTileSize = 128;  // big enough that per-task costs stay small

Status error(StatusCode code, const std::string& message) { return Status(code, message); }

Status chunk_status(ChunkAssembler::Status s, const std::string& what, const std::string& why) {
  switch (s) {
    case ChunkAssembler::Status::Ok:
      return Status::OK;
    case ChunkAssembler::Status::InvalidArgument:
      return error(StatusCode::INVALID_ARGUMENT, what + ": " + why);
    case ChunkAssembler::Status::ResourceExhausted:
      return error(StatusCode::RESOURCE_EXHAUSTED, what + ": " + why);
    case ChunkAssembler::Status::DataLoss:
      return error(StatusCode::DATA_LOSS, what + ": " + why);
  }
  return error(StatusCode::INTERNAL, what);
}

bool terminal(pb::JobState s) {
  return s == pb::JOB_COMPLETED || s == pb::JOB_FAILED || s == pb::JOB_CANCELLED;
}

double unix_now() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// Thrown by job creation with the status to answer.
struct RequestError {
  StatusCode code;
  std::string message;
};

}  // namespace

// One frame of a job: its merge state, durable checkpoint and progress figures.
struct FrameRecord {
  uint32_t number = 0;
  std::string scene_path;                 // in the bundle
  BufferHeader base;                      // what every task buffer of this frame must match
  std::mutex m;                           // serializes merges and checkpoints of this frame
  std::unique_ptr<FrameAccumulator> acc;  // created on the first result; dropped when done
  std::unique_ptr<FrameCheckpoint> checkpoint;
  // Progress, readable under the coordinator's mutex.
  uint32_t passes_merged = 0;
  double spp = 0, rel_mse = 0;
  bool done = false, stopped_on_target = false;
  double first_lease_at = -1, last_merge_at = -1;
};

struct JobRecord {
  std::string id;
  uint64_t seq = 0;
  pb::JobSpec spec;
  pb::JobState state = pb::JOB_QUEUED;
  std::string error;
  int64_t submitted_unix = 0;
  double core_seconds = 0;
  std::vector<Rect> tiles;
  bool splats = false;
  uint32_t passes = 0;
  double noise_target = 0;
  std::vector<std::unique_ptr<FrameRecord>> frames;
  std::map<uint32_t, FrameRecord*> by_number;
};

class CoordinatorCore {
 public:
  explicit CoordinatorCore(const CoordinatorOptions& o);

  Status submit(grpc::ServerReaderInterface<pb::SubmitRequest>* reader, pb::SubmitResponse* out);
  Status missing_blobs(const pb::MissingBlobsRequest& req, pb::MissingBlobsResponse* out);
  Status list(pb::ListJobsResponse* out);
  Status get(const std::string& job_id, pb::JobStatus* out);
  Status watch(ServerContext* ctx, const std::string& job_id,
               grpc::ServerWriterInterface<pb::JobStatus>* writer);
  Status cancel(const std::string& job_id);
  Status fetch(const pb::FetchRequest& req, grpc::ServerWriterInterface<pb::FetchResponse>* w);

  Status register_worker(const pb::RegisterRequest& req, pb::RegisterResponse* out);
  Status lease(const pb::LeaseRequest& req, pb::LeaseResponse* out);
  Status renew(const pb::RenewRequest& req, pb::RenewResponse* out);
  Status fetch_blob(const pb::BlobRequest& req, grpc::ServerWriterInterface<pb::Chunk>* w);
  Status complete(grpc::ServerReaderInterface<pb::CompleteRequest>* reader,
                  pb::CompleteResponse* out);
  Status fail(const pb::FailRequest& req);

  void shutting_down() {
    std::lock_guard lock(mu_);
    closing_ = true;
    changed_.notify_all();
  }

 private:
  double now() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  std::shared_ptr<JobRecord> build_job(const std::string& id, uint64_t seq,
                                       const pb::JobSpec& spec);
  void restore(const StoredJob& stored);
  void resume_frame(JobRecord& job, FrameRecord& f);
  void publish_frame(JobRecord& job, FrameRecord& f);                        // under mu_
  void set_state(JobRecord& job, pb::JobState s, const std::string& error);  // under mu_
  void fill_status(const JobRecord& job, pb::JobStatus* out) const;          // under mu_
  std::shared_ptr<JobRecord> find(const std::string& id) const;              // under mu_

  CoordinatorOptions options_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::string instance_;  // distinguishes lease ids across restarts
  BlobStore blobs_;
  JobStore store_;
  mutable std::mutex mu_;
  std::condition_variable changed_;
  uint64_t version_ = 0;
  bool closing_ = false;
  Scheduler scheduler_;
  std::map<std::string, std::shared_ptr<JobRecord>> jobs_;
  uint64_t next_seq_ = 1, next_worker_ = 1;
};

CoordinatorCore::CoordinatorCore(const CoordinatorOptions& o)
    : options_(o),
      instance_(sha256_hex(std::to_string(unix_now()) + std::to_string(::getpid())).substr(0, 8)),
      blobs_((fs::create_directories(o.state_dir), o.state_dir + "/blobs")),
      store_(o.state_dir + "/jobs.sqlite"),
      scheduler_(SchedulerOptions{o.lease_seconds, 3, o.window_frames, instance_ + "-L"}) {
  next_seq_ = store_.next_seq();
  for (const StoredJob& j : store_.jobs()) restore(j);
}

// Validates a spec against the stored blobs and makes the job's record: every frame's scene is
// parsed (with the job's overrides) so a bad scene is refused now, not by a worker later.
std::shared_ptr<JobRecord> CoordinatorCore::build_job(const std::string& id, uint64_t seq,
                                                      const pb::JobSpec& spec) {
  auto job = std::make_shared<JobRecord>();
  job->id = id;
  job->seq = seq;
  job->spec = spec;
  if (spec.scene_path().empty())
    throw RequestError{StatusCode::INVALID_ARGUMENT, "scene_path is empty"};
  std::vector<BundleEntry> bundle;
  for (const pb::BundleFile& f : spec.files()) {
    try {
      check_bundle_path(f.path());
    } catch (const BlobError& e) {
      throw RequestError{StatusCode::INVALID_ARGUMENT, std::string("files: ") + e.what()};
    }
    if (!is_sha256_hex(f.sha256()))
      throw RequestError{
          StatusCode::INVALID_ARGUMENT,
          "files: '" + f.path() + "' has no valid SHA-256 (64 lower-case hex digits)"};
    if (!blobs_.has(f.sha256()))
      throw RequestError{
          StatusCode::INVALID_ARGUMENT,
          "files: the content of '" + f.path() + "' (" + f.sha256() + ") was not uploaded"};
    bundle.push_back({f.path(), f.sha256()});
  }
  std::string bundle_dir = options_.state_dir + "/jobs/" + id + "/bundle";
  try {
    blobs_.materialize(bundle, bundle_dir);
  } catch (const BlobError& e) {
    throw RequestError{StatusCode::INVALID_ARGUMENT, e.what()};
  }
  std::vector<uint32_t> frames;
  SceneOverrides ov = to_scene_overrides(spec.overrides());
  if (!spec.frames().empty()) {
    try {
      frames = parse_frame_range(spec.frames());
    } catch (const FrameRangeError& e) {
      throw RequestError{StatusCode::INVALID_ARGUMENT, std::string("frames: ") + e.what()};
    }
  }
  int tile_size = spec.tile_size() ? int(spec.tile_size()) : kDefaultTileSize;
  if (tile_size < 8 || tile_size > 4096)
    throw RequestError{StatusCode::INVALID_ARGUMENT,
                       "tile_size: " + std::to_string(tile_size) + " is outside 8..4096"};
  std::map<std::string, Scene> parsed;  // one parse per distinct scene file
  auto scene_for = [&](const std::string& path) -> const Scene& {
    auto it = parsed.find(path);
    if (it != parsed.end()) return it->second;
    bool in_bundle = false;
    for (const BundleEntry& e : bundle) in_bundle |= e.path == path;
    if (!in_bundle)
      throw RequestError{StatusCode::INVALID_ARGUMENT,
                         "scene file '" + path + "' is not in the submitted bundle"};
    try {
      return parsed.emplace(path, load_scene(bundle_dir + "/" + path, ov)).first->second;
    } catch (const std::exception& e) {
      throw RequestError{StatusCode::INVALID_ARGUMENT, e.what()};
    }
  };
  if (frames.empty())
    frames.push_back(scene_for(expand_frame_pattern(spec.scene_path(), 0)).render.frame);
  for (uint32_t number : frames) {
    auto f = std::make_unique<FrameRecord>();
    f->number = number;
    f->scene_path = expand_frame_pattern(spec.scene_path(), number);
    Scene scene = scene_for(f->scene_path);
    SceneOverrides frame_ov;
    frame_ov.frame = number;
    try {
      apply_overrides(scene, frame_ov);
      check_renderable(scene);
    } catch (const std::exception& e) {
      throw RequestError{StatusCode::INVALID_ARGUMENT, e.what()};
    }
    f->base = frame_header(scene, PassSet{});
    std::vector<Rect> tiles = frame_tiles(scene, tile_size);
    if (job->frames.empty()) {
      job->tiles = tiles;
      job->splats = integrator_splats(integrator_kind(scene.render.integrator.type));
      job->passes = scene.render.passes;
      job->noise_target = scene.render.noise_target;
    } else if (tiles != job->tiles || scene.render.passes != job->passes) {
      throw RequestError{StatusCode::INVALID_ARGUMENT,
                         "frame " + std::to_string(number) + " (" + f->scene_path +
                             ") differs from the first frame in resolution or passes; one job "
                             "renders frames of one size and pass count"};
    }
    f->checkpoint = std::make_unique<FrameCheckpoint>(options_.state_dir + "/jobs/" + id +
                                                      "/frame-" + std::to_string(number));
    job->by_number[number] = f.get();
    job->frames.push_back(std::move(f));
  }
  return job;
}

void CoordinatorCore::resume_frame(JobRecord& job, FrameRecord& f) {
  FrameCheckpoint::Loaded loaded = f.checkpoint->load();
  for (const std::string& p : loaded.problems)
    spdlog::warn("job {} frame {}: {} (its tasks will be rendered again)", job.id, f.number, p);
  if (!loaded.prefix && loaded.tasks.empty()) return;
  ProgressiveOptions po{0, job.passes, job.noise_target};
  f.acc = std::make_unique<FrameAccumulator>(f.base, job.tiles, job.splats, po);
  if (loaded.prefix) {
    try {
      f.acc->resume_from(std::move(*loaded.prefix));
    } catch (const std::exception& e) {
      spdlog::warn("job {} frame {}: checkpoint not used: {}", job.id, f.number, e.what());
      f.acc = std::make_unique<FrameAccumulator>(f.base, job.tiles, job.splats, po);
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
  for (uint32_t p = 0; p < f.acc->passes_merged(); ++p)
    for (uint32_t t = 0; t < job.tiles.size(); ++t)
      scheduler_.mark_done(TaskRef{job.id, f.number, p, t});
  if (f.acc->passes_merged() > 0) f.checkpoint->save_prefix(f.acc->frame());
  publish_frame(job, f);
}

void CoordinatorCore::restore(const StoredJob& stored) {
  pb::JobSpec spec;
  if (!spec.ParseFromString(stored.spec)) {
    spdlog::error("job {}: stored spec does not parse; skipped", stored.id);
    return;
  }
  std::shared_ptr<JobRecord> job;
  try {
    job = build_job(stored.id, stored.seq, spec);
  } catch (const RequestError& e) {
    spdlog::error("job {}: cannot be restored: {}", stored.id, e.message);
    return;
  }
  job->state = pb::JobState(stored.state);
  job->error = stored.error;
  job->submitted_unix = stored.submitted_unix;
  job->core_seconds = stored.core_seconds;
  std::vector<uint32_t> numbers;
  for (auto& f : job->frames) numbers.push_back(f->number);
  scheduler_.add_job(job->id, numbers, uint32_t(job->tiles.size()), job->passes, spec.priority());
  if (terminal(job->state)) {
    scheduler_.cancel_job(job->id);
  } else {
    // Failures before the restart still count toward failing a task (and skipping a worker).
    for (const JobStore::TaskFailure& e : store_.failures(job->id))
      scheduler_.restore_failure(TaskRef{job->id, e.frame, e.pass, e.tile}, e.worker_id, e.message);
    if (scheduler_.job_failed(job->id))
      set_state(*job, pb::JOB_FAILED, scheduler_.job_error(job->id));
  }
  for (auto& f : job->frames) resume_frame(*job, *f);
  jobs_[job->id] = job;
  spdlog::info("restored job {} ({}), {} tasks done in the database", job->id,
               pb::JobState_Name(job->state), store_.tasks_done(job->id));
}

Status CoordinatorCore::missing_blobs(const pb::MissingBlobsRequest& req,
                                      pb::MissingBlobsResponse* out) {
  for (const std::string& d : req.sha256()) {
    if (!is_sha256_hex(d))
      return error(StatusCode::INVALID_ARGUMENT,
                   "'" + d + "' is not a SHA-256 (64 lower-case hex)");
    if (!blobs_.has(d)) out->add_sha256(d);
  }
  return Status::OK;
}

Status CoordinatorCore::submit(grpc::ServerReaderInterface<pb::SubmitRequest>* reader,
                               pb::SubmitResponse* out) {
  pb::SubmitRequest msg;
  if (!reader->Read(&msg) || !msg.has_spec())
    return error(StatusCode::INVALID_ARGUMENT, "the first message of Submit must be the job spec");
  pb::JobSpec spec = msg.spec();
  std::optional<ChunkAssembler> blob;
  uint64_t bundle_bytes = 0;
  auto finish_blob = [&]() -> Status {
    if (!blob) return Status::OK;
    Status s = chunk_status(blob->finish(), "blob", blob->error());
    if (!s.ok()) return s;
    std::string bytes = blob->take();
    bundle_bytes += bytes.size();
    if (bundle_bytes > options_.max_bundle_bytes)
      return error(
          StatusCode::RESOURCE_EXHAUSTED,
          "bundle is over the limit of " + std::to_string(options_.max_bundle_bytes) + " bytes");
    blobs_.put(bytes);
    blob.reset();
    return Status::OK;
  };
  while (reader->Read(&msg)) {
    if (!msg.has_blob_chunk())
      return error(StatusCode::INVALID_ARGUMENT, "only blob chunks may follow the job spec");
    if (msg.blob_chunk().offset() == 0) {
      if (Status s = finish_blob(); !s.ok()) return s;
      blob.emplace(options_.max_blob_bytes);
    }
    if (!blob) return error(StatusCode::INVALID_ARGUMENT, "a blob must start at offset 0");
    Status s = chunk_status(blob->add(msg.blob_chunk()), "blob", blob->error());
    if (!s.ok()) return s;
  }
  if (Status s = finish_blob(); !s.ok()) return s;

  std::string id;
  uint64_t seq;
  {
    std::lock_guard lock(mu_);
    seq = next_seq_++;
  }
  char buf[32];
  std::snprintf(buf, sizeof buf, "j%06llu", (unsigned long long)seq);
  id = buf;
  std::shared_ptr<JobRecord> job;
  try {
    job = build_job(id, seq, spec);
  } catch (const RequestError& e) {
    std::error_code ec;
    fs::remove_all(options_.state_dir + "/jobs/" + id, ec);
    return error(e.code, e.message);
  }
  job->submitted_unix = int64_t(unix_now());
  std::string spec_bytes;
  spec.SerializeToString(&spec_bytes);
  std::lock_guard lock(mu_);
  store_.insert_job({id, seq, spec_bytes, int(pb::JOB_QUEUED), "", job->submitted_unix, 0});
  std::vector<uint32_t> numbers;
  for (auto& f : job->frames) numbers.push_back(f->number);
  scheduler_.add_job(id, numbers, uint32_t(job->tiles.size()), job->passes, spec.priority());
  jobs_[id] = job;
  ++version_;
  changed_.notify_all();
  spdlog::info("job {} submitted: {} frames x {} passes x {} tiles ({})", id, numbers.size(),
               job->passes, job->tiles.size(), job->frames[0]->base.integrator);
  out->set_job_id(id);
  return Status::OK;
}

std::shared_ptr<JobRecord> CoordinatorCore::find(const std::string& id) const {
  auto it = jobs_.find(id);
  return it == jobs_.end() ? nullptr : it->second;
}

void CoordinatorCore::fill_status(const JobRecord& job, pb::JobStatus* out) const {
  out->set_job_id(job.id);
  out->set_name(job.spec.name());
  out->set_state(job.state);
  out->set_error(job.error);
  out->set_core_seconds(job.core_seconds);
  out->set_submitted_unix(job.submitted_unix);
  double t = now();
  for (const auto& f : job.frames) {
    pb::FrameStatus* s = out->add_frames();
    s->set_frame(f->number);
    s->set_passes_merged(f->passes_merged);
    s->set_passes_total(job.passes);
    s->set_spp(f->spp);
    s->set_rel_mse(f->rel_mse);
    s->set_done(f->done);
    s->set_stopped_on_target(f->stopped_on_target);
    // Passes still to merge: to the noise target if one is set (relMSE falls as 1/passes),
    // else to the last pass; time per pass from this frame's own progress so far.
    double eta = -1;
    if (f->done) {
      eta = 0;
    } else if (f->passes_merged > 0 && f->first_lease_at >= 0) {
      double per_pass = (t - f->first_lease_at) / f->passes_merged;
      double needed = job.passes;
      if (job.noise_target > 0 && f->passes_merged >= 2 && f->rel_mse > 0)
        needed = std::min(needed, std::ceil(f->passes_merged * f->rel_mse / job.noise_target));
      eta = std::max(0.0, needed - f->passes_merged) * per_pass;
    }
    s->set_eta_seconds(eta);
  }
}

void CoordinatorCore::publish_frame(JobRecord& job, FrameRecord& f) {
  if (f.acc) {
    const SampleBuffer& b = f.acc->frame();
    f.passes_merged = f.acc->passes_merged();
    double pixels = double(b.rect.area());
    f.spp = pixels > 0 ? double(b.total_samples() ? b.total_samples() : b.light_paths) / pixels : 0;
    f.rel_mse = f.passes_merged >= 2 ? b.rel_mse() : 0;
    f.done = f.acc->done();
    f.stopped_on_target = f.acc->stopped_on_target();
  }
  if (f.done) scheduler_.stop_frame(job.id, f.number, f.passes_merged);
  bool all_done = true;
  for (auto& g : job.frames) all_done &= g->done;
  if (all_done && !terminal(job.state)) set_state(job, pb::JOB_COMPLETED, "");
  ++version_;
  changed_.notify_all();
}

void CoordinatorCore::set_state(JobRecord& job, pb::JobState s, const std::string& err) {
  job.state = s;
  job.error = err;
  store_.set_state(job.id, int(s), err);
  if (terminal(s))
    spdlog::info("job {} {}{}", job.id, pb::JobState_Name(s), err.empty() ? "" : ": " + err);
  ++version_;
  changed_.notify_all();
}

Status CoordinatorCore::list(pb::ListJobsResponse* out) {
  std::lock_guard lock(mu_);
  std::vector<const JobRecord*> order;
  for (auto& [id, j] : jobs_) order.push_back(j.get());
  std::sort(order.begin(), order.end(), [](auto* a, auto* b) { return a->seq < b->seq; });
  for (const JobRecord* j : order) fill_status(*j, out->add_jobs());
  return Status::OK;
}

Status CoordinatorCore::get(const std::string& id, pb::JobStatus* out) {
  std::lock_guard lock(mu_);
  auto job = find(id);
  if (!job) return error(StatusCode::NOT_FOUND, "no job '" + id + "'");
  fill_status(*job, out);
  return Status::OK;
}

Status CoordinatorCore::watch(ServerContext* ctx, const std::string& id,
                              grpc::ServerWriterInterface<pb::JobStatus>* writer) {
  std::unique_lock lock(mu_);
  auto job = find(id);
  if (!job) return error(StatusCode::NOT_FOUND, "no job '" + id + "'");
  uint64_t seen = 0;
  while (!ctx->IsCancelled()) {
    if (seen != version_ || seen == 0) {
      seen = version_;
      pb::JobStatus s;
      fill_status(*job, &s);
      bool end = terminal(job->state);
      lock.unlock();
      if (!writer->Write(s)) return Status::OK;
      if (end) return Status::OK;
      lock.lock();
    }
    if (closing_) return error(StatusCode::UNAVAILABLE, "the coordinator is shutting down");
    changed_.wait_for(lock, std::chrono::seconds(1));
  }
  return Status::OK;
}

Status CoordinatorCore::cancel(const std::string& id) {
  std::lock_guard lock(mu_);
  auto job = find(id);
  if (!job) return error(StatusCode::NOT_FOUND, "no job '" + id + "'");
  if (terminal(job->state))
    return error(StatusCode::FAILED_PRECONDITION,
                 "job " + id + " has already ended (" + pb::JobState_Name(job->state) + ")");
  scheduler_.cancel_job(id);
  set_state(*job, pb::JOB_CANCELLED, "cancelled by a user");
  return Status::OK;
}

Status CoordinatorCore::fetch(const pb::FetchRequest& req,
                              grpc::ServerWriterInterface<pb::FetchResponse>* w) {
  std::shared_ptr<JobRecord> job;
  FrameRecord* f = nullptr;
  pb::FrameStatus status;
  {
    std::lock_guard lock(mu_);
    job = find(req.job_id());
    if (!job) return error(StatusCode::NOT_FOUND, "no job '" + req.job_id() + "'");
    auto it = job->by_number.find(req.frame());
    if (it == job->by_number.end())
      return error(StatusCode::NOT_FOUND,
                   "job " + job->id + " has no frame " + std::to_string(req.frame()));
    f = it->second;
    pb::JobStatus js;
    fill_status(*job, &js);
    for (const auto& s : js.frames())
      if (s.frame() == f->number) status = s;
  }
  std::string bytes;
  {
    std::lock_guard frame_lock(f->m);
    if (f->acc && f->acc->passes_merged() > 0) {
      bytes = encode_buffer(f->acc->frame());
    } else {
      std::string path = f->checkpoint->dir() + "/prefix.rfb";
      if (!fs::exists(path))
        return error(StatusCode::FAILED_PRECONDITION, "frame " + std::to_string(f->number) +
                                                          " of job " + job->id +
                                                          " has no complete pass yet");
      bytes = read_file_bytes(path);
    }
  }
  bool first = true;
  bool ok = true;
  for_each_chunk(bytes, [&](pb::Chunk&& c) {
    if (!ok) return;
    pb::FetchResponse r;
    *r.mutable_chunk() = std::move(c);
    if (first) *r.mutable_status() = status;
    first = false;
    ok = w->Write(r);
  });
  return Status::OK;
}

Status CoordinatorCore::register_worker(const pb::RegisterRequest& req, pb::RegisterResponse* out) {
  std::lock_guard lock(mu_);
  std::string host = req.hostname().empty() ? "worker" : req.hostname();
  std::string id = instance_ + "-w" + std::to_string(next_worker_++) + "-" + host;
  out->set_worker_id(id);
  out->set_lease_seconds(uint32_t(std::max(1.0, options_.lease_seconds)));
  out->set_keepalive_seconds(uint32_t(std::max(1.0, options_.lease_seconds / 3)));
  spdlog::info("worker {} registered: {} cores, {}, {}", id, req.cores(), req.build_id(),
               req.isa());
  return Status::OK;
}

Status CoordinatorCore::lease(const pb::LeaseRequest& req, pb::LeaseResponse* out) {
  if (req.worker_id().empty()) return error(StatusCode::INVALID_ARGUMENT, "worker_id is empty");
  std::lock_guard lock(mu_);
  if (closing_) return error(StatusCode::UNAVAILABLE, "the coordinator is shutting down");
  std::optional<Lease> l = scheduler_.lease(req.worker_id(), now());
  if (!l) {
    out->set_no_more_work(!scheduler_.work_left_for(req.worker_id()));
    return Status::OK;
  }
  auto job = find(l->task.job_id);
  FrameRecord* f = job->by_number.at(l->task.frame);
  if (f->first_lease_at < 0) f->first_lease_at = now();
  if (job->state == pb::JOB_QUEUED) set_state(*job, pb::JOB_RUNNING, "");
  pb::Task* t = out->mutable_task();
  t->set_task_id(task_id_text(l->task));
  t->set_lease_id(l->lease_id);
  t->set_job_id(job->id);
  t->set_frame(l->task.frame);
  t->set_pass(l->task.pass);
  const Rect& r = job->tiles[l->task.tile];
  t->mutable_rect()->set_x0(r.x0);
  t->mutable_rect()->set_y0(r.y0);
  t->mutable_rect()->set_w(r.w);
  t->mutable_rect()->set_h(r.h);
  t->set_scene_path(f->scene_path);
  *t->mutable_files() = job->spec.files();
  *t->mutable_overrides() = job->spec.overrides();
  t->set_scene_digest(f->base.scene_digest);
  return Status::OK;
}

Status CoordinatorCore::renew(const pb::RenewRequest& req, pb::RenewResponse* out) {
  std::lock_guard lock(mu_);
  switch (scheduler_.renew(req.lease_id(), now())) {
    case LeaseOutcome::Ok:
      out->set_lease_seconds(uint32_t(std::max(1.0, options_.lease_seconds)));
      return Status::OK;
    case LeaseOutcome::NotFound:
      return error(StatusCode::NOT_FOUND, "no lease '" + req.lease_id() + "'");
    case LeaseOutcome::Ended:
      break;
  }
  return error(StatusCode::FAILED_PRECONDITION,
               "lease " + req.lease_id() +
                   " has ended (it expired, its task was completed by another lease, or its job "
                   "stopped)");
}

Status CoordinatorCore::fetch_blob(const pb::BlobRequest& req,
                                   grpc::ServerWriterInterface<pb::Chunk>* w) {
  if (!is_sha256_hex(req.sha256()))
    return error(StatusCode::INVALID_ARGUMENT,
                 "'" + req.sha256() + "' is not a SHA-256 (64 lower-case hex digits)");
  std::optional<std::string> bytes = blobs_.get(req.sha256());
  if (!bytes) return error(StatusCode::NOT_FOUND, "no blob " + req.sha256());
  bool ok = true;
  for_each_chunk(*bytes, [&](pb::Chunk&& c) {
    if (ok) ok = w->Write(c);
  });
  return Status::OK;
}

Status CoordinatorCore::complete(grpc::ServerReaderInterface<pb::CompleteRequest>* reader,
                                 pb::CompleteResponse* out) {
  pb::CompleteRequest msg;
  if (!reader->Read(&msg) || !msg.has_header())
    return error(StatusCode::INVALID_ARGUMENT,
                 "the first message of CompleteTask must be the header");
  const pb::CompleteHeader header = msg.header();
  std::optional<TaskRef> parsed = parse_task_id(header.task_id());
  if (!parsed)
    return error(StatusCode::INVALID_ARGUMENT, "task_id '" + header.task_id() + "' is malformed");
  const TaskRef ref = *parsed;
  ChunkAssembler chunks(options_.max_buffer_bytes);
  while (reader->Read(&msg)) {
    if (!msg.has_chunk())
      return error(StatusCode::INVALID_ARGUMENT, "only chunks may follow the header");
    Status s = chunk_status(chunks.add(msg.chunk()), "sample buffer", chunks.error());
    if (!s.ok()) return s;
  }
  if (Status s = chunk_status(chunks.finish(), "sample buffer", chunks.error()); !s.ok()) return s;

  std::shared_ptr<JobRecord> job;
  FrameRecord* f = nullptr;
  {
    std::lock_guard lock(mu_);
    job = find(ref.job_id);
    if (!job) return error(StatusCode::NOT_FOUND, "no job '" + ref.job_id + "'");
    auto it = job->by_number.find(ref.frame);
    if (it == job->by_number.end() || ref.tile >= job->tiles.size() || ref.pass >= job->passes)
      return error(StatusCode::NOT_FOUND, "job " + job->id + " has no task " + header.task_id());
    f = it->second;
  }
  SampleBuffer buffer;
  try {
    buffer = decode_buffer(chunks.take(), "sample buffer of task " + header.task_id());
  } catch (const std::exception& e) {
    return error(StatusCode::INVALID_ARGUMENT, e.what());
  }
  const Rect& rect = job->tiles[ref.tile];
  if (!(buffer.rect == rect))
    return error(StatusCode::INVALID_ARGUMENT,
                 "task " + header.task_id() + ": buffer covers " + std::to_string(buffer.rect.w) +
                     "x" + std::to_string(buffer.rect.h) + " at " + std::to_string(buffer.rect.x0) +
                     "," + std::to_string(buffer.rect.y0) + ", not the task's tile");
  if (!(buffer.header.passes == PassSet::range(ref.pass, ref.pass + 1)))
    return error(StatusCode::INVALID_ARGUMENT,
                 "task " + header.task_id() + ": buffer holds passes " +
                     buffer.header.passes.to_string() + ", not pass " + std::to_string(ref.pass));
  if (std::string why = merge_incompatibility(f->base, buffer.header); !why.empty())
    return error(StatusCode::INVALID_ARGUMENT, "task " + header.task_id() + ": " + why);

  std::lock_guard frame_lock(f->m);  // one merge and checkpoint at a time per frame
  ProgressiveOptions po{0, job->passes, job->noise_target};
  if (!f->acc) {
    if (f->done) {
      out->set_accepted(false);
      return Status::OK;
    }
    f->acc = std::make_unique<FrameAccumulator>(f->base, job->tiles, job->splats, po);
  }
  if (!f->acc->task_needed(rect, ref.pass)) {  // merged already, or beyond the stop
    std::lock_guard lock(mu_);
    scheduler_.complete(header.lease_id(), ref, now());
    out->set_accepted(false);
    return Status::OK;
  }
  // Durable first: the task's result, then the database, then the answer.
  try {
    f->checkpoint->save_task(ref.pass, ref.tile, buffer);
  } catch (const std::exception& e) {
    return error(StatusCode::INTERNAL, std::string("cannot store the result: ") + e.what());
  }
  {
    std::lock_guard lock(mu_);
    if (scheduler_.complete(header.lease_id(), ref, now()) != CompleteOutcome::Accepted) {
      out->set_accepted(false);  // the job was cancelled or failed meanwhile
      return Status::OK;
    }
    std::string worker = scheduler_.lease_worker(header.lease_id());
    if (worker.empty()) worker = header.worker_id();  // a lease from before a restart
    store_.task_done(job->id, ref.frame, ref.pass, ref.tile, worker);
    job->core_seconds += buffer.header.core_seconds;
    store_.add_core_seconds(job->id, buffer.header.core_seconds);
  }
  // The merge and the prefix checkpoint hold this frame's lock only: leases, renewals and other
  // frames' merges go on meanwhile.
  bool merged = f->acc->add(std::move(buffer)) == FrameAccumulator::AddResult::Merged;
  if (merged) f->checkpoint->save_prefix(f->acc->frame());
  std::lock_guard lock(mu_);
  if (merged) f->last_merge_at = now();
  publish_frame(*job, *f);
  if (f->done) f->acc.reset();  // its image lives in the checkpoint now
  out->set_accepted(true);
  return Status::OK;
}

Status CoordinatorCore::fail(const pb::FailRequest& req) {
  std::lock_guard lock(mu_);
  std::optional<TaskRef> task = scheduler_.lease_task(req.lease_id());
  switch (scheduler_.fail(req.lease_id(), req.message(), req.handed_back(), now())) {
    case LeaseOutcome::NotFound:
      return error(StatusCode::NOT_FOUND, "no lease '" + req.lease_id() + "'");
    case LeaseOutcome::Ended:
      return error(StatusCode::FAILED_PRECONDITION, "lease " + req.lease_id() + " has ended");
    case LeaseOutcome::Ok:
      break;
  }
  if (task && !req.handed_back()) {
    // Recorded under the id the scheduler counted it under (the lease's worker).
    store_.task_failed(task->job_id, task->frame, task->pass, task->tile,
                       scheduler_.lease_worker(req.lease_id()), req.message());
    spdlog::warn("task {} failed on {}: {}", task_id_text(*task), req.worker_id(), req.message());
  }
  if (task && scheduler_.job_failed(task->job_id)) {
    auto job = find(task->job_id);
    if (job && !terminal(job->state))
      set_state(*job, pb::JOB_FAILED, scheduler_.job_error(job->id));
  }
  return Status::OK;
}

// ---------------------------------------------------------------------------------------------
// gRPC glue: the two services forward to the core.

namespace {

// A handler that throws must not take the server down: answer INTERNAL with the message.
template <class F>
Status guarded(F&& f) {
  try {
    return f();
  } catch (const std::exception& e) {
    return error(StatusCode::INTERNAL, e.what());
  }
}

class JobServiceImpl final : public pb::JobService::Service {
 public:
  explicit JobServiceImpl(CoordinatorCore& c) : c_(c) {}
  Status MissingBlobs(ServerContext*, const pb::MissingBlobsRequest* r,
                      pb::MissingBlobsResponse* o) override {
    return guarded([&] { return c_.missing_blobs(*r, o); });
  }
  Status Submit(ServerContext*, grpc::ServerReader<pb::SubmitRequest>* r,
                pb::SubmitResponse* o) override {
    return guarded([&] { return c_.submit(r, o); });
  }
  Status ListJobs(ServerContext*, const pb::ListJobsRequest*, pb::ListJobsResponse* o) override {
    return guarded([&] { return c_.list(o); });
  }
  Status GetJob(ServerContext*, const pb::JobRef* r, pb::JobStatus* o) override {
    return guarded([&] { return c_.get(r->job_id(), o); });
  }
  Status WatchJob(ServerContext* ctx, const pb::JobRef* r,
                  grpc::ServerWriter<pb::JobStatus>* w) override {
    return guarded([&] { return c_.watch(ctx, r->job_id(), w); });
  }
  Status CancelJob(ServerContext*, const pb::JobRef* r, pb::CancelResponse*) override {
    return guarded([&] { return c_.cancel(r->job_id()); });
  }
  Status FetchFrame(ServerContext*, const pb::FetchRequest* r,
                    grpc::ServerWriter<pb::FetchResponse>* w) override {
    return guarded([&] { return c_.fetch(*r, w); });
  }

 private:
  CoordinatorCore& c_;
};

class WorkerServiceImpl final : public pb::WorkerService::Service {
 public:
  explicit WorkerServiceImpl(CoordinatorCore& c) : c_(c) {}
  Status Register(ServerContext*, const pb::RegisterRequest* r, pb::RegisterResponse* o) override {
    return guarded([&] { return c_.register_worker(*r, o); });
  }
  Status LeaseTask(ServerContext*, const pb::LeaseRequest* r, pb::LeaseResponse* o) override {
    return guarded([&] { return c_.lease(*r, o); });
  }
  Status RenewLease(ServerContext*, const pb::RenewRequest* r, pb::RenewResponse* o) override {
    return guarded([&] { return c_.renew(*r, o); });
  }
  Status FetchBlob(ServerContext*, const pb::BlobRequest* r,
                   grpc::ServerWriter<pb::Chunk>* w) override {
    return guarded([&] { return c_.fetch_blob(*r, w); });
  }
  Status CompleteTask(ServerContext*, grpc::ServerReader<pb::CompleteRequest>* r,
                      pb::CompleteResponse* o) override {
    return guarded([&] { return c_.complete(r, o); });
  }
  Status FailTask(ServerContext*, const pb::FailRequest* r, pb::FailResponse*) override {
    return guarded([&] { return c_.fail(*r); });
  }

 private:
  CoordinatorCore& c_;
};

}  // namespace

struct CoordinatorServer::Impl {
  std::unique_ptr<CoordinatorCore> core;
  std::unique_ptr<JobServiceImpl> jobs;
  std::unique_ptr<WorkerServiceImpl> workers;
  std::unique_ptr<grpc::Server> server;
  int port = 0;
};

CoordinatorServer::CoordinatorServer(const CoordinatorOptions& o)
    : impl_(std::make_unique<Impl>()) {
  if (o.state_dir.empty()) throw std::runtime_error("coordinator: --state-dir is required");
  impl_->core = std::make_unique<CoordinatorCore>(o);
  impl_->jobs = std::make_unique<JobServiceImpl>(*impl_->core);
  impl_->workers = std::make_unique<WorkerServiceImpl>(*impl_->core);
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder b;
  b.AddListeningPort(o.listen, grpc::InsecureServerCredentials(), &impl_->port);
  b.RegisterService(impl_->jobs.get());
  b.RegisterService(impl_->workers.get());
  // Workers ping every keepalive_seconds (a third of the lease); allow it.
  int min_ping_ms = int(std::max(1.0, o.lease_seconds / 3) * 1000 / 2);
  b.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, min_ping_ms);
  b.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  impl_->server = b.BuildAndStart();
  if (!impl_->server || impl_->port == 0)
    throw std::runtime_error("coordinator: cannot listen on " + o.listen);
}

CoordinatorServer::~CoordinatorServer() { shutdown(); }

int CoordinatorServer::port() const { return impl_->port; }

void CoordinatorServer::wait() { impl_->server->Wait(); }

void CoordinatorServer::shutdown() {
  if (!impl_ || !impl_->server) return;
  impl_->core->shutting_down();
  impl_->server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(5));
}

int run_coordinator(const CoordinatorOptions& o) {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);  // before gRPC starts its threads
  CoordinatorServer server(o);
  spdlog::info("coordinator listening on {} (port {}), state in {}", o.listen, server.port(),
               o.state_dir);
  int sig = 0;
  sigwait(&set, &sig);
  spdlog::info("signal {}: shutting down", sig);
  server.shutdown();
  return 0;
}

}  // namespace rf
