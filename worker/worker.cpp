#include "worker/worker.h"

#include <fcntl.h>
#include <grpcpp/grpcpp.h>
#include <signal.h>
#include <spdlog/details/os.h>
#include <spdlog/sinks/base_sink.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <deque>
#include <filesystem>
#include <mutex>
#include <random>
#include <set>
#include <thread>

#include "engine/buffer_file.h"
#include "engine/build_info.h"
#include "engine/digest.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "farm/blob_store.h"
#include "farm/channel.h"
#include "farm/chunking.h"
#include "farm/convert.h"
#include "farm/tags.h"
#include "farm/upload.h"
#include "proto/rayfarm.grpc.pb.h"

namespace rf {

namespace fs = std::filesystem;
namespace pb = rayfarm::v1;
using Clock = std::chrono::steady_clock;

namespace {

std::string default_cache_dir() {
  if (const char* x = std::getenv("XDG_CACHE_HOME"); x && *x) return std::string(x) + "/rayfarm";
  if (const char* h = std::getenv("HOME"); h && *h) return std::string(h) + "/.cache/rayfarm";
  return "/tmp/rayfarm-cache-" + std::to_string(::getuid());
}

double cpu_seconds() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

// Every RPC waits for the channel to (re)connect within its deadline instead of failing at once
// while the coordinator restarts.
constexpr bool kWaitForReady = true;

struct TaskFailure : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// The coordinator refuses this worker's credentials: retrying cannot help.
bool refused(const grpc::Status& s) {
  return s.error_code() == grpc::StatusCode::UNAUTHENTICATED ||
         s.error_code() == grpc::StatusCode::PERMISSION_DENIED;
}

// The coordinator went away or could not take the call now (stopped: CANCELLED; restarting or
// unreachable: UNAVAILABLE; slow: DEADLINE_EXCEEDED; busy: RESOURCE_EXHAUSTED, ABORTED): the
// same call is worth making again later.
bool coordinator_away(const grpc::Status& s) {
  switch (s.error_code()) {
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::DEADLINE_EXCEEDED:
    case grpc::StatusCode::CANCELLED:
    case grpc::StatusCode::ABORTED:
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
    case grpc::StatusCode::UNKNOWN:
      return true;
    default:
      return false;
  }
}

// The log lines of the task being rendered (`rayfarm logs`): a sink on the default logger that
// keeps what is logged, from any thread, between begin() and take(), bounded as bounded_log
// bounds them (the first lines and the last, with a line counting those left out between).
class AttemptLogSink final : public spdlog::sinks::base_sink<std::mutex> {
 public:
  // Lines of the calling thread are left out from now on: the previous task's upload thread.
  void skip_this_thread() { skipped_thread_ = spdlog::details::os::thread_id(); }
  void begin() {
    std::lock_guard lock(mutex_);
    head_.clear(), tail_.clear(), skipped_ = 0, on_ = true;
  }
  std::vector<std::string> take() {
    std::lock_guard lock(mutex_);
    on_ = false;
    std::vector<std::string> out = std::move(head_);
    if (skipped_ > 0) out.push_back("... " + std::to_string(skipped_) + " lines left out ...");
    out.insert(out.end(), tail_.begin(), tail_.end());
    head_.clear(), tail_.clear();
    return bounded_log(out);
  }

 protected:
  void sink_it_(const spdlog::details::log_msg& msg) override {
    if (!on_ || msg.thread_id == skipped_thread_) return;
    std::string line(spdlog::level::to_string_view(msg.level).data(),
                     spdlog::level::to_string_view(msg.level).size());
    line += ": ";
    line.append(msg.payload.data(), std::min(msg.payload.size(), kAttemptLogLineBytes));
    if (head_.size() < kHead) return head_.push_back(std::move(line));
    tail_.push_back(std::move(line));
    if (tail_.size() > kAttemptLogLines - kHead - 1) tail_.pop_front(), ++skipped_;
  }
  void flush_() override {}

 private:
  static constexpr size_t kHead = 8;
  bool on_ = false;
  std::atomic<size_t> skipped_thread_{0};
  std::vector<std::string> head_;
  std::deque<std::string> tail_;
  size_t skipped_ = 0;
};

}  // namespace

class Worker {
 public:
  explicit Worker(const WorkerOptions& o)
      : o_(o),
        cache_dir_(o.cache_dir.empty() ? default_cache_dir() : o.cache_dir),
        blobs_(cache_dir_ + "/blobs"),
        rng_(std::random_device{}()),
        attempt_log_(std::make_shared<AttemptLogSink>()) {
    // Before any other thread logs; it stays for the process's life (threads that outlive the
    // worker may still log).
    spdlog::default_logger()->sinks().push_back(attempt_log_);
  }

