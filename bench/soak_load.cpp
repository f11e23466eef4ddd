// soak_load: many simulated workers in one process, each speaking the real worker protocol
// (Register, LeaseTask, RenewLease, FetchBlob, CompleteTask) over its own connection to a
// coordinator, for the soak benchmark (bench/soak.sh, docs/reliability.md). Each renders its
// tasks with the engine, as `rayfarm worker` does, and misbehaves on a fraction of them:
//
//   --kill P     drops the task and its connection without a word, then registers again as a new
//                worker a second later (a worker process killed and restarted);
//   --stall P    holds the task past its lease without renewing, then uploads the late result;
//   --corrupt P  uploads a damaged result (a flipped byte in the buffer, or a NaN sample), which
//                the coordinator must refuse.
//
// Runs until --seconds pass or SIGTERM/SIGINT, then prints one JSON line of counters. A corrupt
// result the coordinator accepted is counted in corrupt_accepted (should stay 0).
//
// With --timeline FILE it also writes, every --interval seconds of wall-clock time (aligned to
// multiples of it, so that the lines of several load processes fall into the same intervals), one
// JSON line: the interval's end (Unix seconds), its lease calls answered, the tasks among them,
// results merged, and a histogram of the lease calls' latency (client-side, connection to answer)
// in buckets of 2^(1/16) (4.4%): bucket i holds latencies in [2^(i/16), 2^((i+1)/16)) us.
// bench/soak_plot.py merges the histograms of all load processes into p50 and p99.
//
//   soak_load --coordinator HOST:PORT [--workers 200] [--first-index 0] [--seconds 600]
//             [--kill 0.02] [--stall 0.01] [--corrupt 0.01] [--cache DIR] [--seed 1]
//             [--timeline FILE] [--interval 5] [--batch 1]
//
// With --batch N each lease asks for up to N tasks and the results go up to N in one upload (the
// worker's batched leases and uploads, docs/design.md).
#include <grpcpp/grpcpp.h>
#include <signal.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "engine/buffer_file.h"
#include "engine/build_info.h"
#include "engine/digest.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "farm/blob_store.h"
#include "farm/chunking.h"
#include "farm/convert.h"
#include "farm/upload.h"
#include "proto/rayfarm.grpc.pb.h"

namespace {

namespace pb = rayfarm::v1;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::atomic<bool> g_stop{false};

struct Counters {
  std::atomic<uint64_t> registrations{0}, leased{0}, merged{0}, not_needed{0}, refused{0},
      late_refused{0}, upload_errors{0}, lease_errors{0}, kills{0}, stalls{0}, corrupt{0},
      corrupt_accepted{0}, renewals{0}, renew_failures{0}, lease_calls{0};
};
Counters g_count;

struct Options {
  std::string coordinator;
  int workers = 200;
  double seconds = 600, kill = 0.02, stall = 0.01, corrupt = 0.01;
  std::string cache = "soak-cache";
  uint32_t seed = 1;
  int first_index = 0;  // simulated worker names: sim-<first_index + i>
  std::string timeline;
  double interval = 5;
  int batch = 1;  // tasks asked for per lease, and results per upload (at most)
};

// Lease latency per interval: a log-bucketed histogram (16 buckets per doubling).
class LatencyHistogram {
 public:
  void add(double microseconds) {
    int bucket = int(std::floor(16 * std::log2(std::max(1.0, microseconds))));
    std::lock_guard lock(mu_);
    ++counts_[bucket];
  }
  // The counts since the last call, as a JSON object {"bucket": count, ...}; resets them.
  std::string take_json() {
    std::map<int, uint64_t> counts;
    {
      std::lock_guard lock(mu_);
      counts.swap(counts_);
    }
    std::string out = "{";
    for (const auto& [bucket, n] : counts)
      out += (out.size() > 1 ? ", \"" : "\"") + std::to_string(bucket) + "\": " + std::to_string(n);
    return out + "}";
  }

