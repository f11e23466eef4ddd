// The farm's client commands: submit, status, watch, fetch, cancel, pause, resume, priority, retry,
// delete, logs, workers, health. Each talks to one coordinator: --coordinator ADDR, else
// $RAYFARM_COORDINATOR, else 127.0.0.1:7070.
#include "client/commands.h"

#include <fcntl.h>
#include <grpcpp/grpcpp.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>
#include <set>
#include <thread>

#include "engine/buffer_file.h"
#include "engine/digest.h"
#include "engine/image_io.h"
#include "engine/progress.h"
#include "farm/auth.h"  // format_utc_time
#include "farm/blob_store.h"
#include "farm/channel.h"
#include "farm/chunking.h"
#include "farm/convert.h"
#include "farm/frame_range.h"
#include "farm/job.h"
#include "farm/probe.h"
#include "proto/rayfarm.grpc.pb.h"

namespace rf {

namespace fs = std::filesystem;
namespace pb = rayfarm::v1;

std::string default_coordinator() {
  const char* env = std::getenv("RAYFARM_COORDINATOR");
  return env && *env ? env : "127.0.0.1:7070";
}

namespace {

std::unique_ptr<pb::JobService::Stub> job_stub(const Endpoint& ep) {
  return pb::JobService::NewStub(coordinator_channel(ep.address, ep.creds));
}

using Clock = std::chrono::steady_clock;

// The command's deadline, and the retries of its calls within it.
class Retry {
 public:
  explicit Retry(const Endpoint& ep)
      : end_(Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                std::chrono::duration<double>(ep.timeout))),
        address_(ep.address),
        rng_(std::random_device{}()) {}

  double left() const { return std::chrono::duration<double>(end_ - Clock::now()).count(); }

  // call(ctx) with a deadline of per_call seconds (less if the command's ends sooner), again
  // while it answers UNAVAILABLE and time is left. The last status.
  template <class Call>
  grpc::Status run(double per_call, Call&& call) {
    for (int attempt = 0;; ++attempt) {
      grpc::ClientContext ctx;
      set_deadline(ctx, std::max(0.001, std::min(per_call, left())));
      grpc::Status s = call(ctx);
      if (!retry_after(s, attempt)) return s;
    }
  }

  // After a call that answered s: sleeps and returns true if it should be made again.
  bool retry_after(const grpc::Status& s, int attempt) {
    if (s.error_code() != grpc::StatusCode::UNAVAILABLE) return false;
    double wait = backoff_seconds(attempt, 0.1, 5, rng_);
    if (left() <= wait) return false;
    // Said once, with gRPC's reason: a coordinator that is down and one this client cannot
    // speak to (TLS on one side only, a wrong CA) both answer UNAVAILABLE.
    if (retries_ == 0)
      std::cerr << "rayfarm: coordinator " << address_ << " unavailable (" << s.error_message()
                << "); retrying for up to " << std::lround(left()) << " s (--timeout)\n";
    ++retries_;
    std::this_thread::sleep_for(std::chrono::duration<double>(wait));
    return true;
  }
  int retries() const { return retries_; }

 private:
  Clock::time_point end_;
  std::string address_;
  std::mt19937 rng_;
  int retries_ = 0;
};

// 128 random bits in hex: one submit command's idempotency key.
std::string new_request_id() {
  std::random_device rd;
  std::string out;
  char buf[9];
  for (int i = 0; i < 4; ++i) {
    std::snprintf(buf, sizeof buf, "%08x", unsigned(rd()));
    out += buf;
  }
  return out;
}

const char* code_name(grpc::StatusCode c) {
  switch (c) {
    case grpc::StatusCode::CANCELLED:
      return "CANCELLED";
    case grpc::StatusCode::INVALID_ARGUMENT:
      return "INVALID_ARGUMENT";
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::NOT_FOUND:
      return "NOT_FOUND";
    case grpc::StatusCode::UNAUTHENTICATED:
      return "UNAUTHENTICATED";
    case grpc::StatusCode::PERMISSION_DENIED:
      return "PERMISSION_DENIED";
    case grpc::StatusCode::FAILED_PRECONDITION:
      return "FAILED_PRECONDITION";
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::DATA_LOSS:
      return "DATA_LOSS";
    case grpc::StatusCode::UNAVAILABLE:
      return "UNAVAILABLE";
    case grpc::StatusCode::INTERNAL:
      return "INTERNAL";
    default:
      return "ERROR";
  }
}

void check(const grpc::Status& s, const std::string& what, const Endpoint& ep,
           const Retry* retry = nullptr) {
  if (s.ok()) return;
  std::string msg = what + ": " + code_name(s.error_code()) + ": " + s.error_message();
  if (s.error_code() == grpc::StatusCode::UNAVAILABLE)
    msg += unavailable_hint(s, ep.address, !ep.creds.tls_ca.empty());
  if (retry && retry->retries() > 0)
    msg += " (after " + std::to_string(retry->retries()) + " retries; --timeout)";
  throw FarmError(msg, s.error_code() == grpc::StatusCode::INVALID_ARGUMENT ||
                               s.error_code() == grpc::StatusCode::NOT_FOUND
                           ? 2
                           : 1);
}

const char* state_name(pb::JobState s) {
  switch (s) {
    case pb::JOB_QUEUED:
      return "queued";
    case pb::JOB_RUNNING:
      return "running";
    case pb::JOB_COMPLETED:
      return "completed";
    case pb::JOB_FAILED:
      return "failed";
    case pb::JOB_CANCELLED:
      return "cancelled";
    default:
      return "unknown";
  }
}

}  // namespace

