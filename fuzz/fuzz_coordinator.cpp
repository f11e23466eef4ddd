// libFuzzer target: the coordinator's request handlers, through its transport-free core
// (coordinator/core.h), driven as hostile clients and workers would drive them over gRPC.
//
// Each input is a program: a sequence of requests, each an operation byte, a caller byte
// (an admin, or a client or worker of one of two tenants) and that request's fields read from
// the input. Every input starts from a fresh state directory holding one valid job (the Cornell
// box, 16x16 in 8x8 tiles, 4 passes), so leases, uploads and restarts have something to work on.
// Requests: submit (a mutated valid spec, or any bytes as a serialized rayfarm.v1.JobSpec, read
// by the service's own conversion), upload a blob, register, lease, renew, upload a result (a
// valid buffer, one with flipped bytes, or any bytes; the upload's header checked first, as the
// service does), fail, cancel, pause/resume, priority, retry, delete, workers, status/list/watch,
// fetch, missing blobs, workers with tags and jobs requiring them, task logs, a
// clock jump (leases expire) and a restart of the coordinator on the same state directory.
//
// Findings, beyond what the sanitizers see:
// - an exception other than CoordinatorError (the service would answer INTERNAL to a client's
//   bad request);
// - a fetched frame that does not decode, or whose passes disagree with its status, or (the valid
//   job) a pixel whose sample count is not its merged passes' (a task merged twice, or lost);
// - the valid job's spp not equal to its merged passes times the samples per pass.
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "coordinator/core.h"
#include "engine/buffer_file.h"
#include "engine/build_info.h"
#include "engine/digest.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "farm/blob_store.h"
#include "farm/convert.h"
#include "proto/rayfarm.pb.h"

#include <spdlog/spdlog.h>

namespace fs = std::filesystem;

namespace {

using namespace rf;

const std::string kScene = RAYFARM_SOURCE_DIR "/scenes/cornell-box/scene.json";
constexpr int kSamplesPerPass = 2;
constexpr uint32_t kPasses = 4;

[[noreturn]] void finding(const std::string& what) {
  std::fprintf(stderr, "fuzz_coordinator: %s\n", what.c_str());
  std::abort();
}

// Reads the input's bytes as request fields; past the end everything is zero or empty.
class Reader {
 public:
  Reader(const uint8_t* data, size_t size) : p_(data), n_(size) {}
  bool empty() const { return n_ == 0; }
  uint8_t byte() {
    if (n_ == 0) return 0;
    --n_;
    return *p_++;
  }
  uint32_t u32() {
    uint32_t v = 0;
    for (int i = 0; i < 4; ++i) v = v << 8 | byte();
    return v;
  }
  // A string of up to `max` bytes (its length is the first byte, scaled), in 7-bit ASCII (NUL
  // and control characters included): the wire's string fields are UTF-8, which gRPC's parser
  // checks before a handler sees them.
  std::string str(size_t max = 255) {
    size_t len = std::min<size_t>({size_t(byte()) * max / 255, n_, max});
    std::string s(reinterpret_cast<const char*>(p_), len);
    for (char& c : s) c = char(c & 0x7f);
    p_ += len;
    n_ -= len;
    return s;
  }
  // Up to 64 KiB, length from two bytes.
  std::string blob() {
    size_t len = std::min<size_t>(size_t(byte()) << 8 | byte(), n_);
    std::string s(reinterpret_cast<const char*>(p_), len);
    p_ += len;
    n_ -= len;
    return s;
  }