 private:
  std::mutex mu_;
  std::map<int, uint64_t> counts_;
};
LatencyHistogram g_lease_latency;

void set_deadline(grpc::ClientContext& ctx, double seconds) {
  ctx.set_deadline(std::chrono::system_clock::now() +
                   std::chrono::milliseconds(int64_t(seconds * 1000)));
  ctx.set_wait_for_ready(true);
}

// Scenes shared by all simulated workers: fetched, laid out and parsed once per bundle and
// settings, as one worker process would for its own tasks.
class Scenes {
 public:
  explicit Scenes(const std::string& dir) : dir_(dir), blobs_(dir + "/blobs") {}

  std::shared_ptr<const rf::Renderer> get(const pb::Task& task, pb::WorkerService::Stub& stub) {
    std::string key = task.scene_digest() + task.overrides().SerializeAsString();
    std::lock_guard lock(mu_);
    auto it = cache_.find(key);
    if (it != cache_.end()) return it->second.renderer;
    std::vector<rf::BundleEntry> bundle = rf::from_wire(task.files());
    for (const rf::BundleEntry& e : bundle)
      if (!blobs_.has(e.sha256)) fetch(stub, e.sha256);
    std::string dir = dir_ + "/bundles/" + std::to_string(cache_.size());
    blobs_.materialize(bundle, dir);
    Entry& e = cache_[key];
    e.scene = std::make_unique<rf::Scene>(
        rf::load_scene(dir + "/" + task.scene_path(), rf::to_scene_overrides(task.overrides())));
    e.renderer = std::make_shared<rf::Renderer>(*e.scene);
    return e.renderer;
  }

 private:
  void fetch(pb::WorkerService::Stub& stub, const std::string& sha256) {
    grpc::ClientContext ctx;
    set_deadline(ctx, 60);
    pb::BlobRequest req;
    req.set_sha256(sha256);
    auto reader = stub.FetchBlob(&ctx, req);
    rf::ChunkAssembler assembler(uint64_t(1) << 32);
    pb::Chunk c;
    while (reader->Read(&c)) assembler.add(c);
    grpc::Status s = reader->Finish();
    if (!s.ok() || assembler.finish() != rf::ChunkAssembler::Status::Ok)
      throw std::runtime_error("blob " + sha256 + ": " + s.error_message() + assembler.error());
    blobs_.put(assembler.take(), sha256);
  }

  struct Entry {
    std::unique_ptr<rf::Scene> scene;
    std::shared_ptr<rf::Renderer> renderer;
  };
  std::string dir_;
  rf::BlobStore blobs_;
  std::mutex mu_;
  std::map<std::string, Entry> cache_;
};

class SimulatedWorker {
 public:
  SimulatedWorker(const Options& o, Scenes& scenes, int index)
      : o_(o), scenes_(scenes), index_(index), rng_(o.seed * 7919u + index) {}

  void run() {
    while (!g_stop) {
      connect();
      if (!register_self()) {
        pause(1);
        continue;
      }
      serve();  // returns when "killed" (or stopping)
      pause(1);
    }
  }

 private:
  void connect() {
    grpc::ChannelArguments args;
    args.SetInt(GRPC_ARG_USE_LOCAL_SUBCHANNEL_POOL, 1);  // a connection of its own
    args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 2000);
    channel_ = grpc::CreateCustomChannel(o_.coordinator, grpc::InsecureChannelCredentials(), args);
    stub_ = pb::WorkerService::NewStub(channel_);
  }

  bool register_self() {
    grpc::ClientContext ctx;
    set_deadline(ctx, 30);
    pb::RegisterRequest req;
    req.set_hostname("sim-" + std::to_string(o_.first_index + index_));
    req.set_cores(1);
    req.set_build_id(rf::build_id());
    req.set_isa(rf::cpu_isa());
    pb::RegisterResponse resp;
    if (!stub_->Register(&ctx, req, &resp).ok()) return false;
    ++g_count.registrations;
    worker_id_ = resp.worker_id();
    lease_seconds_ = resp.lease_seconds();
    keepalive_seconds_ = std::max(1u, resp.keepalive_seconds());
    max_results_ = std::clamp<size_t>(resp.max_results_per_upload(), 1, size_t(o_.batch));
    max_upload_bytes_ = resp.max_upload_bytes();
    return true;
  }