namespace {

// A scene's bundle for `frames` (a range; empty: the scene's frame): every distinct scene file
// the frames name, and every asset they use, by path relative to the scene's directory. Parsing
// here also refuses a bad scene before upload.
struct SceneBundle {
  std::string pattern;  // the scene file's name in the bundle
  std::vector<BundleEntry> files;
};
SceneBundle scene_bundle(const fs::path& scene, const std::string& frame_range) {
  fs::path dir = scene.parent_path();
  std::string pattern = scene.filename().string();
  std::vector<FrameNumber> frames;
  if (!frame_range.empty()) {
    try {
      frames = parse_frame_range(frame_range);
    } catch (const FrameRangeError& e) {
      throw FarmError(std::string("--frames: ") + e.what(), 2);
    }
  }
  std::set<std::string> scene_files;
  if (pattern.find('#') == std::string::npos || frames.empty())
    scene_files.insert(pattern);
  else
    for (FrameNumber f : frames) scene_files.insert(expand_frame_pattern(pattern, f));
  std::map<std::string, std::string> files;  // path -> digest, in path order
  for (const std::string& name : scene_files) {
    if (!fs::exists(dir / name)) throw FarmError((dir / name).string() + ": no such scene file", 2);
    for (const BundleEntry& e : bundle_of_scene((dir / name).string())) files[e.path] = e.sha256;
  }
  SceneBundle out{pattern, {}};
  for (const auto& [path, digest] : files) out.files.push_back({path, digest});
  return out;
}

// The job a submit describes.
JobSpec job_spec(const SubmitArgs& a) {
  fs::path scene(a.scene);
  fs::path dir = scene.parent_path();
  SceneBundle bundle = scene_bundle(scene, a.frames);
  JobSpec spec;
  // Default name: the scene's stem, or its directory's name for the usual "scene.json".
  std::string stem = scene.stem().string();
  if (stem == "scene" && !dir.filename().empty()) stem = dir.filename().string();
  spec.name = a.name.empty() ? stem : a.name;
  spec.scene_path = bundle.pattern;
  spec.files = std::move(bundle.files);
  spec.frames = a.frames;
  spec.overrides = a.overrides;
  spec.priority = a.priority;
  spec.tile_size = uint32_t(a.tile_size);
  spec.build_id = a.build_id;
  spec.required_tags = a.required_tags;
  return spec;
}

// Writes `first` (Submit's spec, RequeueJob's request), then the bundle's files the coordinator
// lacks (each once) as blob chunks, and finishes the stream.
template <class Message, class Writer>
grpc::Status stream_bundle(Writer& w, const Message& first, const std::vector<BundleEntry>& files,
                           const fs::path& dir, std::set<std::string> missing) {
  bool ok = w.Write(first);
  for (const BundleEntry& f : files) {
    if (!ok || !missing.count(f.sha256)) continue;
    missing.erase(f.sha256);
    std::string bytes = read_file_bytes((dir / f.path).string());
    for_each_chunk(bytes, [&](pb::Chunk&& c) {
      if (!ok) return;
      Message m;
      *m.mutable_blob_chunk() = std::move(c);
      ok = w.Write(m);
    });
  }
  if (ok) w.WritesDone();
  return w.Finish();
}

// Streams the spec, then the bundle's files the coordinator lacks (each once), in chunks.
grpc::Status upload_job(pb::JobService::Stub& stub, const JobSpec& spec, const fs::path& dir,
                        std::set<std::string> missing, double seconds, std::string* job_id) {
  grpc::ClientContext ctx;
  set_deadline(ctx, std::max(0.001, std::min(3600.0, seconds)));
  pb::SubmitResponse resp;
  auto w = stub.Submit(&ctx, &resp);
  pb::SubmitRequest first;
  *first.mutable_spec() = to_wire(spec);
  grpc::Status s = stream_bundle(*w, first, spec.files, dir, std::move(missing));
  *job_id = resp.job_id();
  return s;
}

}  // namespace

// Retried as a whole (blob query and upload) while the coordinator is unavailable; the request
// id makes a retry whose first attempt did reach the coordinator get that attempt's job.
int cmd_bundle(const std::string& scene, const std::string& frames, bool json) {
  SceneBundle b = scene_bundle(fs::path(scene), frames);
  const fs::path dir = fs::absolute(fs::path(scene)).parent_path();
  nlohmann::json files = nlohmann::json::array();
  for (const BundleEntry& f : b.files) {
    std::error_code ec;
    const uint64_t bytes = fs::file_size(dir / f.path, ec);
    if (json)
      files.push_back({{"path", f.path}, {"sha256", f.sha256}, {"bytes", ec ? 0 : bytes}});
    else
      std::printf("%s %12llu %s\n", f.sha256.c_str(), (unsigned long long)bytes, f.path.c_str());
  }
  if (json)
    std::printf("%s\n",
                nlohmann::json({{"scene", b.pattern}, {"dir", dir.string()}, {"files", files}})
                    .dump(2)
                    .c_str());
  return 0;
}