  int run();

 private:
  int serve();  // run() after the signal thread started
  void connect(int keepalive_seconds);
  bool register_self();
  // Renders, then starts the upload; on a drain timeout hands the task back and exits.
  void run_task(const pb::Task& task);
  Renderer& prepare(const pb::Task& task);
  void fetch_blob(const std::string& sha256);
  void upload(const pb::Task& task, const SampleBuffer& buffer, double core_seconds,
              const std::vector<std::string>& log);
  // Reports the task failed (or handed back) with the attempt's log lines so far.
  void fail_task(const pb::Task& task, const std::string& message, bool handed_back,
                 const std::vector<std::string>& log);
  // Sleeps with exponential, jittered backoff (capped); false if a stop was requested.
  bool backoff(int attempt);
  bool sleep_unless_stopped(double seconds);
  // Rewrites --heartbeat-file (at most once a second; from any thread).
  void beat();
  std::atomic<int64_t> last_beat_ns_{0};
  std::atomic<bool> beat_warned_{false};
  bool stopping() const { return stop_.load(); }
  // The coordinator answered: the --give-up-after clock starts again.
  void heard_from_coordinator() { last_contact_ns_ = Clock::now().time_since_epoch().count(); }
  double seconds_without_coordinator() const {
    return std::chrono::duration<double>(Clock::now().time_since_epoch() -
                                         Clock::duration(last_contact_ns_.load()))
        .count();
  }
  // Throws once give_up_after seconds have passed without an answer from the coordinator.
  void check_give_up(const grpc::Status& last);
  // A call's deadline of `seconds`, cut to what is left of give_up_after (so the worker gives up
  // on time, not at the end of a call that waits for the coordinator).
  double within_give_up(double seconds) const;
  // With --give-up-after: a thread that counts the time the channel is not connected (calls
  // waiting for the coordinator to come back count as without it) and exits the process 1 once
  // it reaches give_up_after. The task in flight is lost to this worker only: its lease expires
  // and the coordinator, once back, hands it to another.
  void start_give_up_watch();
  // This process's bundle layouts (hard links into the blob cache); the blobs stay cached.
  void remove_bundle_dirs() {
    std::error_code ec;
    std::string suffix = "-" + std::to_string(::getpid());
    for (const auto& e : fs::directory_iterator(cache_dir_ + "/bundles", ec)) {
      std::string name = e.path().filename().string();
      if (name.size() > suffix.size() &&
          name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0)
        fs::remove_all(e.path(), ec);
    }
  }

  WorkerOptions o_;
  std::string cache_dir_;
  BlobStore blobs_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::WorkerService::Stub> stub_;
  std::string worker_id_;
  double lease_seconds_ = 30, keepalive_seconds_ = 10;
  std::mt19937 rng_;
  std::shared_ptr<AttemptLogSink> attempt_log_;  // on the default logger while this lives

  std::atomic<bool> stop_{false};
  std::atomic<int64_t> last_contact_ns_{Clock::now().time_since_epoch().count()};
  Clock::time_point stop_at_;
  std::mutex m_;
  std::condition_variable cv_;
  std::thread signal_thread_;