  void serve() {
    std::uniform_real_distribution<double> u(0, 1);
    while (!g_stop) {
      grpc::ClientContext ctx;
      set_deadline(ctx, 5);
      pb::LeaseRequest req;
      req.set_worker_id(worker_id_);
      req.set_max_tasks(uint32_t(o_.batch));
      pb::LeaseResponse resp;
      auto asked = Clock::now();
      grpc::Status s = stub_->LeaseTask(&ctx, req, &resp);
      if (s.ok()) {
        ++g_count.lease_calls;
        g_lease_latency.add(
            std::chrono::duration<double, std::micro>(Clock::now() - asked).count());
      }
      if (s.error_code() == grpc::StatusCode::NOT_FOUND) return;
      if (!s.ok()) {
        ++g_count.lease_errors;
        pause(0.5);
        continue;
      }
      if (!resp.has_task()) {
        pause(0.5 + u(rng_));
        continue;
      }
      std::vector<pb::Task> tasks{resp.task()};
      tasks.insert(tasks.end(), resp.more().begin(), resp.more().end());
      g_count.leased += tasks.size();
      std::vector<Result> batch;  // uploaded together (one CompleteTask) when allowed
      uint64_t batch_bytes = 0;
      for (const pb::Task& task : tasks) {
        double r = u(rng_);
        if (r < o_.kill) {
          ++g_count.kills;
          channel_.reset();  // the connection closes; the leases are left to expire
          stub_.reset();
          return;
        }
        bool stall = r < o_.kill + o_.stall;
        bool corrupt = !stall && r < o_.kill + o_.stall + o_.corrupt;
        if (stall) {
          ++g_count.stalls;
          pause(lease_seconds_ + 1);
        }
        Result result{&task, {}, corrupt, stall};
        try {
          result.bytes = render(task, !stall);
        } catch (const std::exception& e) {
          spdlog::error("sim-{}: task {}: {}", index_, task.task_id(), e.what());
          continue;
        }
        if (corrupt) {
          ++g_count.corrupt;
          damage(result.bytes);
        }
        if (stall) {
          upload({result});  // late, alone
          continue;
        }
        batch_bytes += result.bytes.size();
        batch.push_back(std::move(result));
        if (batch.size() >= max_results_ || batch_bytes >= max_upload_bytes_ / 2) {
          upload(batch);
          batch.clear();
          batch_bytes = 0;
        }
      }
      if (!batch.empty()) upload(batch);
    }
  }

  // Renders the task (renewing its lease meanwhile unless told not to); the encoded buffer.
  // Serially, as the one core each simulated worker registers with: hundreds of threads that
  // each start TBB anew (this async thread) collapse into TBB's spin-and-yield waits on 2 cores
  // (1,600 to 110 tasks/s within 30 s, two thirds of the CPU in libtbb and sched_yield; the
  // soak of CI failed on it once). The image is the same bit for bit
  // (Determinism.WholeFrameEqualsTilesBitForBit).
  std::string render(const pb::Task& task, bool renew) {
    std::shared_ptr<const rf::Renderer> renderer = scenes_.get(task, *stub_);
    rf::Rect rect = rf::from_wire(task.rect());
    auto done = std::async(std::launch::async, [&] {
      return renderer->render(rf::TaskKey{task.frame(), rect, task.pass()}, /*parallel=*/false);
    });
    while (done.wait_for(std::chrono::duration<double>(keepalive_seconds_)) !=
           std::future_status::ready) {
      if (!renew) continue;
      grpc::ClientContext ctx;
      set_deadline(ctx, 10);
      pb::RenewRequest req;
      req.set_worker_id(worker_id_);
      req.set_lease_id(task.lease_id());
      pb::RenewResponse resp;
      (stub_->RenewLease(&ctx, req, &resp).ok() ? g_count.renewals : g_count.renew_failures)++;
    }
    return rf::encode_buffer(done.get());
  }

