// The gRPC face of the coordinator: the job and worker services translate between protobuf and
// the core (core.h), stream large payloads in chunks (farm/chunking.h) and turn the core's
// errors into status codes in one place (grpc_code). The job logic lives in the core.
#include "coordinator/service.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <signal.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <optional>

#include "coordinator/core.h"
#include "farm/chunking.h"
#include "farm/convert.h"
#include "proto/rayfarm.grpc.pb.h"

namespace rf {

namespace pb = rayfarm::v1;
using grpc::ServerContext;
using grpc::Status;
using grpc::StatusCode;

namespace {

// The one place where the core's error codes become gRPC's (DESIGN.md "Status codes").
StatusCode grpc_code(ErrorCode c) {
  switch (c) {
    case ErrorCode::InvalidArgument:
      return StatusCode::INVALID_ARGUMENT;
    case ErrorCode::NotFound:
      return StatusCode::NOT_FOUND;
    case ErrorCode::FailedPrecondition:
      return StatusCode::FAILED_PRECONDITION;
    case ErrorCode::ResourceExhausted:
      return StatusCode::RESOURCE_EXHAUSTED;
    case ErrorCode::DataLoss:
      return StatusCode::DATA_LOSS;
    case ErrorCode::Unavailable:
      return StatusCode::UNAVAILABLE;
    case ErrorCode::Internal:
      return StatusCode::INTERNAL;
  }
  return StatusCode::INTERNAL;
}

// Runs a handler. A refusal answers with its code; anything else thrown must not take the
// server down: it answers INTERNAL with the message.
template <class F>
Status handle(F&& f) {
  try {
    f();
    return Status::OK;
  } catch (const CoordinatorError& e) {
    return Status(grpc_code(e.code), e.what());
  } catch (const std::exception& e) {
    return Status(StatusCode::INTERNAL, e.what());
  }
}

// A chunk stream's problem as the core's error code, so it reaches grpc_code like every other.
void check_chunks(ChunkAssembler::Status s, const std::string& what, const ChunkAssembler& a) {
  switch (s) {
    case ChunkAssembler::Status::Ok:
      return;
    case ChunkAssembler::Status::InvalidArgument:
      throw CoordinatorError(ErrorCode::InvalidArgument, what + ": " + a.error());
    case ChunkAssembler::Status::ResourceExhausted:
      throw CoordinatorError(ErrorCode::ResourceExhausted, what + ": " + a.error());
    case ChunkAssembler::Status::DataLoss:
      throw CoordinatorError(ErrorCode::DataLoss, what + ": " + a.error());
  }
}

[[noreturn]] void bad_request(const std::string& message) {
  throw CoordinatorError(ErrorCode::InvalidArgument, message);
}

// Streams a payload as chunks; the first message may carry more (make(chunk, first)).
template <class Message, class Make>
void write_chunks(grpc::ServerWriterInterface<Message>* w, const std::string& bytes, Make make) {
  bool first = true, ok = true;
  for_each_chunk(bytes, [&](pb::Chunk&& c) {
    if (ok) ok = w->Write(make(std::move(c), first));
    first = false;
  });
}

pb::FrameStatus to_wire(const FrameStatus& s) {
  pb::FrameStatus out;
  out.set_frame(s.frame);
  out.set_passes_merged(s.progress.passes_merged);
  out.set_passes_total(s.progress.passes_total);
  out.set_spp(s.progress.spp);
  out.set_rel_mse(s.progress.rel_mse);
  out.set_eta_seconds(s.progress.eta_seconds);
  out.set_done(s.progress.done);
  out.set_stopped_on_target(s.progress.stopped_on_target);
  return out;
}

pb::JobStatus to_wire(const JobStatus& s) {
  static_assert(
      int(JobState::Queued) == pb::JOB_QUEUED && int(JobState::Running) == pb::JOB_RUNNING &&
      int(JobState::Completed) == pb::JOB_COMPLETED && int(JobState::Failed) == pb::JOB_FAILED &&
      int(JobState::Cancelled) == pb::JOB_CANCELLED);
  pb::JobStatus out;
  out.set_job_id(s.job_id);
  out.set_name(s.name);
  out.set_state(pb::JobState(int(s.state)));
  out.set_error(s.error);
  out.set_core_seconds(s.core_seconds);
  out.set_submitted_unix(s.submitted_unix);
  for (const FrameStatus& f : s.frames) *out.add_frames() = to_wire(f);
  return out;
}

void to_wire(const TaskAssignment& a, pb::Task* t) {
  t->set_task_id(task_id_text(a.task));
  t->set_lease_id(a.lease_id);
  t->set_job_id(a.task.job_id);
  t->set_frame(a.task.frame);
  t->set_pass(a.task.pass);
  *t->mutable_rect() = to_wire(a.rect);
  t->set_scene_path(a.scene_path);
  for (const BundleEntry& e : a.files) {
    pb::BundleFile* f = t->add_files();
    f->set_path(e.path);
    f->set_sha256(e.sha256);
  }
  *t->mutable_overrides() = to_wire_overrides(a.overrides);
  t->set_scene_digest(a.scene_digest);
}

// Submit's stream after the spec: blobs as chunk runs, each starting at offset 0.
void receive_blobs(Coordinator& core, grpc::ServerReaderInterface<pb::SubmitRequest>* reader,
                   const CoordinatorOptions& o) {
  std::optional<ChunkAssembler> blob;
  uint64_t bundle_bytes = 0;
  auto finish_blob = [&] {
    if (!blob) return;
    check_chunks(blob->finish(), "blob", *blob);
    std::string bytes = blob->take();
    bundle_bytes += bytes.size();
    if (bundle_bytes > o.max_bundle_bytes)
      throw CoordinatorError(
          ErrorCode::ResourceExhausted,
          "bundle is over the limit of " + std::to_string(o.max_bundle_bytes) + " bytes");
    core.put_blob(bytes);
    blob.reset();
  };
  pb::SubmitRequest msg;
  while (reader->Read(&msg)) {
    if (!msg.has_blob_chunk()) bad_request("only blob chunks may follow the job spec");
    if (msg.blob_chunk().offset() == 0) {
      finish_blob();
      blob.emplace(o.max_blob_bytes);
    }
    if (!blob) bad_request("a blob must start at offset 0");
    check_chunks(blob->add(msg.blob_chunk()), "blob", *blob);
  }
  finish_blob();
}

class JobServiceImpl final : public pb::JobService::Service {
 public:
  JobServiceImpl(Coordinator& c, const CoordinatorOptions& o) : c_(c), o_(o) {}

