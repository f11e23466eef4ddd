// The gRPC face of the coordinator: the job and worker services translate between protobuf and
// the core (core.h), stream large payloads in chunks (farm/chunking.h) and turn the core's
// errors into status codes in one place (grpc_code). The job logic lives in the core.
#include "coordinator/service.h"

#include "engine/buffer_file.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <openssl/err.h>
#include <openssl/pem.h>
#include <openssl/x509.h>
#include <signal.h>
#include <spdlog/spdlog.h>

#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <ctime>
#include <mutex>
#include <optional>
#include <thread>

#include "coordinator/core.h"
#include "coordinator/metrics.h"
#include "coordinator/monitor.h"
#include "engine/digest.h"  // read_file_bytes
#include "farm/auth.h"
#include "farm/chunking.h"
#include "farm/convert.h"
#include "farm/frame_range.h"
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
    case ErrorCode::PermissionDenied:
      return StatusCode::PERMISSION_DENIED;
    case ErrorCode::Unauthenticated:
      return StatusCode::UNAUTHENTICATED;
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

// Which role a method needs; an admin token passes both.
enum class Access { Client, Worker };

// The one place where calls are authenticated and authorised (docs/security.md). Every handler
// goes through guarded(), which asks the gate first; gRPC C++ server interceptors cannot end a
// call with a status of their choosing, so this is the interceptor. The gate serves plaintext
// and TLS alike: the token travels as call metadata ("authorization: Bearer TOKEN").
// The refusal log's rate limit: a token bucket of kBurst lines refilled at kPerSecond, so a client
// hammering with a bad token costs the log at most that (the metric counts every refusal).
class LogBudget {
 public:
  static constexpr double kPerSecond = 20, kBurst = 100;
  // True when a line may be logged; *suppressed is how many were not since the last one.
  bool take(uint64_t* suppressed) {
    std::lock_guard lock(mu_);
    auto now = std::chrono::steady_clock::now();
    tokens_ =
        std::min(kBurst, tokens_ + kPerSecond * std::chrono::duration<double>(now - last_).count());
    last_ = now;
    if (tokens_ < 1) {
      ++suppressed_;
      return false;
    }
    tokens_ -= 1;
    *suppressed = suppressed_;
    suppressed_ = 0;
    return true;
  }

 private:
  std::mutex mu_;
  double tokens_ = kBurst;
  std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
  uint64_t suppressed_ = 0;
};

class Gate {
 public:
  Gate(std::string token_file, bool worker_certs)
      : file_(std::move(token_file)), worker_certs_(worker_certs) {
    if (!file_.empty()) table_ = std::make_shared<const TokenTable>(TokenTable::load(file_));
  }
  bool open() const { return file_.empty(); }
  void reload() {
    if (open()) return;
    auto fresh = std::make_shared<const TokenTable>(TokenTable::load(file_));
    std::lock_guard lock(mu_);
    table_ = std::move(fresh);
  }

  // The principal of a token presented to the web monitor, or nothing with the reason.
  std::optional<Principal> principal(const std::string& token, std::string* why) const {
    std::shared_ptr<const TokenTable> table;
    {
      std::lock_guard lock(mu_);
      table = table_;
    }
    Principal who;
    switch (table ? table->check(token, int64_t(std::time(nullptr)), &who)
                  : TokenTable::Check::Unknown) {
      case TokenTable::Check::Accepted:
        return who;
      case TokenTable::Check::Expired:
        *why = "token " + token_id(token) + " has expired";
        return std::nullopt;
      case TokenTable::Check::Unknown:
        break;
    }
    *why = "token " + token_id(token) + " is not accepted";
    return std::nullopt;
  }

  // The caller of this call, or a refusal: UNAUTHENTICATED without an accepted token,
  // PERMISSION_DENIED for a token of the wrong role. Refusals are logged with the peer and
  // the token's id (a digest prefix), never the token.
  // Counts refusals in the core's metrics from now on.
  void count_in(Coordinator* core) { core_ = core; }