  // A flipped byte past the header, or (every other time) a NaN sample sum.
  void damage(std::string& bytes) {
    if (rng_() % 2 == 0) {
      size_t at = bytes.size() / 2 + rng_() % (bytes.size() / 2);
      bytes[at] = char(bytes[at] ^ (1 << (rng_() % 8)));
    } else {
      rf::SampleBuffer b = rf::decode_buffer(bytes, "result");
      b.sum[rng_() % b.sum.size()] = std::nan("");
      bytes = rf::encode_buffer(b);
    }
  }

  struct Result {
    const pb::Task* task;
    std::string bytes;
    bool corrupt, late;
  };

  // The worker's own upload client (farm/upload.h): the results in one call, each answered on
  // its own; those not settled go again, up to five calls.
  void upload(const std::vector<Result>& results) {
    std::vector<const Result*> pending;
    for (const Result& r : results) pending.push_back(&r);
    for (int attempt = 0; attempt < 5 && !g_stop && !pending.empty(); ++attempt) {
      if (attempt > 0) pause(0.5);
      std::vector<rf::UploadItem> items;
      for (const Result* r : pending) items.push_back({r->task, r->bytes, 0.01, {}});
      rf::BatchAnswer answer = rf::upload_results(*stub_, worker_id_, items, 60, false);
      if (!answer.status.ok()) {
        if (pending.size() == 1 && settle(*pending[0], answer.status, false)) return;
        ++g_count.upload_errors;
        continue;
      }
      std::vector<const Result*> again;
      for (size_t i = 0; i < pending.size(); ++i)
        if (!settle(*pending[i], answer.results[i].status, answer.results[i].accepted)) {
          ++g_count.upload_errors;
          again.push_back(pending[i]);
        }
      pending = std::move(again);
    }
  }

  // Counts one result's answer; false when it is worth sending again.
  bool settle(const Result& r, const grpc::Status& s, bool accepted) {
    if (s.ok()) {
      if (r.corrupt && accepted) ++g_count.corrupt_accepted;
      (accepted ? g_count.merged : g_count.not_needed)++;
      return true;
    }
    switch (s.error_code()) {
      case grpc::StatusCode::INVALID_ARGUMENT:
      case grpc::StatusCode::DATA_LOSS:
        ++g_count.refused;
        if (!r.corrupt)
          spdlog::error("sim-{}: task {}: a sound result refused: {}", index_, r.task->task_id(),
                        s.error_message());
        return true;
      case grpc::StatusCode::FAILED_PRECONDITION:
      case grpc::StatusCode::NOT_FOUND:
      case grpc::StatusCode::PERMISSION_DENIED:  // barred from the job after its refusals
        (r.late ? g_count.late_refused : g_count.refused)++;
        return true;
      default:
        return false;
    }
  }

  void pause(double seconds) {
    auto end = Clock::now() + std::chrono::duration<double>(seconds);
    while (!g_stop && Clock::now() < end)
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }

  const Options& o_;
  Scenes& scenes_;
  int index_;
  std::mt19937 rng_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<pb::WorkerService::Stub> stub_;
  std::string worker_id_;
  uint32_t lease_seconds_ = 30;
  double keepalive_seconds_ = 10;
  size_t max_results_ = 1;  // per upload: --batch, within the coordinator's bound
  uint64_t max_upload_bytes_ = 0;
};