  Status MissingBlobs(ServerContext*, const pb::MissingBlobsRequest* r,
                      pb::MissingBlobsResponse* o) override {
    return handle([&] {
      for (std::string& d : c_.missing_blobs({r->sha256().begin(), r->sha256().end()}))
        o->add_sha256(std::move(d));
    });
  }
  Status Submit(ServerContext*, grpc::ServerReader<pb::SubmitRequest>* r,
                pb::SubmitResponse* o) override {
    return handle([&] {
      pb::SubmitRequest first;
      if (!r->Read(&first) || !first.has_spec())
        bad_request("the first message of Submit must be the job spec");
      receive_blobs(c_, r, o_);
      o->set_job_id(c_.submit(from_wire(first.spec())));
    });
  }
  Status ListJobs(ServerContext*, const pb::ListJobsRequest*, pb::ListJobsResponse* o) override {
    return handle([&] {
      for (const JobStatus& s : c_.list()) *o->add_jobs() = to_wire(s);
    });
  }
  Status GetJob(ServerContext*, const pb::JobRef* r, pb::JobStatus* o) override {
    return handle([&] { *o = to_wire(c_.status(r->job_id())); });
  }
  // A message at every change, until the job ends or the client goes.
  Status WatchJob(ServerContext* ctx, const pb::JobRef* r,
                  grpc::ServerWriter<pb::JobStatus>* w) override {
    return handle([&] {
      uint64_t seen = 0;
      while (!ctx->IsCancelled()) {
        std::optional<JobStatus> s = c_.next_status(r->job_id(), seen, 1.0);
        if (!s) continue;
        if (!w->Write(to_wire(*s)) || terminal(s->state)) return;
      }
    });
  }
  Status CancelJob(ServerContext*, const pb::JobRef* r, pb::CancelResponse*) override {
    return handle([&] { c_.cancel(r->job_id()); });
  }
  Status FetchFrame(ServerContext*, const pb::FetchRequest* r,
                    grpc::ServerWriter<pb::FetchResponse>* w) override {
    return handle([&] {
      FrameImage image = c_.fetch(r->job_id(), r->frame());
      write_chunks(w, image.buffer, [&](pb::Chunk&& c, bool first) {
        pb::FetchResponse m;
        *m.mutable_chunk() = std::move(c);
        if (first) *m.mutable_status() = to_wire(image.status);
        return m;
      });
    });
  }