int cmd_submit(const Endpoint& ep, const SubmitArgs& a, bool json,
               std::optional<WatchOutput> wait) {
  const std::string& addr = ep.address;
  JobSpec spec = job_spec(a);
  spec.request_id = new_request_id();
  pb::MissingBlobsRequest missing_req;
  for (const BundleEntry& f : spec.files) missing_req.add_sha256(f.sha256);
  auto stub = job_stub(ep);
  Retry retry(ep);
  for (int attempt = 0;; ++attempt) {
    pb::MissingBlobsResponse missing;
    check(retry.run(30,
                    [&](grpc::ClientContext& ctx) {
                      return stub->MissingBlobs(&ctx, missing_req, &missing);
                    }),
          "submit", ep, &retry);
    std::string id;
    grpc::Status s =
        upload_job(*stub, spec, fs::path(a.scene).parent_path(),
                   {missing.sha256().begin(), missing.sha256().end()}, retry.left(), &id);
    if (s.ok()) {
      if (json)
        std::printf("%s\n", nlohmann::json({{"job_id", id}}).dump().c_str());
      else
        std::printf("%s\n", id.c_str());
      std::fflush(stdout);
      return wait ? cmd_watch(ep, id, *wait) : 0;
    }
    if (!retry.retry_after(s, attempt)) check(s, "submit", ep, &retry);
  }
}

namespace {

// A job's settings as submitted: only those given (the rest are the scene file's).
nlohmann::json settings_json(const pb::RenderOverrides& o) {
  nlohmann::json out = nlohmann::json::object();
  if (o.has_spp()) out["spp"] = o.spp();
  if (o.has_passes()) out["passes"] = o.passes();
  if (o.has_integrator()) out["integrator"] = o.integrator();
  if (o.has_seed()) out["seed"] = o.seed();
  if (o.has_width()) out["width"] = o.width();
  if (o.has_height()) out["height"] = o.height();
  if (o.has_max_depth()) out["max_depth"] = o.max_depth();
  if (o.has_filter()) out["filter"] = o.filter();
  if (o.has_noise_target()) out["noise_target"] = o.noise_target();
  if (o.has_sampler()) out["sampler"] = o.sampler();
  if (o.has_aovs()) out["aovs"] = o.aovs();
  if (o.has_light_selection()) out["light_selection"] = o.light_selection();
  if (o.has_shutter()) out["shutter"] = o.shutter();
  return out;
}

nlohmann::json to_json(const pb::JobStatus& j) {
  nlohmann::json frames = nlohmann::json::array();
  for (const pb::FrameStatus& f : j.frames())
    frames.push_back({{"frame", f.frame()},
                      {"passes_merged", f.passes_merged()},
                      {"passes_total", f.passes_total()},
                      {"spp", f.spp()},
                      {"rel_mse", f.rel_mse()},
                      {"eta_seconds", f.eta_seconds()},
                      {"done", f.done()},
                      {"stopped_on_target", f.stopped_on_target()},
                      {"scene_version", f.scene_version()},
                      {"run", f.run()}});
  return {{"job_id", j.job_id()},
          {"name", j.name()},
          {"tenant", j.tenant()},
          {"state", state_name(j.state())},
          {"error", j.error()},
          {"core_seconds", j.core_seconds()},
          {"submitted_unix", j.submitted_unix()},
          {"paused", j.paused()},
          {"priority", j.priority()},
          {"held_frames", j.held_frames()},
          {"build_id", j.build_id()},
          {"cpu_kind", j.cpu_kind()},
          {"waiting_for", j.waiting_for()},
          {"settings", settings_json(j.settings())},
          {"scene_path", j.scene_path()},
          {"tile_size", j.tile_size()},
          {"required_tags", j.required_tags()},
          {"ended_unix", j.ended_unix() ? nlohmann::json(j.ended_unix()) : nullptr},
          {"frames", frames}};
}

// Core-seconds as shown: two significant digits below 10 (a small job is not "0"), whole
// seconds above.
std::string core_seconds_text(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, v < 10 ? "%.2g" : "%.0f", v);
  return buf;
}

std::string job_line(const pb::JobStatus& j) {
  int done = 0;
  uint64_t merged = 0, total = 0;
  double worst = 0, eta = 0;
  bool eta_known = true;
  for (const pb::FrameStatus& f : j.frames()) {
    done += f.done();
    merged += f.passes_merged();
    total += f.passes_total();
    worst = std::max(worst, f.rel_mse());
    if (!f.done()) {
      if (f.eta_seconds() < 0) eta_known = false;
      eta += f.eta_seconds();
    }
  }
  // A paused job shows as such (its state is still queued or running underneath).
  const std::string state = j.paused() ? std::string(state_name(j.state())) + ",paused"
                                       : std::string(state_name(j.state()));
  char buf[512];
  std::snprintf(buf, sizeof buf,
                "%-10s %-20s %-10s frames %d/%d  passes %llu/%llu  relMSE<=%.3g  %s core-s  "
                "priority %d  ETA %s",
                printable(j.job_id()).c_str(), printable(j.name()).c_str(), state.c_str(), done,
                j.frames_size(), (unsigned long long)merged, (unsigned long long)total, worst,
                core_seconds_text(j.core_seconds()).c_str(), j.priority(),
                j.paused()                                                      ? "paused"
                : j.state() == pb::JOB_COMPLETED                                ? "0s"
                : j.state() == pb::JOB_FAILED || j.state() == pb::JOB_CANCELLED ? "-"
                : eta_known ? duration_text(eta).c_str()
                            : "?");
  std::string line = buf;
  if (!j.held_frames().empty()) line += "  held " + printable(j.held_frames());
  if (!j.waiting_for().empty()) line += "  WAITING: " + printable(j.waiting_for());
  return line;
}

}  // namespace