  Caller admit(ServerContext* ctx, Access need, const char* method) const {
    auto deny = [&](ErrorCode code, const std::string& why) {
      uint64_t suppressed = 0;
      bool log = log_budget_.take(&suppressed);
      if (core_) core_->note_refused_call(log);
      if (log)
        spdlog::warn("refused {} from {}: {}{}", method, ctx->peer(), why,
                     suppressed ? " (" + std::to_string(suppressed) +
                                      " refusals before this one not logged: over " +
                                      std::to_string(LogBudget::kPerSecond) + " a second)"
                                : std::string());
      throw CoordinatorError(code, why);
    };
    if (need == Access::Worker && worker_certs_) {
      std::shared_ptr<const grpc::AuthContext> auth = ctx->auth_context();
      if (!auth || !auth->IsPeerAuthenticated())
        deny(ErrorCode::Unauthenticated,
             std::string(method) +
                 " needs a client certificate signed by the coordinator's "
                 "--tls-client-ca (mutual TLS is on for workers)");
    }
    if (open()) return Caller{};
    std::string token;
    const auto& md = ctx->client_metadata();
    auto it = md.find("authorization");
    if (it == md.end())
      deny(ErrorCode::Unauthenticated,
           "no token: this coordinator needs 'authorization: Bearer TOKEN' (--token-file, "
           "RAYFARM_TOKEN_FILE or RAYFARM_TOKEN)");
    std::string_view value(it->second.data(), it->second.size());
    constexpr std::string_view kBearer = "Bearer ";
    if (value.substr(0, kBearer.size()) != kBearer)
      deny(ErrorCode::Unauthenticated, "the authorization metadata is not 'Bearer TOKEN'");
    token = std::string(value.substr(kBearer.size()));
    std::shared_ptr<const TokenTable> table;
    {
      std::lock_guard lock(mu_);
      table = table_;
    }
    Principal who;
    switch (table->check(token, int64_t(std::time(nullptr)), &who)) {
      case TokenTable::Check::Unknown:
        deny(ErrorCode::Unauthenticated, "token " + token_id(token) + " is not accepted");
      case TokenTable::Check::Expired:
        deny(ErrorCode::Unauthenticated, "token " + token_id(token) + " has expired");
      case TokenTable::Check::Accepted:
        break;
    }
    Role needed = need == Access::Client ? Role::Client : Role::Worker;
    if (who.role != Role::Admin && who.role != needed)
      deny(ErrorCode::PermissionDenied, std::string(method) + " needs a " + role_name(needed) +
                                            " or admin token; " + who.id + " is a " +
                                            role_name(who.role) + " token");
    return Caller{who.id, who.tenant, who.role == Role::Admin};
  }

 private:
  std::string file_;
  bool worker_certs_;  // mutual TLS: worker methods need a verified client certificate
  Coordinator* core_ = nullptr;
  mutable LogBudget log_budget_;
  mutable std::mutex mu_;
  std::shared_ptr<const TokenTable> table_;
};

// The PEM files of --tls-cert, --tls-key and --tls-client-ca checked with OpenSSL before gRPC
// sees them (gRPC says only "cannot listen"): certificates, a private key, and the key the
// certificate's. Throws naming the flag, the file and what is wrong.
void check_tls_files(const CoordinatorOptions& o, const std::string& cert, const std::string& key,
                     const std::string& ca) {
  auto parse_cert = [](const std::string& pem) {
    BIO* b = BIO_new_mem_buf(pem.data(), int(pem.size()));
    X509* x = b ? PEM_read_bio_X509(b, nullptr, nullptr, nullptr) : nullptr;
    BIO_free(b);
    return x;
  };
  auto looks_like_key = [](const std::string& pem) {
    return pem.find("PRIVATE KEY-----") != std::string::npos;
  };
  X509* x = parse_cert(cert);
  if (!x)
    throw std::runtime_error(
        "coordinator: --tls-cert " + o.tls_cert + " holds no PEM certificate" +
        (looks_like_key(cert) ? " but a private key: are --tls-cert and --tls-key swapped?" : ""));
  BIO* b = BIO_new_mem_buf(key.data(), int(key.size()));
  EVP_PKEY* k = b ? PEM_read_bio_PrivateKey(b, nullptr, nullptr, nullptr) : nullptr;
  BIO_free(b);
  bool matches = k && X509_check_private_key(x, k) == 1;
  X509_free(x);
  EVP_PKEY_free(k);
  ERR_clear_error();
  if (!k)
    throw std::runtime_error("coordinator: --tls-key " + o.tls_key +
                             " holds no PEM private key (an encrypted key is not read either)");
  if (!matches)
    throw std::runtime_error("coordinator: --tls-key " + o.tls_key +
                             " is not the key of the certificate in --tls-cert " + o.tls_cert);
  if (!ca.empty()) {
    X509* c = parse_cert(ca);
    if (!c)
      throw std::runtime_error("coordinator: --tls-client-ca " + o.tls_client_ca +
                               " holds no PEM certificate");
    X509_free(c);
  }
}

// TLS server credentials from the options' PEM files, or plaintext when none is given.
std::shared_ptr<grpc::ServerCredentials> server_credentials(const CoordinatorOptions& o) {
  if (o.tls_cert.empty() && o.tls_key.empty() && o.tls_client_ca.empty())
    return grpc::InsecureServerCredentials();
  if (o.tls_cert.empty() || o.tls_key.empty())
    throw std::runtime_error("coordinator: TLS needs both --tls-cert and --tls-key");
  check_tls_files(o, read_file_bytes(o.tls_cert), read_file_bytes(o.tls_key),
                  o.tls_client_ca.empty() ? "" : read_file_bytes(o.tls_client_ca));
  // Client certificates: verified when sent; the gate requires one for the worker methods.
  grpc::SslServerCredentialsOptions ssl(o.tls_client_ca.empty()
                                            ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
                                            : GRPC_SSL_REQUEST_CLIENT_CERTIFICATE_AND_VERIFY);
  if (!o.tls_client_ca.empty()) ssl.pem_root_certs = read_file_bytes(o.tls_client_ca);
  ssl.pem_key_cert_pairs.push_back({read_file_bytes(o.tls_key), read_file_bytes(o.tls_cert)});
  return grpc::SslServerCredentials(ssl);
}