 private:
  Coordinator& c_;
  const CoordinatorOptions& o_;
};

class WorkerServiceImpl final : public pb::WorkerService::Service {
 public:
  WorkerServiceImpl(Coordinator& c, const CoordinatorOptions& o) : c_(c), o_(o) {}

  Status Register(ServerContext*, const pb::RegisterRequest* r, pb::RegisterResponse* o) override {
    return handle([&] {
      Registration reg = c_.register_worker({r->hostname(), r->cores(), r->build_id(), r->isa()});
      o->set_worker_id(reg.worker_id);
      o->set_lease_seconds(reg.lease_seconds);
      o->set_keepalive_seconds(reg.keepalive_seconds);
    });
  }
  Status LeaseTask(ServerContext*, const pb::LeaseRequest* r, pb::LeaseResponse* o) override {
    return handle([&] {
      LeaseResult l = c_.lease(r->worker_id());
      if (l.task)
        to_wire(*l.task, o->mutable_task());
      else
        o->set_no_more_work(l.no_more_work);
    });
  }
  Status RenewLease(ServerContext*, const pb::RenewRequest* r, pb::RenewResponse* o) override {
    return handle([&] { o->set_lease_seconds(c_.renew(r->lease_id())); });
  }
  Status FetchBlob(ServerContext*, const pb::BlobRequest* r,
                   grpc::ServerWriter<pb::Chunk>* w) override {
    return handle([&] {
      write_chunks(w, c_.blob(r->sha256()), [](pb::Chunk&& c, bool) { return std::move(c); });
    });
  }
  // A header, then the sample buffer in chunks.
  Status CompleteTask(ServerContext*, grpc::ServerReader<pb::CompleteRequest>* r,
                      pb::CompleteResponse* o) override {
    return handle([&] {
      pb::CompleteRequest msg;
      if (!r->Read(&msg) || !msg.has_header())
        bad_request("the first message of CompleteTask must be the header");
      const pb::CompleteHeader header = msg.header();
      std::optional<TaskRef> task = parse_task_id(header.task_id());
      if (!task) bad_request("task_id '" + header.task_id() + "' is malformed");
      ChunkAssembler chunks(o_.max_buffer_bytes);
      while (r->Read(&msg)) {
        if (!msg.has_chunk()) bad_request("only chunks may follow the header");
        check_chunks(chunks.add(msg.chunk()), "sample buffer", chunks);
      }
      check_chunks(chunks.finish(), "sample buffer", chunks);
      o->set_accepted(
          c_.complete({header.worker_id(), header.lease_id(), std::move(*task), chunks.take()}));
    });
  }
  Status FailTask(ServerContext*, const pb::FailRequest* r, pb::FailResponse*) override {
    return handle([&] {
      c_.fail({r->worker_id(), r->lease_id(), r->message(), r->handed_back()});
    });
  }

 private:
  Coordinator& c_;
  const CoordinatorOptions& o_;
};

}  // namespace

struct CoordinatorServer::Impl {
  CoordinatorOptions options;
  std::unique_ptr<Coordinator> core;
  std::unique_ptr<JobServiceImpl> jobs;
  std::unique_ptr<WorkerServiceImpl> workers;
  std::unique_ptr<grpc::Server> server;
  int port = 0;
};

CoordinatorServer::CoordinatorServer(const CoordinatorOptions& o)
    : impl_(std::make_unique<Impl>()) {
  if (o.state_dir.empty()) throw std::runtime_error("coordinator: --state-dir is required");
  impl_->options = o;
  CoreOptions core;
  core.state_dir = o.state_dir;
  core.lease_seconds = o.lease_seconds;
  core.window_frames = o.window_frames;
  impl_->core = std::make_unique<Coordinator>(core);
  impl_->jobs = std::make_unique<JobServiceImpl>(*impl_->core, impl_->options);
  impl_->workers = std::make_unique<WorkerServiceImpl>(*impl_->core, impl_->options);
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
  impl_->core->shut_down();
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