int cmd_status(const Endpoint& ep, const std::string& job, bool json, const StatusPage& page) {
  const std::string& addr = ep.address;
  auto stub = job_stub(ep);
  Retry retry(ep);
  std::vector<pb::JobStatus> jobs;
  if (job.empty()) {  // page by page, up to page.limit jobs (all when 0)
    std::string after = page.after, next;
    do {
      pb::ListJobsRequest req;
      req.set_after(after);
      if (page.limit) req.set_limit(uint32_t(std::min<uint64_t>(page.limit - jobs.size(), 1000)));
      pb::ListJobsResponse resp;
      check(
          retry.run(30, [&](grpc::ClientContext& ctx) { return stub->ListJobs(&ctx, req, &resp); }),
          "status", ep, &retry);
      jobs.insert(jobs.end(), resp.jobs().begin(), resp.jobs().end());
      next = after = resp.next_after();
    } while (!after.empty() && (page.limit == 0 || jobs.size() < page.limit));
    if (!next.empty()) std::fprintf(stderr, "more jobs follow: status --after %s\n", next.c_str());
  } else {
    pb::JobRef ref;
    ref.set_job_id(job);
    pb::JobStatus s;
    check(retry.run(30, [&](grpc::ClientContext& ctx) { return stub->GetJob(&ctx, ref, &s); }),
          "status", ep, &retry);
    jobs.push_back(s);
  }
  if (json) {
    nlohmann::json out = nlohmann::json::array();
    for (const auto& j : jobs) out.push_back(to_json(j));
    std::printf("%s\n", (job.empty() ? out : out[0]).dump(2).c_str());
    return 0;
  }
  for (const auto& j : jobs) {
    std::printf("%s\n", job_line(j).c_str());
    if (!j.error().empty()) std::printf("  error: %s\n", j.error().c_str());
  }
  return 0;
}

namespace {

// A frame's relMSE as shown: it cannot be estimated from fewer than two passes.
bool rel_mse_known(const pb::FrameStatus& f) { return f.passes_merged() >= 2; }
std::string rel_mse_text(uint32_t passes, double v) {
  if (passes < 2) return "n/a";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4g", v);
  return buf;
}

// What `watch` prints of each update, in its three forms (WatchOutput).
class WatchPrinter {
 public:
  WatchPrinter(const std::string& job, const WatchOutput& o) : job_(job), o_(o) {}

  void update(const pb::JobStatus& s) {
    uint64_t merged = 0, total = 0;
    for (const pb::FrameStatus& f : s.frames()) {
      merged += f.done() ? f.passes_total() : f.passes_merged();
      total += f.passes_total();
      // Lines only when something other than the ETA changed.
      char key[160];
      std::snprintf(key, sizeof key, "%u/%u %.17g %.17g %d%d", f.passes_merged(), f.passes_total(),
                    f.spp(), f.rel_mse(), f.done(), f.stopped_on_target());
      if (last_[f.frame()] == key) continue;
      last_[f.frame()] = key;
      if (o_.json) {
        nlohmann::json line = {{"event", "frame"},
                               {"job_id", job_},
                               {"frame", f.frame()},
                               {"passes_merged", f.passes_merged()},
                               {"passes_total", f.passes_total()},
                               {"spp", f.spp()},
                               {"rel_mse", nullptr},
                               {"eta_seconds", nullptr},
                               {"done", f.done()},
                               {"stopped_on_target", f.stopped_on_target()}};
        if (rel_mse_known(f)) line["rel_mse"] = f.rel_mse();
        if (f.eta_seconds() >= 0) line["eta_seconds"] = f.eta_seconds();
        std::printf("%s\n", line.dump().c_str());
      } else if (o_.openjd) {
        if (f.done())
          std::printf("openjd_status: frame %d done (%.0f spp%s)\n", f.frame(), f.spp(),
                      f.stopped_on_target() ? ", noise target" : "");
      } else {
        std::printf("frame %d: passes %u/%u, %.0f spp, relMSE %s, %s\n", f.frame(),
                    f.passes_merged(), f.passes_total(), f.spp(),
                    rel_mse_text(f.passes_merged(), f.rel_mse()).c_str(),
                    f.done()              ? (f.stopped_on_target() ? "done (noise target)" : "done")
                    : f.eta_seconds() < 0 ? "ETA -"
                                          : ("ETA " + duration_text(f.eta_seconds())).c_str());
      }
    }
    if (o_.openjd && total > 0) {
      double percent = std::floor(1000.0 * double(merged) / double(total)) / 10;
      if (percent != last_percent_) std::printf("openjd_progress: %.1f\n", percent);
      last_percent_ = percent;
    }
    std::fflush(stdout);
  }