 private:
  const uint8_t* p_;
  size_t n_;
};

struct Scene0 {
  JobSpec spec;                         // the valid job's spec (without its request id)
  std::vector<std::string> blob_bytes;  // its bundle's files
};

const Scene0& valid_job() {
  static const Scene0 s = [] {
    Scene0 s;
    s.spec.name = "cornell";
    s.spec.scene_path = "scene.json";
    s.spec.files = bundle_of_scene(kScene);
    for (const BundleEntry& f : s.spec.files)
      s.blob_bytes.push_back(read_file_bytes((fs::path(kScene).parent_path() / f.path).string()));
    s.spec.frames = "1";
    s.spec.overrides.width = 16;
    s.spec.overrides.height = 16;
    s.spec.overrides.passes = kPasses;
    s.spec.overrides.spp = kSamplesPerPass * kPasses;
    s.spec.tile_size = 8;
    return s;
  }();
  return s;
}

// The buffer header a task of the valid job must carry, per pass (the scene parsed once).
const BufferHeader& valid_header(uint32_t pass, const SceneOverrides& overrides) {
  static std::map<uint32_t, BufferHeader> headers;
  auto it = headers.find(pass);
  if (it != headers.end()) return it->second;
  static const Scene scene = load_scene(kScene, overrides);
  return headers[pass] = frame_header(scene, 1, PassSet::range(pass, pass + 1));
}

constexpr int kRequests = 25;  // the operations of Farm::request

const Caller kCallers[] = {
    {"admin", "ops", true}, {"alice", "shot1", false}, {"bob", "shot2", false}};

class Farm {
 public:
  explicit Farm(std::string dir) : dir_(std::move(dir)) {
    fs::remove_all(dir_);
    start();
    const Scene0& v = valid_job();
    for (const std::string& b : v.blob_bytes) core_->put_blob(b, kCallers[1]);
    job0_ = core_->submit(v.spec, kCallers[1]);
    jobs_.push_back(job0_);
  }
  ~Farm() {
    core_.reset();
    fs::remove_all(dir_);
  }

  void run(Reader& in) {
    for (int steps = 0; !in.empty() && steps < 64; ++steps) {
      uint8_t op = in.byte();
      const Caller& caller = kCallers[in.byte() % 3];
      if (trace_)
        std::fprintf(stderr, "request %d by %s\n", op % kRequests, caller.principal.c_str());
      try {
        request(op % kRequests, caller, in);
      } catch (const CoordinatorError& e) {
        // A refusal, with its code: what a bad request should get.
        if (trace_) std::fprintf(stderr, "  refused: %s\n", e.what());
      } catch (const std::exception& e) {
        finding("request " + std::to_string(op % kRequests) + " threw a non-refusal: " + e.what());
      }
    }
    check_job0();
  }

 private:
  void start() {
    core_.reset();
    CoreOptions o;
    o.state_dir = dir_;
    o.scene_checker = in_process_scene_checker();
    o.store = store_;  // kept across the program's restarts, as a database would be
    o.lease_seconds = 10;
    o.instance = "i" + std::to_string(starts_++);
    o.clock = [this] { return now_; };
    o.verify_fraction = 0.25;
    core_ = std::make_unique<Coordinator>(o);
    leases_.clear();  // a restarted coordinator knows none of them
  }

  template <class T>
  const T* pick(const std::vector<T>& v, Reader& in) {
    uint8_t b = in.byte();
    return v.empty() || b >= v.size() * 2 ? nullptr : &v[b % v.size()];
  }
  std::string job_id(Reader& in) {
    const std::string* j = pick(jobs_, in);
    return j ? *j : in.str(32);
  }
  std::string worker_id(Reader& in) {
    const std::string* w = pick(workers_, in);
    return w ? *w : in.str(32);
  }

  struct Held {
    TaskAssignment task;
    std::string worker_id;
  };