// Runs a handler for its admitted caller. A refusal answers with its code; anything else
// thrown must not take the server down: it answers INTERNAL with the message.
template <class F>
Status guarded(const Gate& gate, ServerContext* ctx, Access need, const char* method, F&& f) {
  try {
    f(gate.admit(ctx, need, method));
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
  out.set_scene_version(s.scene_version);
  out.set_run(s.run);
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
  out.set_tenant(s.tenant);
  out.set_build_id(s.build_id);
  out.set_cpu_kind(s.cpu_kind);
  out.set_waiting_for(s.waiting_for);
  out.set_paused(s.paused);
  out.set_priority(s.priority);
  out.set_held_frames(frame_range_text(s.held));
  for (const FrameStatus& f : s.frames) *out.add_frames() = to_wire(f);
  *out.mutable_settings() = to_wire_overrides(s.settings);
  out.set_scene_path(s.scene_path);
  out.set_tile_size(s.tile_size);
  for (const std::string& t : s.required_tags) out.add_required_tags(t);
  out.set_ended_unix(s.ended_unix);
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

// Submit's (and RequeueJob's) stream after its first message: blobs as chunk runs, each starting
// at offset 0.
template <class Message>
void receive_blobs(Coordinator& core, grpc::ServerReaderInterface<Message>* reader,
                   const CoordinatorOptions& o, const Caller& caller) {
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
    core.put_blob(bytes, caller);
    blob.reset();
  };
  Message msg;
  while (reader->Read(&msg)) {
    if (!msg.has_blob_chunk()) bad_request("only blob chunks may follow the first message");
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
  JobServiceImpl(Coordinator& c, const CoordinatorOptions& o, const Gate& g)
      : c_(c), o_(o), g_(g) {}

  Status MissingBlobs(ServerContext* ctx, const pb::MissingBlobsRequest* r,
                      pb::MissingBlobsResponse* o) override {
    return guarded(g_, ctx, Access::Client, "MissingBlobs", [&](const Caller& caller) {
      for (std::string& d : c_.missing_blobs({r->sha256().begin(), r->sha256().end()}, caller))
        o->add_sha256(std::move(d));
    });
  }
  Status Submit(ServerContext* ctx, grpc::ServerReader<pb::SubmitRequest>* r,
                pb::SubmitResponse* o) override {
    return guarded(g_, ctx, Access::Client, "Submit", [&](const Caller& caller) {
      pb::SubmitRequest first;
      if (!r->Read(&first) || !first.has_spec())
        bad_request("the first message of Submit must be the job spec");
      receive_blobs(c_, r, o_, caller);
      o->set_job_id(c_.submit(from_wire(first.spec()), caller));
    });
  }
  // A page of jobs: at most the limit asked (100 by default, 1000 at most) and about 3 MiB, so
  // the answer stays under gRPC's 4 MiB message limit whatever the jobs hold.
  Status ListJobs(ServerContext* ctx, const pb::ListJobsRequest* r,
                  pb::ListJobsResponse* o) override {
    return guarded(g_, ctx, Access::Client, "ListJobs", [&](const Caller& caller) {
      size_t limit = r->limit() == 0 ? 100 : std::min<size_t>(r->limit(), 1000);
      bool more = false;
      std::vector<JobStatus> page = c_.list(caller, limit, r->after(), &more);
      size_t bytes = 0;
      for (size_t i = 0; i < page.size(); ++i) {
        pb::JobStatus s = to_wire(page[i]);
        bytes += s.ByteSizeLong();
        if (i > 0 && bytes > (3u << 20)) {
          more = true;
          break;
        }
        *o->add_jobs() = std::move(s);
      }
      if (more && o->jobs_size() > 0) o->set_next_after(o->jobs(o->jobs_size() - 1).job_id());
    });
  }
  Status GetJob(ServerContext* ctx, const pb::JobRef* r, pb::JobStatus* o) override {
    return guarded(g_, ctx, Access::Client, "GetJob",
                   [&](const Caller& caller) { *o = to_wire(c_.status(r->job_id(), caller)); });
  }
  // A message at every change, until the job ends or the client goes.
  Status WatchJob(ServerContext* ctx, const pb::JobRef* r,
                  grpc::ServerWriter<pb::JobStatus>* w) override {
    return guarded(g_, ctx, Access::Client, "WatchJob", [&](const Caller& caller) {
      uint64_t seen = 0;
      while (!ctx->IsCancelled()) {
        std::optional<JobStatus> s = c_.next_status(r->job_id(), seen, 1.0, caller);
        if (!s) continue;
        if (!w->Write(to_wire(*s)) || terminal(s->state)) return;
      }
    });
  }
  Status CancelJob(ServerContext* ctx, const pb::JobRef* r, pb::CancelResponse*) override {
    return guarded(g_, ctx, Access::Client, "CancelJob",
                   [&](const Caller& caller) { c_.cancel(r->job_id(), caller); });
  }
  Status PauseJob(ServerContext* ctx, const pb::JobRef* r, pb::JobStatus* o) override {
    return guarded(g_, ctx, Access::Client, "PauseJob", [&](const Caller& caller) {
      c_.set_paused(r->job_id(), true, caller);
      *o = to_wire(c_.status(r->job_id(), caller));
    });
  }
  Status ResumeJob(ServerContext* ctx, const pb::JobRef* r, pb::JobStatus* o) override {
    return guarded(g_, ctx, Access::Client, "ResumeJob", [&](const Caller& caller) {
      c_.set_paused(r->job_id(), false, caller);
      *o = to_wire(c_.status(r->job_id(), caller));
    });
  }
  Status SetJobPriority(ServerContext* ctx, const pb::SetPriorityRequest* r,
                        pb::JobStatus* o) override {
    return guarded(g_, ctx, Access::Client, "SetJobPriority", [&](const Caller& caller) {
      c_.set_priority(r->job_id(), r->priority(), caller);
      *o = to_wire(c_.status(r->job_id(), caller));
    });
  }
  Status RetryJob(ServerContext* ctx, const pb::RetryRequest* r, pb::JobStatus* o) override {
    return guarded(g_, ctx, Access::Client, "RetryJob", [&](const Caller& caller) {
      c_.retry(r->job_id(), r->frames(), caller);
      *o = to_wire(c_.status(r->job_id(), caller));
    });
  }
  Status RequeueJob(ServerContext* ctx, grpc::ServerReader<pb::RequeueMessage>* r,
                    pb::JobStatus* o) override {
    return guarded(g_, ctx, Access::Client, "RequeueJob", [&](const Caller& caller) {
      pb::RequeueMessage first;
      if (!r->Read(&first) || !first.has_request())
        bad_request("the first message of RequeueJob must be the request");
      const pb::RequeueRequest& q = first.request();
      // The job is checked before any blob is stored: no upload for another tenant's job.
      (void)c_.status(q.job_id(), caller);
      receive_blobs(c_, r, o_, caller);
      std::optional<SceneVersion> scene;
      if (!q.scene_path().empty())
        scene = SceneVersion{q.scene_path(), from_wire(q.files()), ""};
      else if (q.files_size() > 0)
        bad_request("files without a scene_path: name the scene file in the bundle");
      c_.requeue(q.job_id(), q.frames(), scene, q.request_id(), caller);
      *o = to_wire(c_.status(q.job_id(), caller));
    });
  }
  Status DeleteJob(ServerContext* ctx, const pb::DeleteRequest* r, pb::DeleteResponse*) override {
    return guarded(g_, ctx, Access::Client, "DeleteJob",
                   [&](const Caller& caller) { c_.delete_job(r->job_id(), r->force(), caller); });
  }
  Status GetTaskLog(ServerContext* ctx, const pb::TaskLogRequest* r,
                    pb::TaskLogResponse* o) override {
    return guarded(g_, ctx, Access::Client, "GetTaskLog", [&](const Caller& caller) {
      std::optional<FrameNumber> frame;
      if (r->has_frame()) frame = r->frame();
      TaskLog log = c_.task_log(r->job_id(), frame, r->task_id(), r->limit(), caller);
      for (const TaskAttempt& a : log.attempts) {
        pb::TaskAttempt* p = o->add_attempts();
        p->set_task_id(task_id_text({a.job_id, a.frame, a.pass, a.tile}));
        p->set_worker_id(a.worker_id);
        p->set_lease_id(a.lease_id);
        p->set_started_unix(a.started_unix);
        p->set_ended_unix(a.ended_unix);
        p->set_outcome(attempt_outcome_name(a.outcome));
        p->set_message(a.message);
        for (const std::string& l : a.log) p->add_log(l);
      }
      o->set_more(log.more);
    });
  }
  Status ListWorkers(ServerContext* ctx, const pb::ListWorkersRequest*,
                     pb::ListWorkersResponse* o) override {
    return guarded(g_, ctx, Access::Client, "ListWorkers", [&](const Caller& caller) {
      for (const WorkerStatus& w : c_.workers(caller)) {
        pb::WorkerStatus* p = o->add_workers();
        p->set_worker_id(w.worker_id);
        p->set_hostname(w.info.hostname);
        p->set_cores(w.info.cores);
        p->set_build_id(w.info.build_id);
        p->set_isa(w.info.isa);
        for (const std::string& t : w.info.tags) p->add_tags(t);
        for (const std::string& t : w.tasks) p->add_tasks(t);
        p->set_failures(uint32_t(w.failures));
        p->set_seconds_since_contact(w.seconds_since_contact);
        p->set_refused(w.refused);
        p->set_principal(w.principal);
      }
    });
  }
  Status FetchFrame(ServerContext* ctx, const pb::FetchRequest* r,
                    grpc::ServerWriter<pb::FetchResponse>* w) override {
    return guarded(g_, ctx, Access::Client, "FetchFrame", [&](const Caller& caller) {
      FrameImage image = c_.fetch(r->job_id(), r->frame(), caller);
      auto message = [&](pb::Chunk&& c, bool first) {
        pb::FetchResponse m;
        *m.mutable_chunk() = std::move(c);
        if (first) *m.mutable_status() = to_wire(image.status);
        return m;
      };
      if (!image.file) {
        write_chunks(w, image.buffer, message);
        return;
      }
      // A frame kept in tiles: its checkpoint read and sent a chunk at a time, without a
      // SHA-256 (it would take a pass over the file first; the .rfb carries its own checksum,
      // which the client checks).
      for (uint64_t at = 0; at < image.file->size;) {  // an .rfb is never empty
        pb::Chunk c;
        const size_t n = size_t(std::min<uint64_t>(kChunkBytes, image.file->size - at));
        std::string data(n, '\0');
        if (!pread_full(image.file->fd, data.data(), n, at))
          throw CoordinatorError(ErrorCode::Unavailable, "cannot read the frame's checkpoint: " +
                                                             std::string(std::strerror(errno)));
        c.set_offset(at);
        if (at == 0) c.set_total_size(image.file->size);
        c.set_data(std::move(data));
        if (!w->Write(message(std::move(c), at == 0))) return;
        at += n;
      }
    });
  }

 private:
  Coordinator& c_;
  const CoordinatorOptions& o_;
  const Gate& g_;
};

class WorkerServiceImpl final : public pb::WorkerService::Service {
 public:
  WorkerServiceImpl(Coordinator& c, const CoordinatorOptions& o, const Gate& g)
      : c_(c), o_(o), g_(g) {}

  Status Register(ServerContext* ctx, const pb::RegisterRequest* r,
                  pb::RegisterResponse* o) override {
    return guarded(g_, ctx, Access::Worker, "Register", [&](const Caller& caller) {
      Registration reg = c_.register_worker({r->hostname(),
                                             r->cores(),
                                             r->build_id(),
                                             r->isa(),
                                             {r->tags().begin(), r->tags().end()}},
                                            caller);
      o->set_worker_id(reg.worker_id);
      o->set_lease_seconds(reg.lease_seconds);
      o->set_keepalive_seconds(reg.keepalive_seconds);
      o->set_max_results_per_upload(Coordinator::kMaxResultsPerUpload);
      o->set_max_upload_bytes(kMaxUploadBytes);
    });
  }
  Status LeaseTask(ServerContext* ctx, const pb::LeaseRequest* r, pb::LeaseResponse* o) override {
    return guarded(g_, ctx, Access::Worker, "LeaseTask", [&](const Caller& caller) {
      LeaseResult l = c_.lease(r->worker_id(), caller, r->max_tasks());
      if (l.task)
        to_wire(*l.task, o->mutable_task());
      for (const TaskAssignment& a : l.more) to_wire(a, o->add_more());
      if (!l.task) o->set_no_more_work(l.no_more_work);
    });
  }
  Status RenewLease(ServerContext* ctx, const pb::RenewRequest* r, pb::RenewResponse* o) override {
    return guarded(g_, ctx, Access::Worker, "RenewLease", [&](const Caller& caller) {
      o->set_lease_seconds(c_.renew(r->worker_id(), r->lease_id(), caller));
    });
  }
  Status FetchBlob(ServerContext* ctx, const pb::BlobRequest* r,
                   grpc::ServerWriter<pb::Chunk>* w) override {
    return guarded(g_, ctx, Access::Worker, "FetchBlob", [&](const Caller& caller) {
      write_chunks(w, c_.blob(r->sha256(), caller),
                   [](pb::Chunk&& c, bool) { return std::move(c); });
    });
  }
  // A header, then the sample buffer in chunks; in a batched upload the next header and chunks
  // after them. Each header is checked (job, task, lease held by this caller's worker) before a
  // byte of its buffer is read. One result is answered as before: a refusal is the call's
  // status. Several are answered one by one in `results` (a refusal is that result's), once one
  // flush made them all durable (Coordinator::complete_batch).
  Status CompleteTask(ServerContext* ctx, grpc::ServerReader<pb::CompleteRequest>* r,
                      pb::CompleteResponse* o) override {
    return guarded(g_, ctx, Access::Worker, "CompleteTask", [&](const Caller& caller) {
      pb::CompleteRequest msg;
      if (!r->Read(&msg) || !msg.has_header())
        bad_request("the first message of CompleteTask must be the header");
      const std::string worker = msg.header().worker_id();
      const uint32_t count = std::max(1u, msg.header().results());
      if (count > Coordinator::kMaxResultsPerUpload)
        bad_request("an upload carries at most " +
                    std::to_string(Coordinator::kMaxResultsPerUpload) + " results, not " +
                    std::to_string(count));
      const bool single = count == 1;
      std::optional<UploadSlot> slot;
      // Each result's answer so far (an error, or "not needed"), and what goes on to the core.
      struct Received {
        std::optional<CoordinatorError> error;
        bool read = false;  // its buffer is in `results`
      };
      std::vector<Received> received;
      std::vector<TaskResult> results;
      uint64_t bytes = 0;
      bool more = true;  // msg holds the next header
      while (more) {
        const pb::CompleteHeader header = msg.header();
        more = false;
        if (received.size() == count)
          bad_request("the upload announced " + std::to_string(count) + " results and sent more");
        if (header.worker_id() != worker)
          bad_request("the results of one upload must all be of worker " + worker.substr(0, 64));
        std::optional<TaskRef> task = parse_task_id(header.task_id());
        if (!task) bad_request("task_id '" + header.task_id().substr(0, 64) + "' is malformed");
        Received& got = received.emplace_back();
        bool wanted = false;
        try {
          wanted = c_.check_upload(header.worker_id(), header.lease_id(), *task, caller);
        } catch (const CoordinatorError& e) {
          if (single) throw;  // answered as the call's status, without reading on
          got.error = e;
        }
        if (single && !wanted && !got.error) {
          o->set_accepted(false);  // the task needs nothing more: answered without reading on
          return;
        }
        if (wanted && !slot) slot.emplace(*this, worker);
        // The buffer's chunks, up to the next header or the end; a result not wanted (settled,
        // refused) has its chunks read past.
        const uint64_t limit = single ? o_.max_buffer_bytes : kMaxUploadBytes - bytes;
        ChunkAssembler chunks(limit, ChunkAssembler::Digest::Optional);
        std::optional<CoordinatorError> broken;
        while (r->Read(&msg)) {
          if (msg.has_header() && !single) {
            more = true;
            break;
          }
          if (!msg.has_chunk()) bad_request("only chunks may follow the header");
          if (!wanted || broken) continue;
          try {
            check_chunks(chunks.add(msg.chunk()), "sample buffer", chunks);
          } catch (const CoordinatorError& e) {
            broken = e;
          }
        }
        if (!wanted) continue;
        if (!broken) try {
            check_chunks(chunks.finish(), "sample buffer", chunks);
          } catch (const CoordinatorError& e) {
            broken = e;
          }
        if (broken) {
          c_.refuse_upload(header.worker_id(), header.lease_id(), *task, broken->what(),
                           {header.log().begin(), header.log().end()});
          if (single) throw *broken;
          got.error = broken;
          continue;
        }
        std::string buffer = chunks.take();
        bytes += buffer.size();
        got.read = true;
        results.push_back({header.worker_id(), header.lease_id(), std::move(*task),
                           std::move(buffer),
                           bounded_log({header.log().begin(), header.log().end()})});
      }
      if (single) {  // one result: as before batches
        o->set_accepted(received[0].read && c_.complete(std::move(results[0]), caller));
        return;
      }
      if (received.size() != count)
        bad_request("the upload announced " + std::to_string(count) + " results and sent " +
                    std::to_string(received.size()));
      std::vector<Coordinator::ResultOutcome> outcomes =
          c_.complete_batch(std::move(results), caller);
      size_t next = 0;
      for (const Received& got : received) {
        pb::ResultOutcome* out = o->add_results();
        std::optional<CoordinatorError> error = got.error;
        if (got.read) {
          const Coordinator::ResultOutcome& done = outcomes[next++];
          error = done.error;
          out->set_accepted(done.accepted);
        }
        if (error) {
          out->set_code(int32_t(grpc_code(error->code)));
          out->set_message(error->what());
        }
      }
      o->set_accepted(o->results(0).accepted());
    });
  }
  Status FailTask(ServerContext* ctx, const pb::FailRequest* r, pb::FailResponse*) override {
    return guarded(g_, ctx, Access::Worker, "FailTask", [&](const Caller& caller) {
      c_.fail({r->worker_id(),
               r->lease_id(),
               r->message(),
               r->handed_back(),
               {r->log().begin(), r->log().end()}},
              caller);
    });
  }

 private:
  // One of a worker's concurrent uploads (a worker sends one at a time, two while retrying);
  // refused with RESOURCE_EXHAUSTED over kUploadsPerWorker, so one worker id cannot hold many
  // buffers in memory at once.
  static constexpr int kUploadsPerWorker = 2;
  // A batched upload's results together (one result alone may be up to max_buffer_bytes).
  static constexpr uint64_t kMaxUploadBytes = uint64_t(64) << 20;
  class UploadSlot {
   public:
    UploadSlot(WorkerServiceImpl& s, const std::string& worker) : s_(s), worker_(worker) {
      std::lock_guard lock(s_.uploads_mu_);
      if (s_.uploads_[worker_] >= kUploadsPerWorker)
        throw CoordinatorError(ErrorCode::ResourceExhausted, "worker " + worker_ + " already has " +
                                                                 std::to_string(kUploadsPerWorker) +
                                                                 " uploads in flight");
      ++s_.uploads_[worker_];
    }
    ~UploadSlot() {
      std::lock_guard lock(s_.uploads_mu_);
      if (--s_.uploads_[worker_] == 0) s_.uploads_.erase(worker_);
    }

   private:
    WorkerServiceImpl& s_;
    std::string worker_;
  };

  Coordinator& c_;
  const CoordinatorOptions& o_;
  const Gate& g_;
  std::mutex uploads_mu_;
  std::map<std::string, int> uploads_;
};

}  // namespace

struct CoordinatorServer::Impl {
  CoordinatorOptions options;
  std::unique_ptr<Gate> gate;
  std::unique_ptr<Coordinator> core;
  std::unique_ptr<JobServiceImpl> jobs;
  std::unique_ptr<WorkerServiceImpl> workers;
  std::unique_ptr<grpc::Server> server;
  std::unique_ptr<grpc::Server> health_server;  // --health-listen: the health service alone
  std::unique_ptr<MetricsServer> metrics;       // --metrics-listen; goes before the core
  std::unique_ptr<Monitor> monitor;             // --monitor-listen; goes before the core
  int port = 0, health_port = 0;
  // Retention (Coordinator::collect) at start and then every interval, until shutdown.
  std::thread retention;
  std::mutex retention_mu;
  std::condition_variable retention_cv;
  bool stopping = false;
};

CoordinatorServer::CoordinatorServer(const CoordinatorOptions& o)
    : impl_(std::make_unique<Impl>()) {
  if (o.state_dir.empty()) throw std::runtime_error("coordinator: --state-dir is required");
  if (o.token_file.empty() && !loopback_listen(o.listen))
    throw std::runtime_error(
        "coordinator: refusing to listen on " + o.listen +
        " without --token-file: anyone who reaches it could submit, cancel and upload results. "
        "Give --token-file (docs/security.md) or listen on a loopback address (127.0.0.1:PORT)");
  impl_->options = o;
  impl_->gate = std::make_unique<Gate>(o.token_file, !o.tls_client_ca.empty());
  CoreOptions core;
  core.state_dir = o.state_dir;
  core.lease_seconds = o.lease_seconds;
  core.window_frames = o.window_frames;
  core.share = o.share;
  core.limits = o.limits;
  core.verify_fraction = o.verify_fraction;
  core.keep_finished_seconds = o.keep_finished_seconds;
  core.frame_memory = o.frame_memory;
  core.blob_grace_seconds = o.blob_grace_seconds;
  core.scene_checker = child_scene_checker(o.scene_check_binary, o.limits.scene_check);
  impl_->core = std::make_unique<Coordinator>(core);
  impl_->gate->count_in(impl_->core.get());
  impl_->jobs = std::make_unique<JobServiceImpl>(*impl_->core, impl_->options, *impl_->gate);
  impl_->workers = std::make_unique<WorkerServiceImpl>(*impl_->core, impl_->options, *impl_->gate);
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder b;
  b.AddListeningPort(o.listen, server_credentials(o), &impl_->port);
  b.RegisterService(impl_->jobs.get());
  b.RegisterService(impl_->workers.get());
  // Workers ping every keepalive_seconds (a third of the lease); allow it.
  int min_ping_ms = int(std::max(1.0, o.lease_seconds / 3) * 1000 / 2);
  b.AddChannelArgument(GRPC_ARG_HTTP2_MIN_RECV_PING_INTERVAL_WITHOUT_DATA_MS, min_ping_ms);
  b.AddChannelArgument(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  // A second coordinator on the same port must fail to bind, not share the port's clients.
  b.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  // Connections that never finish their handshake, that sit idle, or whose peer is gone (a
  // half-open TCP connection): closed, so they cannot pile up (docs/security.md).
  b.AddChannelArgument(GRPC_ARG_SERVER_HANDSHAKE_TIMEOUT_MS, 10 * 1000);
  b.AddChannelArgument(GRPC_ARG_MAX_CONNECTION_IDLE_MS, 5 * 60 * 1000);
  b.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIME_MS, 60 * 1000);
  b.AddChannelArgument(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, 20 * 1000);
  impl_->server = b.BuildAndStart();
  if (!impl_->server || impl_->port == 0)
    throw std::runtime_error("coordinator: cannot listen on " + o.listen);
  if (!o.health_listen.empty()) {
    grpc::ServerBuilder hb;  // no services of ours: the default health service alone
    hb.AddListeningPort(o.health_listen, grpc::InsecureServerCredentials(), &impl_->health_port);
    hb.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
    impl_->health_server = hb.BuildAndStart();
    if (!impl_->health_server || impl_->health_port == 0)
      throw std::runtime_error("coordinator: cannot listen on --health-listen " + o.health_listen);
  }
  // "rayfarm.storage": SERVING while results can be stored, NOT_SERVING while they cannot
  // (disk full, unwritable state). The overall status ("") stays SERVING: the coordinator still
  // leases, answers and holds results back until it can store them; restarting it would not help.
  auto set_storage = [impl = impl_.get()](const std::string& problem) {
    for (grpc::Server* s : {impl->server.get(), impl->health_server.get()})
      if (s && s->GetHealthCheckService())
        s->GetHealthCheckService()->SetServingStatus("rayfarm.storage", problem.empty());
  };
  set_storage("");
  impl_->core->set_storage_listener(set_storage);
  if (!o.metrics_listen.empty())
    impl_->metrics = std::make_unique<MetricsServer>(o.metrics_listen, *impl_->core);
  if (!o.monitor_listen.empty()) {
    MonitorOptions mo;
    mo.listen = o.monitor_listen;
    mo.tls_cert = o.tls_cert;
    mo.tls_key = o.tls_key;
    mo.open = impl_->gate->open();
    impl_->monitor = std::make_unique<Monitor>(
        *impl_->core, mo, [gate = impl_->gate.get()](const std::string& token, std::string* why) {
          return gate->principal(token, why);
        });
  }
  // Often enough that nothing outstays its time by more than a quarter of it (at most a minute).
  const double keep = o.keep_finished_seconds > 0 ? o.keep_finished_seconds : 1e9;
  const double interval = std::clamp(std::min(keep, o.blob_grace_seconds) / 4, 1.0, 60.0);
  impl_->retention = std::thread([impl = impl_.get(), interval] {
    std::unique_lock lock(impl->retention_mu);
    while (!impl->stopping) {
      lock.unlock();
      try {
        impl->core->collect(
            std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch())
                .count());
      } catch (const std::exception& e) {  // the next pass tries again
        spdlog::warn("retention: {}", e.what());
      }
      lock.lock();
      impl->retention_cv.wait_for(lock, std::chrono::duration<double>(interval),
                                  [impl] { return impl->stopping; });
    }
  });
}