// This process's CPU time (user + system), seconds.
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{"Simulated workers for the soak benchmark (bench/soak.sh)"};
  app.add_option("--coordinator", o.coordinator, "HOST:PORT")->required();
  app.add_option("--workers", o.workers)->check(CLI::Range(1, 100000));
  app.add_option("--seconds", o.seconds)->check(CLI::Range(1.0, 1e6));
  app.add_option("--kill", o.kill)->check(CLI::Range(0.0, 1.0));
  app.add_option("--stall", o.stall)->check(CLI::Range(0.0, 1.0));
  app.add_option("--corrupt", o.corrupt)->check(CLI::Range(0.0, 1.0));
  app.add_option("--cache", o.cache, "directory for fetched bundles");
  app.add_option("--seed", o.seed);
  app.add_option("--first-index", o.first_index, "the first simulated worker's number")
      ->check(CLI::Range(0, 100000000));
  app.add_option("--timeline", o.timeline, "write per-interval JSON lines here");
  app.add_option("--interval", o.interval, "seconds per timeline line")
      ->check(CLI::Range(0.1, 3600.0));
  app.add_option("--batch", o.batch,
                 "tasks asked for per lease and results sent per upload, at most (batched "
                 "leases; the coordinator decides how many it hands out)")
      ->check(CLI::Range(1, 64));
  CLI11_PARSE(app, argc, argv);

  signal(SIGTERM, [](int) { g_stop = true; });
  signal(SIGINT, [](int) { g_stop = true; });
  fs::remove_all(o.cache);
  fs::create_directories(o.cache);
  Scenes scenes(o.cache);
  std::vector<std::thread> threads;
  auto t0 = Clock::now();
  for (int i = 0; i < o.workers; ++i)
    threads.emplace_back([&, i] { SimulatedWorker(o, scenes, i).run(); });
  std::FILE* timeline = o.timeline.empty() ? nullptr : std::fopen(o.timeline.c_str(), "w");
  if (!o.timeline.empty() && !timeline) {
    spdlog::error("{}: {}", o.timeline, std::strerror(errno));
    return 2;
  }
  auto wall = [] {
    return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
        .count();
  };
  double next_line = (std::floor(wall() / o.interval) + 1) * o.interval;
  uint64_t leased_before = 0, merged_before = 0, calls_before = 0;
  auto write_line = [&](double end) {
    uint64_t leased = g_count.leased, merged = g_count.merged, calls = g_count.lease_calls;
    std::fprintf(timeline,
                 "{\"t\": %.3f, \"lease_calls\": %llu, \"leased\": %llu, \"merged\": %llu, "
                 "\"latency_us_log2x16\": %s}\n",
                 end, (unsigned long long)(calls - calls_before),
                 (unsigned long long)(leased - leased_before),
                 (unsigned long long)(merged - merged_before), g_lease_latency.take_json().c_str());
    std::fflush(timeline);
    leased_before = leased, merged_before = merged, calls_before = calls;
  };
  while (!g_stop && std::chrono::duration<double>(Clock::now() - t0).count() < o.seconds) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (timeline && wall() >= next_line) {
      write_line(next_line);
      next_line += o.interval;
    }
  }
  g_stop = true;
  for (std::thread& t : threads) t.join();
  if (timeline) {
    write_line(wall());
    std::fclose(timeline);
  }
  const Counters& c = g_count;
  std::printf(
      "{\"seconds\": %.1f, \"workers\": %d, \"registrations\": %llu, \"leased\": %llu, "
      "\"merged\": %llu, \"not_needed\": %llu, \"refused\": %llu, \"late_refused\": %llu, "
      "\"upload_errors\": %llu, \"lease_errors\": %llu, \"kills\": %llu, \"stalls\": %llu, "
      "\"corrupt\": %llu, \"corrupt_accepted\": %llu, \"renewals\": %llu, "
      "\"renew_failures\": %llu, \"cpu_seconds\": %.1f}\n",
      std::chrono::duration<double>(Clock::now() - t0).count(), o.workers,
      (unsigned long long)c.registrations, (unsigned long long)c.leased,
      (unsigned long long)c.merged, (unsigned long long)c.not_needed, (unsigned long long)c.refused,
      (unsigned long long)c.late_refused, (unsigned long long)c.upload_errors,
      (unsigned long long)c.lease_errors, (unsigned long long)c.kills, (unsigned long long)c.stalls,
      (unsigned long long)c.corrupt, (unsigned long long)c.corrupt_accepted,
      (unsigned long long)c.renewals, (unsigned long long)c.renew_failures, cpu_seconds());
  return c.corrupt_accepted == 0 ? 0 : 1;
}