  void request(int op, const Caller& caller, Reader& in) {
    switch (op) {
      case 0: {  // submit
        JobSpec spec;
        if (in.byte() & 1) {
          rayfarm::v1::JobSpec wire;
          if (!wire.ParseFromString(in.blob())) return;  // the service answers INVALID_ARGUMENT
          spec = from_wire(wire);
        } else {
          spec = valid_job().spec;
          uint8_t fields = in.byte();
          if (fields & 1) spec.frames = in.str(32);
          if (fields & 2) spec.tile_size = in.u32();
          if (fields & 4) spec.overrides.width = in.u32() % 4096;
          if (fields & 8) spec.overrides.height = in.u32() % 4096;
          if (fields & 16) spec.overrides.passes = in.u32();
          if (fields & 32) spec.overrides.spp = in.u32();
          if (fields & 64) spec.scene_path = in.str();
          if (fields & 128) spec.request_id = in.str(40);
        }
        jobs_.push_back(core_->submit(spec, caller));
        return;
      }
      case 1:
        core_->put_blob(in.blob(), caller);
        return;
      case 2: {
        WorkerInfo w{in.str(64), in.byte(), in.byte() & 1 ? in.str(64) : build_id(), cpu_isa()};
        workers_.push_back(core_->register_worker(w, caller).worker_id);
        return;
      }
      case 3: {
        std::string w = worker_id(in);
        LeaseResult l = core_->lease(w, caller, in.byte() % 70);  // batches, over the bound too
        if (l.task) leases_.push_back({*l.task, w});
        for (const TaskAssignment& more : l.more) {
          if (more.task.job_id != l.task->task.job_id)
            finding("a batched lease handed out tasks of two jobs");
          leases_.push_back({more, w});
        }
        if (l.more.size() >= Coordinator::kMaxTasksPerLease)
          finding("a lease handed out " + std::to_string(l.more.size() + 1) + " tasks");
        if (trace_ && l.task)
          std::fprintf(stderr, "  %s leased %s (%s)\n", w.c_str(),
                       task_id_text(l.task->task).c_str(), l.task->lease_id.c_str());
        return;
      }
      case 4: {
        const Held* h = pick(leases_, in);
        core_->renew(h && in.byte() & 1 ? h->worker_id : worker_id(in),
                     h ? h->task.lease_id : in.str(), caller);
        return;
      }
      case 5:
        upload(caller, in);
        return;
      case 6: {
        const Held* h = pick(leases_, in);
        TaskFailureReport r{h ? h->worker_id : worker_id(in), h ? h->task.lease_id : in.str(),
                            in.str(), bool(in.byte() & 1)};
        core_->fail(r, caller);
        return;
      }
      case 7:
        core_->cancel(job_id(in), caller);
        return;
      case 8: {
        uint8_t what = in.byte() % 3;
        if (what == 0) {
          core_->status(job_id(in), caller);
        } else if (what == 1) {
          bool more = false;
          core_->list(caller, in.byte(), in.byte() & 1 ? job_id(in) : "", &more);
        } else {
          uint64_t seen = in.byte();
          core_->next_status(job_id(in), seen, 0, caller);
        }
        return;
      }
      case 9: {
        std::string job = job_id(in);
        FrameImage image = core_->fetch(job, in.byte() % 4, caller);
        SampleBuffer b;
        try {
          b = decode_buffer(image.buffer, "fetched frame");
        } catch (const std::exception& e) {
          finding("a fetched frame does not decode: " + std::string(e.what()));
        }
        if (job != job0_) return;
        uint32_t passes = b.header.passes.count();
        if (passes != image.status.progress.passes_merged)
          finding("fetched frame holds " + std::to_string(passes) + " passes, its status says " +
                  std::to_string(image.status.progress.passes_merged));
        // No task merged twice (or lost): every pixel has each merged pass's samples once.
        for (uint64_t c : b.count)
          if (c != uint64_t(passes) * kSamplesPerPass)
            finding("a fetched pixel has " + std::to_string(c) + " samples after " +
                    std::to_string(passes) + " passes of " + std::to_string(kSamplesPerPass));
        return;
      }
      case 10: {
        std::vector<std::string> digests;
        for (int i = in.byte() % 4; i > 0; --i)
          digests.push_back(in.byte() & 1 ? sha256_hex(valid_job().blob_bytes[0]) : in.str(64));
        core_->missing_blobs(digests, caller);
        return;
      }
      case 11:
        now_ += in.byte();  // seconds: past 10, every lease held has expired
        return;
      case 12:
        start();
        return;
      case 13: {  // an upload's header only, as a hostile worker's that never sends the bytes
        const Held* h = pick(leases_, in);
        if (h) core_->check_upload(h->worker_id, h->task.lease_id, h->task.task, caller);
        return;
      }
      case 14:  // pause or resume
        core_->set_paused(job_id(in), in.byte() & 1, caller);
        return;
      case 16:
        core_->workers(caller);
        return;
      case 17: {  // retry: every unfinished frame, or a range (any text)
        const std::string job = job_id(in);
        core_->retry(job, in.byte() & 1 ? in.str(16) : "", caller);
        return;
      }
      case 18: {  // delete, forced or not
        const std::string job = job_id(in);
        core_->delete_job(job, in.byte() & 1, caller);
        if (job == job0_) job0_deleted_ = true;
        return;
      }
      case 19: {  // register with tags (any text: bad ones are refused)
        WorkerInfo w{"tagged", 1, build_id(), cpu_isa(), {in.str(24), in.str(24)}};
        workers_.push_back(core_->register_worker(w, caller).worker_id);
        return;
      }
      case 21: {  // logs: of a frame, of a task (a held lease's, or any text), any limit
        const std::string job = job_id(in);
        const uint8_t what = in.byte();
        std::optional<FrameNumber> frame;
        if (what & 1) frame = FrameNumber(int32_t(in.u32()));
        const Held* h = what & 2 ? pick(leases_, in) : nullptr;
        std::string task = h ? task_id_text(h->task.task) : (what & 4 ? in.str(48) : "");
        core_->task_log(job, frame, task, in.u32(), caller);
        return;
      }
      case 20: {  // the valid job, requiring tags (any text)
        JobSpec spec = valid_job().spec;
        spec.required_tags = {in.str(24), in.str(24)};
        jobs_.push_back(core_->submit(spec, caller));
        return;
      }
      case 22: {  // requeue: a range (any text); the valid scene again, any bundle, or none
        const std::string job = job_id(in);
        const uint8_t how = in.byte();
        const std::string frames = how & 1 ? in.str(16) : "1";
        std::optional<SceneVersion> scene;
        if (how & 2)
          scene = SceneVersion{valid_job().spec.scene_path, valid_job().spec.files, ""};
        else if (how & 4)
          scene = SceneVersion{in.str(), {{in.str(32), in.str(64)}}, ""};
        core_->requeue(job, frames, scene, how & 8 ? in.str(16) : "", caller);
        return;
      }
      case 23: {  // retention, up to 255 days ahead (finished jobs expire after 7, blobs after 1 h)
        const double ahead = in.byte() * 86400.0 + in.byte() * 60.0;
        core_->collect(
            std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
                .count() +
            ahead);
        try {
          core_->status(job0_, kCallers[0]);
        } catch (const CoordinatorError& e) {
          if (e.code == ErrorCode::NotFound) job0_deleted_ = true;  // it expired
        }
        return;
      }
      case 15: {  // a new priority, any 32-bit value
        const std::string job = job_id(in);
        core_->set_priority(job, int(int32_t(in.u32())), caller);
        return;
      }
      case 24: {  // a batched upload: up to 8 results, each as upload() makes them
        std::vector<TaskResult> batch;
        for (int n = 1 + in.byte() % 8; n > 0; --n)
          if (std::optional<TaskResult> r = result(caller, in)) batch.push_back(std::move(*r));
        const size_t sent = batch.size();
        std::vector<Coordinator::ResultOutcome> out =
            core_->complete_batch(std::move(batch), caller);
        if (out.size() != sent)
          finding("a batch of " + std::to_string(sent) + " got " + std::to_string(out.size()) +
                  " answers");
        for (const Coordinator::ResultOutcome& o : out)
          if (o.accepted && o.error) finding("a batched result both taken and refused");
        return;
      }
    }
  }