  // The job's end; its exit status (0 completed, 1 failed, 3 cancelled).
  int end(pb::JobState state, const std::string& error, double core_seconds) {
    const int status = state == pb::JOB_COMPLETED ? 0 : state == pb::JOB_FAILED ? 1 : 3;
    if (o_.json) {
      std::printf("%s\n", nlohmann::json({{"event", "end"},
                                          {"job_id", job_},
                                          {"state", state_name(state)},
                                          {"error", error},
                                          {"core_seconds", core_seconds}})
                              .dump()
                              .c_str());
    } else {
      std::string text = state == pb::JOB_COMPLETED
                             ? "completed (" + core_seconds_text(core_seconds) + " core-s)"
                             : std::string(state_name(state)) + (error.empty() ? "" : ": ") + error;
      std::printf("%sjob %s %s\n", o_.openjd ? "openjd_status: " : "", job_.c_str(), text.c_str());
    }
    std::fflush(stdout);
    return status;
  }

 private:
  std::string job_;
  WatchOutput o_;
  std::map<FrameNumber, std::string> last_;
  double last_percent_ = -1;
};

}  // namespace

int cmd_watch(const Endpoint& ep, const std::string& job, const WatchOutput& output) {
  const std::string& addr = ep.address;
  std::shared_ptr<grpc::Channel> channel = coordinator_channel(ep.address, ep.creds);
  auto stub = pb::JobService::NewStub(channel);
  WatchPrinter printer(job, output);
  std::mt19937 rng(std::random_device{}());
  Clock::time_point lost = Clock::now();  // since when no update came (the start counts)
  auto left = [&] {
    return ep.timeout - std::chrono::duration<double>(Clock::now() - lost).count();
  };
  for (int attempt = 0;; ++attempt) {
    // The stream has no deadline (a watch lasts as long as its job); the connection must come
    // within what is left of --timeout, or a silent address would hold it for TCP's own timeout.
    if (!channel->WaitForConnected(
            std::chrono::system_clock::now() +
            std::chrono::milliseconds(int64_t(std::max(0.0, left()) * 1000))))
      throw FarmError("watch: no answer from the coordinator at " + addr + " for " +
                          std::to_string(int(ep.timeout - left())) + " s (--timeout)",
                      1);
    grpc::ClientContext ctx;
    pb::JobRef ref;
    ref.set_job_id(job);
    auto reader = stub->WatchJob(&ctx, ref);
    pb::JobStatus s;
    pb::JobState state = pb::JOB_STATE_UNSPECIFIED;
    std::string error;
    bool heard = false;
    double core_seconds = 0;
    while (reader->Read(&s)) {
      attempt = 0;
      heard = true;
      state = s.state();
      error = s.error();
      core_seconds = s.core_seconds();
      printer.update(s);
    }
    grpc::Status st = reader->Finish();
    if (state == pb::JOB_COMPLETED || state == pb::JOB_FAILED || state == pb::JOB_CANCELLED)
      return printer.end(state, error, core_seconds);
    // The stream broke (a coordinator stopped or restarting, a partition): reconnect unless the
    // job is gone, for as long as --timeout from the last time the coordinator answered.
    if (heard) lost = Clock::now();
    if (!st.ok() && st.error_code() != grpc::StatusCode::UNAVAILABLE &&
        st.error_code() != grpc::StatusCode::DEADLINE_EXCEEDED &&
        st.error_code() != grpc::StatusCode::CANCELLED)
      check(st, "watch", ep);
    double gone = std::chrono::duration<double>(Clock::now() - lost).count();
    if (gone >= ep.timeout)
      throw FarmError("watch: no answer from the coordinator at " + addr + " for " +
                          std::to_string(int(gone)) + " s (--timeout): " + st.error_message(),
                      1);
    if (attempt == 0)
      std::fprintf(stderr, "watch: connection lost (%s); reconnecting\n",
                   st.error_message().c_str());
    std::this_thread::sleep_for(std::chrono::duration<double>(
        std::min(backoff_seconds(attempt, 0.25, 10, rng), std::max(0.0, left()))));
  }
}