CoordinatorServer::~CoordinatorServer() { shutdown(); }

int CoordinatorServer::port() const { return impl_->port; }

int CoordinatorServer::health_port() const { return impl_->health_port; }

int CoordinatorServer::metrics_port() const { return impl_->metrics ? impl_->metrics->port() : 0; }

int CoordinatorServer::monitor_port() const { return impl_->monitor ? impl_->monitor->port() : 0; }

void CoordinatorServer::reload_tokens() {
  impl_->gate->reload();
  if (impl_->monitor) impl_->monitor->revoke_sessions();
}

void CoordinatorServer::wait() { impl_->server->Wait(); }

void CoordinatorServer::shutdown() {
  if (!impl_ || !impl_->server) return;
  {
    std::lock_guard lock(impl_->retention_mu);
    impl_->stopping = true;
  }
  impl_->retention_cv.notify_all();
  if (impl_->retention.joinable()) impl_->retention.join();
  impl_->core->shut_down();
  impl_->server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(5));
  if (impl_->health_server) impl_->health_server->Shutdown();
}

int run_coordinator(const CoordinatorOptions& o) {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGHUP);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);  // before gRPC starts its threads
  // A file size limit (ulimit -f) reached is a write error (EFBIG) to report, not a reason to die.
  ::signal(SIGXFSZ, SIG_IGN);
  keep_heap_for_sample_buffers();  // results arrive and are freed all day
  std::unique_ptr<CoordinatorServer> started;
  try {
    started = std::make_unique<CoordinatorServer>(o);
  } catch (const StoreDamaged& e) {
    spdlog::critical("{}", e.what());
    return kStoreDamagedExit;
  }
  CoordinatorServer& server = *started;
  spdlog::info("coordinator listening on {} (port {}), state in {}, {}", o.listen, server.port(),
               o.state_dir,
               o.token_file.empty() ? std::string("no token file: loopback only, no authentication")
                                    : "tokens from " + o.token_file);
  spdlog::info("transport: {}{}", o.tls_cert.empty() ? "plaintext" : "TLS",
               o.tls_client_ca.empty() ? "" : ", client certificates required for workers");
  if (!o.health_listen.empty())
    spdlog::info("health service alone, plaintext, on {} (health port {})", o.health_listen,
                 server.health_port());
  if (!o.metrics_listen.empty())
    spdlog::info("Prometheus metrics on http://{}/metrics (metrics port {})", o.metrics_listen,
                 server.metrics_port());
  if (!o.monitor_listen.empty())
    spdlog::info("web monitor on {}://{}/ (monitor port {})", o.tls_cert.empty() ? "http" : "https",
                 o.monitor_listen, server.monitor_port());
  int sig = 0;
  for (;;) {
    sigwait(&set, &sig);
    if (sig != SIGHUP) break;
    try {
      server.reload_tokens();
      spdlog::info("SIGHUP: token file {} re-read; monitor sessions ended", o.token_file);
    } catch (const std::exception& e) {
      spdlog::error("SIGHUP: {}; keeping the tokens read before", e.what());
    }
  }
  spdlog::info("signal {}: shutting down", sig);
  server.shutdown();
  return 0;
}

}  // namespace rf