  void upload(const Caller& caller, Reader& in) {
    std::optional<TaskResult> r = result(caller, in);
    if (!r) return;
    const std::string worker = r->worker_id, lease = r->lease_id, task = task_id_text(r->task);
    // True: merged, or (a verified task) held until a second worker's result agrees.
    bool taken = core_->complete(std::move(*r), caller);
    if (trace_)
      std::fprintf(stderr, "  %s %s lease %s: %s\n", worker.c_str(), task.c_str(), lease.c_str(),
                   taken ? "taken" : "not needed");
  }

  // A result as a worker (honest, careless or hostile) sends it: of a held lease or invented,
  // valid, damaged or arbitrary bytes; none when the service would not read on (its task id does
  // not parse, or check_upload says it is not needed).
  std::optional<TaskResult> result(const Caller& caller, Reader& in) {
    const Held* h = pick(leases_, in);
    TaskResult r;
    r.worker_id = h && in.byte() & 1 ? h->worker_id : worker_id(in);
    r.lease_id = h ? h->task.lease_id : in.str();
    if (h) {
      r.task = h->task.task;
    } else if (std::optional<TaskRef> t = parse_task_id(in.str())) {
      r.task = *t;
    } else {
      return std::nullopt;  // the service refuses a task id that does not parse
    }
    uint8_t kind = in.byte() % 3;
    if (kind == 2 || !h || r.task.job_id != job0_) {
      r.buffer = in.blob();
    } else {
      // One pass of the task's tile, every sample one value (from the input: may be NaN).
      uint32_t bits = in.u32();
      float value;
      std::memcpy(&value, &bits, sizeof value);
      SampleBuffer b(valid_header(r.task.pass, h->task.overrides), h->task.rect, false);
      for (int y = h->task.rect.y0; y < h->task.rect.y1(); ++y)
        for (int x = h->task.rect.x0; x < h->task.rect.x1(); ++x)
          for (int s = 0; s < kSamplesPerPass; ++s) b.add_sample(x, y, RGB(value));
      b.finish_pass();
      r.buffer = encode_buffer(b);
      if (kind == 1)
        for (int i = in.byte() % 4; i > 0 && !r.buffer.empty(); --i)
          r.buffer[in.u32() % r.buffer.size()] ^= char(in.byte() | 1);
    }
    if (!core_->check_upload(r.worker_id, r.lease_id, r.task, caller)) return std::nullopt;
    return r;
  }