int cmd_fetch(const Endpoint& ep, const std::string& job, const std::string& out,
              const std::string& frames, const FetchOutput& o) {
  const std::string& addr = ep.address;
  std::set<FrameNumber> wanted;
  if (!frames.empty()) {
    try {
      for (FrameNumber f : parse_frame_range(frames)) wanted.insert(f);
    } catch (const FrameRangeError& e) {
      throw FarmError(std::string("fetch --frames: ") + e.what(), 2);
    }
  }
  // An output template names each frame's EXR; anything else is a directory.
  const bool to_template = fs::path(out).extension() == ".exr";
  if (to_template && wanted.size() != 1 && !is_frame_pattern(out, true))
    throw FarmError("fetch -o " + out +
                        ": several frames need a frame template in the name (shot.####.exr or "
                        "shot.%04d.exr), or a directory",
                    2);
  auto stub = job_stub(ep);
  Retry retry(ep);
  pb::JobStatus status;
  {
    pb::JobRef ref;
    ref.set_job_id(job);
    check(retry.run(30, [&](grpc::ClientContext& ctx) { return stub->GetJob(&ctx, ref, &status); }),
          "fetch", ep, &retry);
  }
  int written = 0;
  for (const pb::FrameStatus& f : status.frames()) {
    if (!wanted.empty() && !wanted.count(f.frame())) continue;
    if (f.passes_merged() == 0) {
      std::fprintf(stderr, "frame %d: no complete pass yet; skipped\n", f.frame());
      continue;
    }
    pb::FetchRequest req;
    req.set_job_id(job);
    req.set_frame(f.frame());
    char name[64];
    std::snprintf(name, sizeof name, "%s.%04d", job.c_str(), f.frame());
    const std::string exr = to_template ? expand_frame_pattern(out, f.frame(), true)
                                        : (fs::path(out) / (std::string(name) + ".exr")).string();
    const std::string png = fs::path(exr).replace_extension(".png").string();
    if (fs::path parent = fs::path(exr).parent_path(); !parent.empty())
      fs::create_directories(parent);
    // The frame's .rfb goes to a hidden file beside the EXR as it arrives, then is read a band of
    // rows at a time: a frame larger than memory is never whole here either.
    const fs::path target(exr);
    const std::string tmp = (target.parent_path() / ("." + target.filename().string() +
                                                     ".rfb.tmp-" + std::to_string(::getpid())))
                                .string();
    struct Removed {
      std::string path;
      int fd = -1;
      ~Removed() {
        if (fd >= 0) ::close(fd);
        ::unlink(path.c_str());
      }
    } spool{tmp};
    auto sink = [&](std::string_view data, uint64_t offset) {
      if (!pwrite_full(spool.fd, data.data(), data.size(), offset))
        throw FarmError(tmp + ": cannot write: " + std::strerror(errno), 1);
    };
    // Digest::Optional: a frame kept in tiles comes without a SHA-256 (its .rfb checks itself).
    ChunkAssembler chunks(uint64_t(1) << 40, ChunkAssembler::Digest::Optional, sink);
    std::string problem;
    grpc::Status fs = retry.run(600, [&](grpc::ClientContext& ctx) {
      if (spool.fd >= 0) ::close(spool.fd);
      spool.fd = ::open(tmp.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
      if (spool.fd < 0) throw FarmError(tmp + ": cannot create: " + std::strerror(errno), 1);
      chunks = ChunkAssembler(uint64_t(1) << 40, ChunkAssembler::Digest::Optional, sink);
      problem.clear();
      auto reader = stub->FetchFrame(&ctx, req);
      pb::FetchResponse r;
      while (reader->Read(&r))
        if (problem.empty() && chunks.add(r.chunk()) != ChunkAssembler::Status::Ok)
          problem = chunks.error();
      return reader->Finish();
    });
    check(fs, "fetch frame " + std::to_string(f.frame()), ep, &retry);
    if (problem.empty() && chunks.finish() != ChunkAssembler::Status::Ok) problem = chunks.error();
    if (!problem.empty())
      throw FarmError("fetch frame " + std::to_string(f.frame()) + ": " + problem, 1);
    BufferFileBands frame(tmp, uint64_t(64) << 20);
    write_exr(exr, frame, {{"job", job}}, o.half ? ExrFormat::Half : ExrFormat::Float);
    if (o.png) write_png(png, frame, o.exposure);
    const uint32_t passes = frame.info().header.passes.count();
    if (o.json) {
      nlohmann::json line = {{"job_id", job},      {"frame", f.frame()},
                             {"exr", exr},         {"png", o.png ? nlohmann::json(png) : nullptr},
                             {"passes", passes},   {"spp", samples_per_pixel(frame)},
                             {"rel_mse", nullptr}, {"done", f.done()}};
      if (passes >= 2 && std::isfinite(frame.rel_mse())) line["rel_mse"] = frame.rel_mse();
      std::printf("%s\n", line.dump().c_str());
      std::fflush(stdout);
    } else {
      std::fprintf(stderr, "frame %d: %u passes, %.0f spp, relMSE %s -> %s\n", f.frame(), passes,
                   samples_per_pixel(frame), rel_mse_text(passes, frame.rel_mse()).c_str(),
                   exr.c_str());
    }
    ++written;
  }
  if (!wanted.empty() && written == 0)
    throw FarmError("job " + job + " has no fetchable frame in " + frames, 2);
  if (written == 0)  // nothing to write is not a success: say why, and exit 1
    throw FarmError("fetch: job " + job + " has no frame with a complete pass to write" +
                        (status.error().empty() ? std::string()
                                                : " (" + std::string(state_name(status.state())) +
                                                      ": " + status.error() + ")"),
                    1);
  return 0;
}

int cmd_cancel(const Endpoint& ep, const std::string& job) {
  const std::string& addr = ep.address;
  auto stub = job_stub(ep);
  Retry retry(ep);
  pb::JobRef ref;
  ref.set_job_id(job);
  pb::CancelResponse resp;
  grpc::Status s =
      retry.run(30, [&](grpc::ClientContext& ctx) { return stub->CancelJob(&ctx, ref, &resp); });
  // Cancelling a cancelled job succeeds (the coordinator's cancel is idempotent), so a retried
  // cancel whose first attempt got through succeeds too.
  check(s, "cancel", ep, &retry);
  std::fprintf(stderr, "job %s cancelled\n", job.c_str());
  return 0;
}

int cmd_pause(const Endpoint& ep, const std::string& job, bool pause) {
  auto stub = job_stub(ep);
  Retry retry(ep);
  pb::JobRef ref;
  ref.set_job_id(job);
  pb::JobStatus status;
  // Both are idempotent, so a retry whose first attempt got through succeeds too.
  const char* what = pause ? "pause" : "resume";
  check(retry.run(30,
                  [&](grpc::ClientContext& ctx) {
                    return pause ? stub->PauseJob(&ctx, ref, &status)
                                 : stub->ResumeJob(&ctx, ref, &status);
                  }),
        what, ep, &retry);
  std::fprintf(stderr, "job %s %s\n", job.c_str(), pause ? "paused" : "resumed");
  return 0;
}

int cmd_priority(const Endpoint& ep, const std::string& job, int priority) {
  auto stub = job_stub(ep);
  Retry retry(ep);
  pb::SetPriorityRequest req;
  req.set_job_id(job);
  req.set_priority(priority);
  pb::JobStatus status;
  check(retry.run(
            30, [&](grpc::ClientContext& ctx) { return stub->SetJobPriority(&ctx, req, &status); }),
        "priority", ep, &retry);
  std::fprintf(stderr, "job %s priority %d\n", job.c_str(), status.priority());
  return 0;
}

int cmd_retry(const Endpoint& ep, const std::string& job, const std::string& frames) {
  auto stub = job_stub(ep);
  Retry retry(ep);
  pb::RetryRequest req;
  req.set_job_id(job);
  req.set_frames(frames);
  pb::JobStatus status;
  // Idempotent for frames that run already: a retry whose first attempt got through succeeds.
  check(retry.run(30, [&](grpc::ClientContext& ctx) { return stub->RetryJob(&ctx, req, &status); }),
        "retry", ep, &retry);
  std::fprintf(stderr, "job %s %s%s\n", job.c_str(), state_name(status.state()),
               status.held_frames().empty()
                   ? ""
                   : ("; frames " + printable(status.held_frames()) + " held").c_str());
  return 0;
}

// Retried as a whole while the coordinator is unavailable, as submit is; the request id makes a
// retry whose first attempt got through change nothing.
int cmd_requeue(const Endpoint& ep, const std::string& job, const std::string& frames,
                const std::string& scene) {
  if (frames.empty())
    throw FarmError("requeue: --frames is required (a range such as 3 or 1-10)", 2);
  pb::RequeueRequest req;
  req.set_job_id(job);
  req.set_frames(frames);
  req.set_request_id(new_request_id());
  std::vector<BundleEntry> files;
  if (!scene.empty()) {
    SceneBundle bundle = scene_bundle(scene, frames);
    req.set_scene_path(bundle.pattern);
    for (const BundleEntry& f : bundle.files) {
      pb::BundleFile* w = req.add_files();
      w->set_path(f.path);
      w->set_sha256(f.sha256);
    }
    files = std::move(bundle.files);
  }
  pb::MissingBlobsRequest missing_req;
  for (const BundleEntry& f : files) missing_req.add_sha256(f.sha256);
  auto stub = job_stub(ep);
  Retry retry(ep);
  for (int attempt = 0;; ++attempt) {
    std::set<std::string> missing;
    if (!files.empty()) {
      pb::MissingBlobsResponse m;
      check(retry.run(30,
                      [&](grpc::ClientContext& ctx) {
                        return stub->MissingBlobs(&ctx, missing_req, &m);
                      }),
            "requeue", ep, &retry);
      missing.insert(m.sha256().begin(), m.sha256().end());
    }
    grpc::ClientContext ctx;
    set_deadline(ctx, std::max(0.001, std::min(3600.0, retry.left())));
    pb::JobStatus status;
    auto w = stub->RequeueJob(&ctx, &status);
    pb::RequeueMessage first;
    *first.mutable_request() = req;
    grpc::Status s =
        stream_bundle(*w, first, files, fs::path(scene).parent_path(), std::move(missing));
    if (s.ok()) {
      uint32_t version = 0;  // the newest, which this requeue added
      for (const pb::FrameStatus& f : status.frames())
        version = std::max(version, f.scene_version());
      std::fprintf(stderr, "job %s %s; frames %s render again%s%s\n", job.c_str(),
                   state_name(status.state()), frames.c_str(),
                   scene.empty() ? "" : (" from scene version " + std::to_string(version)).c_str(),
                   status.held_frames().empty()
                       ? ""
                       : ("; frames " + printable(status.held_frames()) + " held").c_str());
      return 0;
    }
    if (!retry.retry_after(s, attempt)) check(s, "requeue", ep, &retry);
  }
}

int cmd_delete(const Endpoint& ep, const std::string& job, bool force) {
  auto stub = job_stub(ep);
  Retry retry(ep);
  pb::DeleteRequest req;
  req.set_job_id(job);
  req.set_force(force);
  pb::DeleteResponse resp;
  grpc::Status s =
      retry.run(30, [&](grpc::ClientContext& ctx) { return stub->DeleteJob(&ctx, req, &resp); });
  // A retried delete whose first attempt got through finds no job: that is what was asked.
  if (retry.retries() > 0 && s.error_code() == grpc::StatusCode::NOT_FOUND) s = grpc::Status::OK;
  check(s, "delete", ep, &retry);
  std::fprintf(stderr, "job %s deleted\n", job.c_str());
  return 0;
}

int cmd_logs(const Endpoint& ep, const std::string& job, std::optional<FrameNumber> frame,
             const std::string& task, uint32_t limit, bool json) {
  auto stub = job_stub(ep);
  Retry retry(ep);
  pb::TaskLogRequest req;
  req.set_job_id(job);
  if (frame) req.set_frame(*frame);
  req.set_task_id(task);
  req.set_limit(limit);
  pb::TaskLogResponse resp;
  check(retry.run(30, [&](grpc::ClientContext& ctx) { return stub->GetTaskLog(&ctx, req, &resp); }),
        "logs", ep, &retry);
  if (json) {
    nlohmann::json all = nlohmann::json::array();
    for (const pb::TaskAttempt& a : resp.attempts())
      all.push_back({{"task_id", a.task_id()},
                     {"worker_id", a.worker_id()},
                     {"lease_id", a.lease_id()},
                     {"started_unix", a.started_unix()},
                     {"ended_unix", a.ended_unix()},
                     {"outcome", a.outcome()},
                     {"message", a.message()},
                     {"log", std::vector<std::string>(a.log().begin(), a.log().end())}});
    std::printf("%s\n", nlohmann::json{{"attempts", all}, {"more", resp.more()}}.dump(2).c_str());
    return 0;
  }
  if (resp.more()) std::printf("(earlier attempts left out: --limit)\n");
  for (const pb::TaskAttempt& a : resp.attempts()) {
    // UTC, as the coordinator's and workers' machines may not share a time zone.
    std::string when = a.started_unix() > 0 ? format_utc_time(int64_t(a.started_unix())) : "?";
    if (a.ended_unix() > 0) {
      when += " -> " + format_utc_time(int64_t(a.ended_unix())).substr(11);
      if (a.started_unix() > 0)
        when += " (" + duration_text(a.ended_unix() - a.started_unix()) + ")";
    }
    std::printf("%-24s %-28s %s  %s%s\n", printable(a.task_id()).c_str(),
                printable(a.worker_id()).c_str(), when.c_str(), printable(a.outcome()).c_str(),
                a.message().empty() ? "" : (": " + printable(a.message())).c_str());
    for (const std::string& l : a.log()) std::printf("    | %s\n", printable(l).c_str());
  }
  if (resp.attempts().empty()) std::fprintf(stderr, "no attempts yet\n");
  return 0;
}

int cmd_workers(const Endpoint& ep, bool json) {
  auto stub = job_stub(ep);
  Retry retry(ep);
  pb::ListWorkersResponse resp;
  check(retry.run(30,
                  [&](grpc::ClientContext& ctx) {
                    return stub->ListWorkers(&ctx, pb::ListWorkersRequest{}, &resp);
                  }),
        "workers", ep, &retry);
  nlohmann::json all = nlohmann::json::array();
  for (const pb::WorkerStatus& w : resp.workers()) {
    if (json) {
      all.push_back({{"worker_id", w.worker_id()},
                     {"hostname", w.hostname()},
                     {"cores", w.cores()},
                     {"build_id", w.build_id()},
                     {"isa", w.isa()},
                     {"tags", std::vector<std::string>(w.tags().begin(), w.tags().end())},
                     {"tasks", std::vector<std::string>(w.tasks().begin(), w.tasks().end())},
                     {"failures", w.failures()},
                     {"seconds_since_contact", w.seconds_since_contact()},
                     {"refused", w.refused()},
                     {"principal", w.principal()}});
      continue;
    }
    std::string tasks;
    for (const std::string& t : w.tasks()) tasks += (tasks.empty() ? "" : ",") + printable(t);
    const std::string contact = w.seconds_since_contact() < 0
                                    ? std::string("never")
                                    : duration_text(w.seconds_since_contact()) + " ago";
    std::string tags;  // the ones set by hand: isa, cores and memory are every worker's
    for (const std::string& t : w.tags())
      if (t.rfind("isa=", 0) && t.rfind("cores=", 0) && t.rfind("memory_gb=", 0))
        tags += " " + printable(t);
    std::printf("%-32s %3u cores %-8s failures %u  last contact %s  %s%s%s\n",
                printable(w.worker_id()).c_str(), w.cores(), printable(w.isa()).c_str(),
                w.failures(), contact.c_str(), tasks.empty() ? "idle" : tasks.c_str(),
                tags.empty() ? "" : ("  tags:" + tags).c_str(),
                w.refused().empty() ? "" : ("  REFUSED: " + printable(w.refused())).c_str());
  }
  if (json) std::printf("%s\n", all.dump(2).c_str());
  return 0;
}

int cmd_health(const Endpoint& ep, bool services, bool json) {
  const std::string& addr = ep.address;
  try {
    auto creds = channel_credentials(ep.creds);
    std::string s = check_health(addr, "", 5, creds);
    std::vector<std::string> names;
    if (services) names = list_services(addr, 5, creds);
    if (json) {
      nlohmann::json out = {{"address", addr}, {"status", s}};
      if (services) out["services"] = names;
      std::printf("%s\n", out.dump().c_str());
    } else {
      std::printf("%s: %s\n", addr.c_str(), s.c_str());
      for (const std::string& name : names) std::printf("  %s\n", name.c_str());
    }
    return s == "SERVING" ? 0 : 1;
  } catch (const ProbeError& e) {
    if (json)
      std::printf("%s\n", nlohmann::json(
                              {{"address", addr}, {"status", "UNREACHABLE"}, {"error", e.what()}})
                              .dump()
                              .c_str());
    else
      std::printf("%s: unreachable: %s\n", addr.c_str(), e.what());
    return 1;
  }
}

}  // namespace rf