  struct CachedScene {
    std::string key;
    std::string dir;  // its bundle's layout (hard links into the blob cache)
    std::unique_ptr<Scene> scene;
    std::unique_ptr<Renderer> renderer;
  };
  std::deque<CachedScene> scenes_;  // most recently used first
  std::set<std::string> verified_;  // blob digests checked against their content
  // Keeps the blob cache within WorkerOptions::cache_bytes: the least recently used blobs go
  // first, never those of `keep` (the bundle being set up).
  void bound_cache(const std::vector<BundleEntry>& keep);
  // Uploads run while the next tasks render, hiding the round trip and the coordinator's
  // durable write. One upload call is in flight at a time; the results finished meanwhile wait
  // (at most max_results_ of them, or one larger than max_upload_bytes_) and go in the next call
  // together (a batched upload: one flush on the coordinator for all of them).
  struct PendingResult {
    pb::Task task;
    std::string bytes;  // the encoded sample buffer
    double core_seconds = 0;
    std::vector<std::string> log;
  };
  std::thread uploader_;
  std::mutex upload_mu_;
  std::condition_variable upload_cv_;
  std::deque<PendingResult> pending_;  // under upload_mu_
  uint64_t pending_bytes_ = 0;         // under upload_mu_
  bool uploading_ = false;             // under upload_mu_: uploader_ runs
  size_t max_results_ = 1;             // per upload (the coordinator's bound; 1 before batches)
  uint64_t max_upload_bytes_ = 0;
  void start_upload(const pb::Task& task, SampleBuffer&& buffer, double core_seconds,
                    std::vector<std::string> log);
  void upload_loop();
  void upload(std::vector<PendingResult> batch);
  // Waits until every result handed to start_upload has been answered.
  void finish_upload() {
    {
      std::unique_lock lock(upload_mu_);
      upload_cv_.wait(lock, [&] { return !uploading_; });
    }
    if (uploader_.joinable()) uploader_.join();
  }
  // Batched leases: tasks leased together wait here for their turn (main thread only).
  std::deque<pb::Task> queued_;
  static constexpr uint32_t kLeaseBatch = 64;  // tasks asked for per lease
  // Hands the queued tasks back (shutting down, or at --max-tasks): re-queued, not failures.
  void hand_back_queued(const std::string& why);
  void renew(const pb::Task& task, bool& renewing);
  static constexpr size_t kScenesKept = 2;
};

// Pings at most a third of the lease apart (the coordinator's keepalive_seconds), so a partition
// is noticed within one lease.
void Worker::connect(int keepalive_seconds) {
  channel_ = coordinator_channel(o_.coordinator, o_.creds, keepalive_seconds);
  stub_ = pb::WorkerService::NewStub(channel_);
}

double Worker::within_give_up(double seconds) const {
  if (o_.give_up_after <= 0) return seconds;
  return std::clamp(o_.give_up_after - seconds_without_coordinator(), 0.1, seconds);
}

void Worker::check_give_up(const grpc::Status& last) {
  if (o_.give_up_after <= 0) return;
  double silent = seconds_without_coordinator();
  if (silent < o_.give_up_after) return;
  throw std::runtime_error("no answer from the coordinator at " + o_.coordinator + " for " +
                           std::to_string(int(silent)) +
                           " s (--give-up-after); last: " + last.error_message() +
                           (last.error_code() == grpc::StatusCode::UNAVAILABLE
                                ? unavailable_hint(last, o_.coordinator, !o_.creds.tls_ca.empty())
                                : std::string()));
}

void Worker::start_give_up_watch() {
  std::shared_ptr<grpc::Channel> channel = channel_;
  std::thread([this, channel] {
    for (;;) {
      std::this_thread::sleep_for(std::chrono::milliseconds(250));
      if (channel->GetState(false) == GRPC_CHANNEL_READY) {
        heard_from_coordinator();
        continue;
      }
      double silent = seconds_without_coordinator();
      if (silent < o_.give_up_after) continue;
      spdlog::error("no coordinator at {} for {:.0f} s (--give-up-after); exiting", o_.coordinator,
                    silent);
      remove_bundle_dirs();
      spdlog::shutdown();
      std::_Exit(1);
    }
  }).detach();
}

bool Worker::backoff(int attempt) {
  return sleep_unless_stopped(backoff_seconds(attempt, 0.25, 15, rng_));
}

void Worker::beat() {
  if (o_.heartbeat_file.empty()) return;
  int64_t now = Clock::now().time_since_epoch().count(), last = last_beat_ns_.load();
  if (now - last < std::chrono::nanoseconds(std::chrono::seconds(1)).count() ||
      !last_beat_ns_.compare_exchange_strong(last, now))
    return;
  std::string text = std::to_string(std::time(nullptr)) + "\n";
  int fd = ::open(o_.heartbeat_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  bool ok = fd >= 0 && ::write(fd, text.data(), text.size()) == ssize_t(text.size());
  if (fd >= 0) ::close(fd);
  if (!ok && !beat_warned_.exchange(true))
    spdlog::warn("--heartbeat-file {}: cannot write it ({}); health checks reading it will fail",
                 o_.heartbeat_file, std::strerror(errno));
}

bool Worker::sleep_unless_stopped(double seconds) {
  beat();
  std::unique_lock lock(m_);
  cv_.wait_for(lock, std::chrono::milliseconds(int64_t(seconds * 1000)),
               [&] { return stopping(); });
  return !stopping();
}

bool Worker::register_self() {
  pb::RegisterRequest req;
  char host[256] = {};
  ::gethostname(host, sizeof host - 1);
  req.set_hostname(host);
  // The threads it renders with: `--threads` (tbb's global limit), else every core.
  size_t threads = std::min<size_t>(
      std::max(1u, std::thread::hardware_concurrency()),
      tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
  req.set_cores(uint32_t(std::max<size_t>(1, threads)));
  req.set_build_id(build_id());
  req.set_isa(cpu_isa());
  for (const std::string& t : automatic_tags()) req.add_tags(t);
  for (const std::string& t : o_.tags) req.add_tags(t);
  pb::RegisterResponse resp;
  auto registered = [&] {
    heard_from_coordinator();
    worker_id_ = resp.worker_id();
    lease_seconds_ = std::max(1u, resp.lease_seconds());
    keepalive_seconds_ = std::max(1u, resp.keepalive_seconds());
    max_results_ = std::max<size_t>(1, resp.max_results_per_upload());
    max_upload_bytes_ = resp.max_upload_bytes();
    return true;
  };
  for (int attempt = 0;; ++attempt) {
    grpc::ClientContext ctx;
    set_deadline(ctx, within_give_up(10), kWaitForReady);
    grpc::Status s = stub_->Register(&ctx, req, &resp);
    if (s.ok()) return registered();
    if (refused(s) || !coordinator_away(s))
      throw std::runtime_error("register with " + o_.coordinator + ": " + s.error_message());
    if (attempt == 0 && s.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) {
      // A call that waits for the connection says only "Deadline Exceeded"; one that does not
      // fails at once with gRPC's reason (a refused connection, a failed TLS handshake).
      grpc::ClientContext probe;
      set_deadline(probe, within_give_up(2));
      grpc::Status why = stub_->Register(&probe, req, &resp);
      if (why.ok()) return registered();
      if (why.error_code() == grpc::StatusCode::UNAVAILABLE) s = why;
    }
    check_give_up(s);
    if (attempt == 0)
      spdlog::warn("coordinator {} unreachable ({}){}; retrying", o_.coordinator, s.error_message(),
                   s.error_code() == grpc::StatusCode::UNAVAILABLE
                       ? unavailable_hint(s, o_.coordinator, !o_.creds.tls_ca.empty())
                       : std::string());
    if (!backoff(attempt)) return false;
  }
}

void Worker::fetch_blob(const std::string& sha256) {
  grpc::ClientContext ctx;
  set_deadline(ctx, 600, kWaitForReady);
  pb::BlobRequest req;
  req.set_sha256(sha256);
  auto reader = stub_->FetchBlob(&ctx, req);
  ChunkAssembler chunks(uint64_t(64) << 30);
  pb::Chunk c;
  std::string problem;
  while (reader->Read(&c))
    if (problem.empty() && chunks.add(c) != ChunkAssembler::Status::Ok) problem = chunks.error();
  grpc::Status s = reader->Finish();
  if (!s.ok()) throw TaskFailure("fetching blob " + sha256 + ": " + s.error_message());
  if (problem.empty() && chunks.finish() != ChunkAssembler::Status::Ok) problem = chunks.error();
  if (!problem.empty()) throw TaskFailure("fetching blob " + sha256 + ": " + problem);
  blobs_.put(chunks.take(), sha256);
}

void Worker::bound_cache(const std::vector<BundleEntry>& keep) {
  if (o_.cache_bytes == 0) return;
  std::vector<BlobStore::Entry> all = blobs_.list();
  uint64_t total = 0;
  for (const BlobStore::Entry& e : all) total += e.bytes;
  if (total <= o_.cache_bytes) return;
  std::set<std::string> kept;
  for (const BundleEntry& e : keep) kept.insert(e.sha256);
  std::sort(all.begin(), all.end(),
            [](const auto& a, const auto& b) { return a.used_unix < b.used_unix; });
  uint64_t removed = 0, bytes = 0;
  for (const BlobStore::Entry& e : all) {
    if (total <= o_.cache_bytes) break;
    if (kept.count(e.sha256) || !blobs_.remove(e.sha256)) continue;
    total -= e.bytes;
    bytes += e.bytes;
    ++removed;
    verified_.erase(e.sha256);
  }
  spdlog::info(
      "blob cache: removed {} blobs ({} bytes), least recently used first, to hold at "
      "most {} bytes (--cache-bytes); {} bytes cached",
      removed, bytes, o_.cache_bytes, total);
}

Renderer& Worker::prepare(const pb::Task& task) {
  std::string files;
  std::vector<BundleEntry> bundle;
  for (const pb::BundleFile& f : task.files()) {
    files += f.path() + "\t" + f.sha256() + "\n";
    bundle.push_back({f.path(), f.sha256()});
  }
  // Not keyed by frame: a frame selects the seed stream and, for a moving camera, where the camera
  // stands (evaluated per ray from the task's frame), so a sequence of one scene file renders on
  // one BVH; where geometry moves, the renderer adds the frame's BVH over the moving instances
  // (Renderer::kKeepFrames of them kept) to the rest, built once.
  std::string key =
      sha256_hex(task.scene_path() + "\n" + files + task.overrides().SerializeAsString());
  for (auto it = scenes_.begin(); it != scenes_.end(); ++it)
    if (it->key == key) {
      if (it != scenes_.begin()) {
        CachedScene c = std::move(*it);
        scenes_.erase(it);
        scenes_.push_front(std::move(c));
      }
      return *scenes_.front().renderer;
    }
  // One directory per bundle and process: workers sharing a cache never write the same files.
  std::string dir =
      cache_dir_ + "/bundles/" + sha256_hex(files).substr(0, 16) + "-" + std::to_string(::getpid());
  // Twice at most: another worker sharing the cache may evict a blob between its fetch and the
  // layout (BlobError names it); it is fetched again.
  for (int attempt = 0;; ++attempt) {
    for (const BundleEntry& e : bundle) {
      // A cached blob is checked once per process: a corrupted cache is fetched again, not
      // rendered.
      if (blobs_.has(e.sha256) && !verified_.count(e.sha256)) {
        std::optional<std::string> bytes = blobs_.get(e.sha256);
        if (!bytes || sha256_hex(*bytes) != e.sha256) {
          spdlog::warn("cached blob {} is corrupted; fetching it again", e.sha256);
          fs::remove(blobs_.path_of(e.sha256));
        }
      }
      if (!blobs_.has(e.sha256)) fetch_blob(e.sha256);
      blobs_.touch(e.sha256);  // used now: the last to be evicted
      verified_.insert(e.sha256);
    }
    try {
      blobs_.materialize(bundle, dir);
      break;
    } catch (const BlobError& e) {
      if (attempt > 0) throw TaskFailure(e.what());
      for (const BundleEntry& b : bundle) verified_.erase(b.sha256);
    } catch (const std::exception& e) {
      throw TaskFailure(e.what());
    }
  }
  bound_cache(bundle);
  SceneOverrides ov = to_scene_overrides(task.overrides());
  CachedScene c;
  c.key = key;
  try {
    c.scene = std::make_unique<Scene>(load_scene(dir + "/" + task.scene_path(), ov));
  } catch (const std::exception& e) {
    throw TaskFailure(e.what());
  }
  if (c.scene->digest != task.scene_digest())
    throw TaskFailure("scene digest " + c.scene->digest + " differs from the coordinator's " +
                      task.scene_digest() + " (another build or a corrupted cache?)");
  auto t0 = Clock::now();
  c.renderer = std::make_unique<Renderer>(*c.scene);
  // A scene whose geometry moves builds its BVH per frame, at the frame's first task (Renderer).
  spdlog::info("scene {} ({}): {} in {:.2f} s", task.scene_path(), c.scene->digest.substr(0, 12),
               geometry_moves(*c.scene) ? "renderer set up (a BVH per frame)" : "BVH built",
               std::chrono::duration<double>(Clock::now() - t0).count());
  c.dir = dir;
  scenes_.push_front(std::move(c));
  while (scenes_.size() > kScenesKept) {
    // Its layout goes with it (the hard links would keep evicted blobs on disk), unless a scene
    // kept shares it (the same bundle with other settings).
    const std::string old = scenes_.back().dir;
    scenes_.pop_back();
    bool shared = false;
    for (const CachedScene& s : scenes_) shared |= s.dir == old;
    std::error_code ec;
    if (!shared) fs::remove_all(old, ec);
  }
  return *scenes_.front().renderer;
}

void Worker::fail_task(const pb::Task& task, const std::string& message, bool handed_back,
                       const std::vector<std::string>& log) {
  pb::FailRequest req;
  for (const std::string& l : log) req.add_log(l);
  req.set_worker_id(worker_id_);
  req.set_lease_id(task.lease_id());
  req.set_task_id(task.task_id());
  req.set_message(message);
  req.set_handed_back(handed_back);
  grpc::ClientContext ctx;
  set_deadline(ctx, within_give_up(10), kWaitForReady);
  pb::FailResponse resp;
  grpc::Status s = stub_->FailTask(&ctx, req, &resp);
  if (!s.ok())
    spdlog::warn("task {}: reporting {}: {}", task.task_id(),
                 handed_back ? "the hand-back" : "the failure", s.error_message());
}

// Sends the results in one call, each answered on its own. A coordinator that went away gets
// them when it is back (a late result still counts while no one else's was merged), until
// --give-up-after; a result refused for itself is reported as the task's failure.
void Worker::upload(std::vector<PendingResult> batch) {
  auto failed = [&](const PendingResult& r, const std::string& why) {
    spdlog::error("task {}: {}", r.task.task_id(), why);
    if (!stopping()) fail_task(r.task, why, false, r.log);
  };
  for (int attempt = 0; !batch.empty(); ++attempt) {
    std::vector<UploadItem> items;
    for (const PendingResult& r : batch) items.push_back({&r.task, r.bytes, r.core_seconds, r.log});
    BatchAnswer answer = upload_results(*stub_, worker_id_, items, 600, kWaitForReady);
    std::vector<PendingResult> again;
    grpc::Status away;
    for (size_t i = 0; i < batch.size(); ++i) {
      const grpc::Status& s = answer.status.ok() ? answer.results[i].status : answer.status;
      if (s.ok()) {
        heard_from_coordinator();
        spdlog::info(
            "task {}: {}", batch[i].task.task_id(),
            answer.results[i].accepted ? "merged" : "not needed (another result was merged first)");
      } else if (!coordinator_away(s)) {
        failed(batch[i], "upload: " + s.error_message());
      } else {
        away = s;
        again.push_back(std::move(batch[i]));
      }
    }
    batch = std::move(again);
    if (batch.empty()) return;
    try {
      check_give_up(away);
    } catch (const std::runtime_error& e) {
      for (const PendingResult& r : batch) failed(r, e.what());
      return;
    }
    if (attempt == 0)
      spdlog::warn("task {}{}: upload failed ({}); retrying", batch[0].task.task_id(),
                   batch.size() > 1 ? " and " + std::to_string(batch.size() - 1) + " more" : "",
                   away.error_message());
    if (!backoff(attempt)) {
      for (const PendingResult& r : batch) failed(r, "upload interrupted by shutdown");
      return;
    }
  }
}

void Worker::run_task(const pb::Task& task) {
  auto t0 = Clock::now();
  double cpu0 = cpu_seconds();
  attempt_log_->begin();
  const Renderer* renderer = nullptr;
  try {
    renderer = &prepare(task);
  } catch (const TaskFailure& e) {
    spdlog::error("task {}: {}", task.task_id(), e.what());
    fail_task(task, e.what(), false, attempt_log_->take());
    return;
  }
  Rect rect = from_wire(task.rect());
  SampleBuffer result;
  std::string render_error;
  bool finished = false;
  std::thread render([&] {
    try {
      result = renderer->render(TaskKey{task.frame(), rect, task.pass()}, true);
    } catch (const std::exception& e) {
      render_error = e.what();
    }
    std::lock_guard lock(m_);
    finished = true;
    cv_.notify_all();
  });
  // Renew while rendering; a lease that ended still gets its result uploaded (results are
  // deterministic and the first complete one is merged, whichever lease it came from).
  bool renewing = true;
  auto next_renew = Clock::now() + std::chrono::duration<double>(keepalive_seconds_);
  std::unique_lock lock(m_);
  while (!finished) {
    auto wake = next_renew;
    if (stopping())
      wake = std::min(wake, stop_at_ + std::chrono::duration<double>(o_.drain_seconds));
    bool was_stopping = stopping();  // a signal moves the wake-up to the drain deadline
    cv_.wait_until(lock, wake, [&] { return finished || stopping() != was_stopping; });
    if (finished) break;
    beat();
    if (stopping() && Clock::now() >= stop_at_ + std::chrono::duration<double>(o_.drain_seconds)) {
      lock.unlock();
      spdlog::info("task {}: not finished within the drain time; handing it back", task.task_id());
      finish_upload();  // the previous tasks' results still count
      fail_task(task, "worker shutting down", true, attempt_log_->take());
      hand_back_queued("shutting down");
      // Exit with the render still running (it cannot be interrupted, and its stack frame must
      // outlive it); the coordinator re-queues the task without counting a failure.
      spdlog::shutdown();
      std::_Exit(0);
    }
    if (Clock::now() >= next_renew) {
      lock.unlock();
      if (renewing) renew(task, renewing);
      // The tasks leased with it wait their turn under leases of their own.
      for (auto it = queued_.begin(); it != queued_.end();) {
        bool held = true;
        renew(*it, held);
        it = held ? it + 1 : queued_.erase(it);  // ended: re-queued by the coordinator
      }
      lock.lock();
    }
    // Also once the lease ended: the next wake-up is a keepalive away, not a spin.
    if (Clock::now() >= next_renew)
      next_renew = Clock::now() + std::chrono::duration<double>(keepalive_seconds_);
  }
  lock.unlock();
  render.join();
  if (!render_error.empty()) {
    spdlog::error("task {}: {}", task.task_id(), render_error);
    fail_task(task, render_error, false, attempt_log_->take());
    return;
  }
  double core_seconds = cpu_seconds() - cpu0;
  result.header.core_seconds = core_seconds;
  spdlog::info("task {}: rendered in {:.2f} s ({:.1f} core-s)", task.task_id(),
               std::chrono::duration<double>(Clock::now() - t0).count(), core_seconds);
  start_upload(task, std::move(result), core_seconds, attempt_log_->take());
}

void Worker::start_upload(const pb::Task& task, SampleBuffer&& buffer, double core_seconds,
                          std::vector<std::string> log) {
  std::string bytes = encode_buffer(buffer);
  buffer = SampleBuffer();
  std::unique_lock lock(upload_mu_);
  // No more waiting than one call's worth: the render goes on once the uploader takes them.
  upload_cv_.wait(lock, [&] {
    return pending_.empty() ||
           (pending_.size() < max_results_ && pending_bytes_ + bytes.size() <= max_upload_bytes_);
  });
  pending_bytes_ += bytes.size();
  pending_.push_back({task, std::move(bytes), core_seconds, std::move(log)});
  if (uploading_) return;  // the running uploader takes it next
  lock.unlock();
  if (uploader_.joinable()) uploader_.join();  // finished: it cleared uploading_ on its way out
  lock.lock();
  uploading_ = true;
  uploader_ = std::thread([this] { upload_loop(); });
}

void Worker::upload_loop() {
  attempt_log_->skip_this_thread();  // its lines are the tasks' already taken
  std::unique_lock lock(upload_mu_);
  while (!pending_.empty()) {
    std::vector<PendingResult> batch;
    uint64_t bytes = 0;
    while (!pending_.empty() && batch.size() < max_results_ &&
           (batch.empty() || bytes + pending_.front().bytes.size() <= max_upload_bytes_)) {
      bytes += pending_.front().bytes.size();
      batch.push_back(std::move(pending_.front()));
      pending_.pop_front();
    }
    pending_bytes_ -= bytes;
    upload_cv_.notify_all();
    lock.unlock();
    upload(std::move(batch));
    lock.lock();
  }
  uploading_ = false;
  upload_cv_.notify_all();
}

void Worker::hand_back_queued(const std::string& why) {
  while (!queued_.empty()) {
    spdlog::info("task {}: {}; handing it back", queued_.front().task_id(), why);
    fail_task(queued_.front(), "worker " + why, true, {});
    queued_.pop_front();
  }
}

void Worker::renew(const pb::Task& task, bool& renewing) {
  pb::RenewRequest req;
  req.set_worker_id(worker_id_);
  req.set_lease_id(task.lease_id());
  grpc::ClientContext ctx;
  set_deadline(ctx, within_give_up(10), kWaitForReady);
  pb::RenewResponse resp;
  grpc::Status s = stub_->RenewLease(&ctx, req, &resp);
  if (s.error_code() == grpc::StatusCode::FAILED_PRECONDITION ||
      s.error_code() == grpc::StatusCode::NOT_FOUND) {
    spdlog::info("task {}: lease ended ({}); finishing anyway", task.task_id(), s.error_message());
    renewing = false;
  }
}

int Worker::run() {
  // Signals go to one thread: it asks the loop to stop leasing and start the drain clock.
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);
  signal_thread_ = std::thread([this, set] {
    int sig = 0;
    sigwait(&set, &sig);
    spdlog::info("signal {}: no more leases; draining for up to {:.0f} s", sig, o_.drain_seconds);
    std::lock_guard lock(m_);
    stop_at_ = Clock::now();
    stop_ = true;
    cv_.notify_all();
  });
  signal_thread_.detach();

  try {
    return serve();
  } catch (...) {  // refused, or gave up: the upload in flight ends first (it gives up too)
    finish_upload();
    remove_bundle_dirs();
    throw;
  }
}

int Worker::serve() {
  connect(10);
  if (!register_self()) return 0;
  connect(int(keepalive_seconds_));
  if (o_.give_up_after > 0) start_give_up_watch();
  spdlog::info("worker {} connected to {} (lease {:.0f} s), cache {}", worker_id_, o_.coordinator,
               lease_seconds_, cache_dir_);
  int tasks = 0, attempt = 0;
  while (!stopping()) {
    beat();
    if (!queued_.empty()) {  // leased with an earlier task
      pb::Task task = std::move(queued_.front());
      queued_.pop_front();
      run_task(task);
      if (o_.max_tasks > 0 && ++tasks >= o_.max_tasks) break;
      continue;
    }
    pb::LeaseRequest req;
    req.set_worker_id(worker_id_);
    req.set_max_tasks(o_.max_tasks > 0 ? std::min<uint32_t>(kLeaseBatch, o_.max_tasks - tasks)
                                       : kLeaseBatch);
    grpc::ClientContext ctx;
    set_deadline(ctx, within_give_up(5), kWaitForReady);
    pb::LeaseResponse resp;
    grpc::Status s = stub_->LeaseTask(&ctx, req, &resp);
    if (s.error_code() == grpc::StatusCode::NOT_FOUND) {
      // The coordinator does not know this worker id (its state directory was replaced).
      spdlog::warn("lease: {}; registering again", s.error_message());
      if (!register_self()) break;
      continue;
    }
    if (!s.ok()) {
      // Refused: exit with the reason. Anything else: the coordinator went away (a stop, a
      // restart, a partition) or failed this call; wait for it, as long as --give-up-after.
      if (refused(s)) throw std::runtime_error("lease: " + s.error_message());
      check_give_up(s);
      if (attempt == 0)
        spdlog::warn("lease: {} (code {}); waiting for the coordinator", s.error_message(),
                     int(s.error_code()));
      backoff(attempt++);
      continue;
    }
    heard_from_coordinator();
    if (attempt > 0) spdlog::info("coordinator {} is back", o_.coordinator);
    attempt = 0;
    if (!resp.has_task()) {
      if (uploader_.joinable()) {  // our own upload may be what the coordinator waits for
        finish_upload();
        continue;
      }
      if (o_.exit_when_idle && resp.no_more_work()) {
        spdlog::info("no work left; exiting");
        finish_upload();
        remove_bundle_dirs();
        return 0;
      }
      sleep_unless_stopped(o_.idle_poll_seconds);
      continue;
    }
    spdlog::info(
        "task {}: leased ({}){}", resp.task().task_id(), resp.task().lease_id(),
        resp.more_size() > 0 ? ", with " + std::to_string(resp.more_size()) + " more" : "");
    for (const pb::Task& more : resp.more()) {
      spdlog::info("task {}: leased ({})", more.task_id(), more.lease_id());
      queued_.push_back(more);
    }
    run_task(resp.task());
    if (o_.max_tasks > 0 && ++tasks >= o_.max_tasks) break;
  }
  hand_back_queued(stopping() ? "shutting down" : "done");
  finish_upload();
  remove_bundle_dirs();
  spdlog::info("worker {} stopped", worker_id_);
  return 0;
}

int run_worker(const WorkerOptions& o) {
  Worker w(o);
  return w.run();
}

}  // namespace rf