  // The valid job's figures agree with each other.
  void check_job0() {
    if (job0_deleted_) return;
    JobStatus s = core_->status(job0_, kCallers[0]);
    for (const FrameStatus& f : s.frames) {
      if (f.progress.passes_merged > kPasses)
        finding("job 0 merged " + std::to_string(f.progress.passes_merged) + " passes of " +
                std::to_string(kPasses));
      if (f.progress.spp != double(f.progress.passes_merged) * kSamplesPerPass)
        finding("job 0 shows " + std::to_string(f.progress.spp) + " spp after " +
                std::to_string(f.progress.passes_merged) + " passes");
    }
  }

  const bool trace_ = std::getenv("FUZZ_TRACE") != nullptr;  // each request and refusal
  std::string dir_;
  std::shared_ptr<JobStore> store_ = memory_store();
  double now_ = 0;
  int starts_ = 0;
  std::unique_ptr<Coordinator> core_;
  std::string job0_;
  bool job0_deleted_ = false;
  std::vector<std::string> jobs_, workers_;
  std::vector<Held> leases_;
};

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  spdlog::set_level(spdlog::level::off);  // the core's warnings about refused requests
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  // A fresh state directory per input, in memory when /dev/shm exists.
  static const std::string dir =
      (fs::is_directory("/dev/shm") ? std::string("/dev/shm")
                                    : fs::temp_directory_path().string()) +
      "/rayfarm-fuzz-coordinator-" + std::to_string(getpid());
  Reader in(data, size);
  Farm farm(dir);
  farm.run(in);
  return 0;
}
