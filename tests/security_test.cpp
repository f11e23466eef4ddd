// The coordinator against a hostile client (docs/security.md), with real processes on loopback:
// tokens, roles and tenants on every method, the token file re-read on SIGHUP, uploads accepted
// only from the worker holding the lease (checked before a byte of the upload is buffered),
// loopback-only without tokens, one coordinator per state directory and per port. Each farm image
// is still compared with the local render of the same job.
#include <google/protobuf/descriptor.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <thread>

#include "engine/digest.h"
#include "farm/auth.h"
#include "farm/channel.h"
#include "farm/probe.h"
#include "proto/rayfarm.grpc.pb.h"
#include "tests/support/farm.h"

namespace rf {
namespace {

namespace pb = rayfarm::v1;
using test::Farm;
using test::make_token;
using test::Token;
using test::write_token_file;

const std::string kJob = "scenes/cornell-box/scene.json --spp 8 --passes 4 --res 32x32";

// Calls every method of both services once on `channel`, with requests that are harmless when
// admitted, and returns each one's status code.
std::map<std::string, grpc::StatusCode> call_every_method(std::shared_ptr<grpc::Channel> channel) {
  auto jobs = pb::JobService::NewStub(channel);
  auto workers = pb::WorkerService::NewStub(channel);
  std::map<std::string, grpc::StatusCode> out;
  auto unary = [&](const std::string& name, auto&& call) {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    out[name] = call(ctx).error_code();
  };
  pb::JobRef ref;
  ref.set_job_id("j999999");
  unary("MissingBlobs", [&](grpc::ClientContext& c) {
    pb::MissingBlobsResponse r;
    return jobs->MissingBlobs(&c, pb::MissingBlobsRequest{}, &r);
  });
  unary("Submit", [&](grpc::ClientContext& c) {
    pb::SubmitResponse r;
    auto w = jobs->Submit(&c, &r);
    w->WritesDone();
    return w->Finish();
  });
  unary("ListJobs", [&](grpc::ClientContext& c) {
    pb::ListJobsResponse r;
    return jobs->ListJobs(&c, pb::ListJobsRequest{}, &r);
  });
  unary("GetJob", [&](grpc::ClientContext& c) {
    pb::JobStatus r;
    return jobs->GetJob(&c, ref, &r);
  });
  unary("WatchJob", [&](grpc::ClientContext& c) {
    auto rd = jobs->WatchJob(&c, ref);
    pb::JobStatus m;
    while (rd->Read(&m)) {
    }
    return rd->Finish();
  });
  unary("CancelJob", [&](grpc::ClientContext& c) {
    pb::CancelResponse r;
    return jobs->CancelJob(&c, ref, &r);
  });
  unary("PauseJob", [&](grpc::ClientContext& c) {
    pb::JobStatus r;
    return jobs->PauseJob(&c, ref, &r);
  });
  unary("ResumeJob", [&](grpc::ClientContext& c) {
    pb::JobStatus r;
    return jobs->ResumeJob(&c, ref, &r);
  });
  unary("SetJobPriority", [&](grpc::ClientContext& c) {
    pb::SetPriorityRequest req;
    req.set_job_id("j999999");
    pb::JobStatus r;
    return jobs->SetJobPriority(&c, req, &r);
  });
  unary("RetryJob", [&](grpc::ClientContext& c) {
    pb::RetryRequest req;
    req.set_job_id("j999999");
    pb::JobStatus r;
    return jobs->RetryJob(&c, req, &r);
  });
  unary("RequeueJob", [&](grpc::ClientContext& c) {
    pb::JobStatus r;
    auto w = jobs->RequeueJob(&c, &r);
    pb::RequeueMessage m;
    m.mutable_request()->set_job_id("j999999");
    m.mutable_request()->set_frames("0");
    w->Write(m);
    w->WritesDone();
    return w->Finish();
  });
  unary("DeleteJob", [&](grpc::ClientContext& c) {
    pb::DeleteRequest req;
    req.set_job_id("j999999");
    pb::DeleteResponse r;
    return jobs->DeleteJob(&c, req, &r);
  });
  unary("GetTaskLog", [&](grpc::ClientContext& c) {
    pb::TaskLogRequest req;
    req.set_job_id("j999999");
    pb::TaskLogResponse r;
    return jobs->GetTaskLog(&c, req, &r);
  });
  unary("ListWorkers", [&](grpc::ClientContext& c) {
    pb::ListWorkersResponse r;
    return jobs->ListWorkers(&c, pb::ListWorkersRequest{}, &r);
  });
  unary("FetchFrame", [&](grpc::ClientContext& c) {
    pb::FetchRequest req;
    req.set_job_id("j999999");
    auto rd = jobs->FetchFrame(&c, req);
    pb::FetchResponse m;
    while (rd->Read(&m)) {
    }
    return rd->Finish();
  });
  unary("Register", [&](grpc::ClientContext& c) {
    pb::RegisterRequest req;
    req.set_hostname("probe");
    pb::RegisterResponse r;
    return workers->Register(&c, req, &r);
  });
  unary("LeaseTask", [&](grpc::ClientContext& c) {
    pb::LeaseRequest req;
    req.set_worker_id("invented");
    pb::LeaseResponse r;
    return workers->LeaseTask(&c, req, &r);
  });
  unary("RenewLease", [&](grpc::ClientContext& c) {
    pb::RenewRequest req;
    req.set_worker_id("invented");
    req.set_lease_id("invented");
    pb::RenewResponse r;
    return workers->RenewLease(&c, req, &r);
  });
  unary("FetchBlob", [&](grpc::ClientContext& c) {
    pb::BlobRequest req;
    req.set_sha256(std::string(64, 'a'));
    auto rd = workers->FetchBlob(&c, req);
    pb::Chunk m;
    while (rd->Read(&m)) {
    }
    return rd->Finish();
  });
  unary("CompleteTask", [&](grpc::ClientContext& c) {
    pb::CompleteResponse r;
    auto w = workers->CompleteTask(&c, &r);
    pb::CompleteRequest head;
    head.mutable_header()->set_worker_id("invented");
    head.mutable_header()->set_task_id("j999999/1/0/0");
    w->Write(head);
    w->WritesDone();
    return w->Finish();
  });
  unary("FailTask", [&](grpc::ClientContext& c) {
    pb::FailRequest req;
    req.set_worker_id("invented");
    pb::FailResponse r;
    return workers->FailTask(&c, req, &r);
  });
  // Every method the schema has is called above: one added to the proto without a call here
  // fails this.
  size_t methods = 0;
  for (const char* service : {"rayfarm.v1.JobService", "rayfarm.v1.WorkerService"})
    methods += google::protobuf::DescriptorPool::generated_pool()
                   ->FindServiceByName(service)
                   ->method_count();
  EXPECT_EQ(out.size(), methods);
  return out;
}

const std::set<std::string> kWorkerMethods = {"Register",  "LeaseTask",    "RenewLease",
                                              "FetchBlob", "CompleteTask", "FailTask"};

// Every method of both services asks for a token of the right role: none, an unknown one and an
// expired one are UNAUTHENTICATED; a client token on a worker method and a worker token on a job
// method are PERMISSION_DENIED; an admin passes everywhere. The health service stays open. A
// client sees its tenant's jobs only; the job it submits renders on a worker (worker token) to
// the local image. SIGHUP re-reads the file: a token added is accepted, one removed is refused.
// No token appears in the coordinator's log.
TEST(Security, TokensRolesAndTenantsAreCheckedOnEveryMethod) {
  std::string dir = test::make_temp_dir("security-tokens");
  Token shot1 = make_token(dir, "shot1", "--role client --tenant shot1");
  Token shot2 = make_token(dir, "shot2", "--role client --tenant shot2");
  Token worker = make_token(dir, "worker", "--role worker --tenant farm");
  Token admin = make_token(dir, "admin", "--role admin --tenant ops");
  // `token new` refuses a date in the past; a token file can still hold one (written by hand,
  // or a token that has since run out).
  Token expired = make_token(dir, "expired", "--role admin --tenant ops --expires 2099-01-01");
  EXPECT_NE(expired.line.find("expires=2099-01-01T00:00:00Z"), std::string::npos) << expired.line;
  expired.line.replace(expired.line.find("2099"), 4, "2020");
  Token later = make_token(dir, "later", "--role client --tenant shot3");
  test::CommandResult past =
      test::run_command(test::rayfarm_binary() + " token new --role client --expires 2000-01-01");
  EXPECT_EQ(past.exit_code, 2) << past.output;
  EXPECT_NE(past.output.find("is in the past"), std::string::npos) << past.output;
  std::string tokens = dir + "/tokens";
  write_token_file(tokens, {&shot1, &shot2, &worker, &admin, &expired});
  Farm farm("security-farm", 30, tokens);
  farm.client_token_file = shot1.file;
  farm.worker_token_file = worker.file;

  for (const std::string& t :
       {std::string(), std::string("rft_") + std::string(64, '0'), expired.token}) {
    for (auto& [method, code] : call_every_method(farm.channel(t)))
      EXPECT_EQ(code, grpc::StatusCode::UNAUTHENTICATED) << method << " with token '" << t << "'";
  }
  for (auto& [method, code] : call_every_method(farm.channel(shot1.token))) {
    if (kWorkerMethods.count(method))
      EXPECT_EQ(code, grpc::StatusCode::PERMISSION_DENIED) << method << " with a client token";
    else
      EXPECT_NE(code, grpc::StatusCode::PERMISSION_DENIED) << method << " with a client token";
  }
  for (auto& [method, code] : call_every_method(farm.channel(worker.token))) {
    if (kWorkerMethods.count(method))
      EXPECT_NE(code, grpc::StatusCode::PERMISSION_DENIED) << method << " with a worker token";
    else
      EXPECT_EQ(code, grpc::StatusCode::PERMISSION_DENIED) << method << " with a worker token";
  }
  for (auto& [method, code] : call_every_method(farm.channel(admin.token))) {
    EXPECT_NE(code, grpc::StatusCode::UNAUTHENTICATED) << method << " with an admin token";
    EXPECT_NE(code, grpc::StatusCode::PERMISSION_DENIED) << method << " with an admin token";
  }
  EXPECT_EQ(check_health(farm.address()), "SERVING") << "probes carry no token";
  test::CommandResult none =
      test::run_command(test::rayfarm_binary() + " status --coordinator " + farm.address());
  EXPECT_NE(none.exit_code, 0);
  EXPECT_NE(none.output.find("UNAUTHENTICATED"), std::string::npos) << none.output;

  std::string job = farm.submit(kJob + " --frames 1");
  farm.worker();
  EXPECT_EQ(farm.client("watch " + job).exit_code, 0);
  ASSERT_EQ(farm.client("fetch " + job + " -o " + farm.dir() + "/out-" + job).exit_code, 0);
  test::expect_same_image(farm.fetched(job, 1), farm.local(kJob, 1));
  EXPECT_EQ(farm.status(job)["tenant"], "shot1");

  auto as = [&](const Token& t, const std::string& args) {
    return test::run_command(test::rayfarm_binary() + " " + args + " --coordinator " +
                             farm.address() + " --token-file " + t.file);
  };
  test::CommandResult other = as(shot2, "status " + job);
  EXPECT_NE(other.exit_code, 0);
  EXPECT_NE(other.output.find("NOT_FOUND"), std::string::npos) << other.output;  // as a missing id
  EXPECT_NE(as(shot2, "fetch " + job + " -o " + dir + "/stolen").exit_code, 0);
  EXPECT_NE(as(shot2, "watch " + job).exit_code, 0);
  // Another tenant's job operations are NOT_FOUND too (exit 2, as an unknown job id); the
  // owner's on an ended job are FAILED_PRECONDITION (exit 1).
  for (const std::string& op :
       {"pause " + job, "resume " + job, "cancel " + job, "priority " + job + " 5", "retry " + job,
        "delete " + job, "logs " + job, "requeue " + job + " --frames 1"}) {
    test::CommandResult r = as(shot2, op);
    EXPECT_EQ(r.exit_code, 2) << op << ": " << r.output;
    EXPECT_NE(r.output.find("NOT_FOUND"), std::string::npos) << op << ": " << r.output;
    if (op.rfind("cancel", 0) == 0 || op.rfind("delete", 0) == 0 || op.rfind("logs", 0) == 0 ||
        op.rfind("requeue", 0) == 0)
      continue;  // the owner may
    r = as(shot1, op);
    EXPECT_EQ(r.exit_code, 1) << op << ": " << r.output;
    EXPECT_NE(r.output.find("FAILED_PRECONDITION"), std::string::npos) << op << ": " << r.output;
  }
  EXPECT_EQ(as(shot2, "status").output.find(job), std::string::npos) << "listed to another tenant";
  EXPECT_NE(as(admin, "status").output.find(job), std::string::npos) << "an admin sees all";

  // SIGHUP: `later` is accepted once added, shot2 refused once removed.
  EXPECT_EQ(call_every_method(farm.channel(later.token))["ListJobs"],
            grpc::StatusCode::UNAUTHENTICATED);
  write_token_file(tokens, {&shot1, &worker, &admin, &later});
  farm.coordinator().signal(SIGHUP);
  ASSERT_TRUE(farm.coordinator().wait_for_log("SIGHUP: token file", 10))
      << farm.coordinator().log();
  EXPECT_EQ(call_every_method(farm.channel(later.token))["ListJobs"], grpc::StatusCode::OK);
  EXPECT_EQ(call_every_method(farm.channel(shot2.token))["ListJobs"],
            grpc::StatusCode::UNAUTHENTICATED);
  // A broken file on SIGHUP keeps the tokens read before, and says why.
  test::write_text(tokens, "not a token line\n");
  farm.coordinator().signal(SIGHUP);
  ASSERT_TRUE(farm.coordinator().wait_for_log(tokens + ":1:", 10)) << farm.coordinator().log();
  EXPECT_EQ(call_every_method(farm.channel(later.token))["ListJobs"], grpc::StatusCode::OK);

  std::string log = farm.coordinator().log();
  for (const Token* t : {&shot1, &shot2, &worker, &admin, &expired, &later})
    EXPECT_EQ(log.find(t->token), std::string::npos) << "a token is in the coordinator's log";
  EXPECT_NE(log.find("refused"), std::string::npos) << "refusals are logged";
}

long rss_kib(pid_t pid) { return test::proc_status_kib(pid, "VmRSS"); }

// A second worker token cannot change a job it does not hold the leases of: uploads with an
// empty, invented or another task's lease, or under another token's worker id, are refused
// (before the upload's bytes are read), invented worker ids cannot fail the job, and an upload
// for a job that does not exist is refused after its header, without buffering the 300 MiB
// that follow. The honest worker's image still equals the local render, and the coordinator
// logs each refusal with the worker it came from.
TEST(Security, UploadsAreAcceptedOnlyFromTheWorkerHoldingTheLease) {
  std::string dir = test::make_temp_dir("security-uploads");
  Token client = make_token(dir, "client", "--role client --tenant shot1");
  Token honest = make_token(dir, "honest", "--role worker --tenant farm");
  Token rogue = make_token(dir, "rogue", "--role worker --tenant farm");
  std::string tokens = dir + "/tokens";
  write_token_file(tokens, {&client, &honest, &rogue});
  Farm farm("security-uploads-farm", 30, tokens);
  farm.client_token_file = client.file;
  farm.worker_token_file = honest.file;
  std::string job = farm.submit(kJob + " --frames 1 --tile-size 16");

  auto stub = pb::WorkerService::NewStub(farm.channel(rogue.token));
  std::string me = test::register_worker(*stub, "rogue");
  std::optional<pb::Task> leased = test::lease_task(*stub, me);
  ASSERT_TRUE(leased);
  const pb::Task mine = *leased;
  auto garbage = test::chunks_of(std::string(1000, 'x'));
  pb::Task other = mine;  // another task of the job, under my lease
  other.set_task_id(job + "/1/0/3");
  ASSERT_NE(other.task_id(), mine.task_id());
  EXPECT_EQ(test::complete_with(*stub, me, other, garbage).error_code(),
            grpc::StatusCode::PERMISSION_DENIED);
  pb::Task no_lease = other;
  no_lease.set_lease_id("");
  EXPECT_EQ(test::complete_with(*stub, me, no_lease, garbage).error_code(),
            grpc::StatusCode::NOT_FOUND);
  no_lease.set_lease_id("L-invented");
  EXPECT_EQ(test::complete_with(*stub, me, no_lease, garbage).error_code(),
            grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(test::complete_with(*stub, "invented", mine, garbage).error_code(),
            grpc::StatusCode::NOT_FOUND);
  for (int i = 0; i < 3; ++i) {
    grpc::ClientContext ctx;
    pb::FailRequest fr;
    fr.set_worker_id("fake-" + std::to_string(i));
    fr.set_lease_id(mine.lease_id());
    fr.set_message("forged failure");
    pb::FailResponse resp;
    EXPECT_EQ(stub->FailTask(&ctx, fr, &resp).error_code(), grpc::StatusCode::NOT_FOUND);
  }
  {  // my own lease, handed back: the honest worker renders that task too
    grpc::ClientContext ctx;
    pb::FailRequest fr;
    fr.set_worker_id(me);
    fr.set_lease_id(mine.lease_id());
    fr.set_handed_back(true);
    pb::FailResponse resp;
    EXPECT_TRUE(stub->FailTask(&ctx, fr, &resp).ok());
  }
  {  // 300 MiB announced for a job that does not exist: refused after the header
    long before = rss_kib(farm.coordinator().pid());
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    pb::CompleteResponse resp;
    auto w = stub->CompleteTask(&ctx, &resp);
    pb::CompleteRequest head;
    head.mutable_header()->set_worker_id(me);
    head.mutable_header()->set_lease_id(mine.lease_id());
    head.mutable_header()->set_task_id("j999999/1/0/0");
    ASSERT_TRUE(w->Write(head));
    std::string mib(1 << 20, 'x');
    int written = 0;
    for (uint64_t i = 0; i < 300; ++i) {
      pb::CompleteRequest m;
      m.mutable_chunk()->set_offset(i << 20);
      m.mutable_chunk()->set_data(mib);
      if (i == 0) {  // a well-formed stream: a server that buffered it would take it all
        m.mutable_chunk()->set_total_size(uint64_t(300) << 20);
        m.mutable_chunk()->set_sha256(std::string(64, '0'));
      }
      if (!w->Write(m)) break;
      ++written;
    }
    long during = rss_kib(farm.coordinator().pid());
    if (written == 300) w->WritesDone();
    grpc::Status st = w->Finish();
    EXPECT_EQ(st.error_code(), grpc::StatusCode::NOT_FOUND) << st.error_message();
    EXPECT_LT(written, 300) << "the stream went on after the refusal";
    EXPECT_LT(during - before, 64 * 1024) << "RSS " << before << " -> " << during << " KiB";
  }
  {  // batched uploads: a malformed batch fails as a whole; a sound one answers each result
    std::optional<pb::Task> again = test::lease_task(*stub, me);
    ASSERT_TRUE(again);
    pb::Task forged = *again;  // another task under this lease
    forged.set_task_id(job + "/1/0/" + (again->task_id() == job + "/1/0/2" ? "1" : "2"));
    struct Sent {
      std::string worker;
      pb::Task task;
    };
    auto batch = [&](uint32_t announce, const std::vector<Sent>& results,
                     pb::CompleteResponse* resp) {
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
      auto w = stub->CompleteTask(&ctx, resp);
      for (size_t i = 0; i < results.size(); ++i) {
        pb::CompleteRequest head;
        head.mutable_header()->set_worker_id(results[i].worker);
        head.mutable_header()->set_lease_id(results[i].task.lease_id());
        head.mutable_header()->set_task_id(results[i].task.task_id());
        if (i == 0) head.mutable_header()->set_results(announce);
        if (!w->Write(head)) break;
        for (const pb::Chunk& c : garbage) {
          pb::CompleteRequest m;
          *m.mutable_chunk() = c;
          w->Write(m);
        }
      }
      w->WritesDone();
      return w->Finish();
    };
    pb::CompleteResponse resp;
    grpc::Status st = batch(3, {{me, *again}, {me, forged}}, &resp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << "3 announced, 2 sent";
    EXPECT_NE(st.error_message().find("announced 3 results and sent 2"), std::string::npos)
        << st.error_message();
    st = batch(2, {{me, *again}, {me, forged}, {me, forged}}, &resp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << "2 announced, 3 sent";
    st = batch(65, {{me, *again}}, &resp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << st.error_message();
    st = batch(2, {{me, *again}, {"invented", forged}}, &resp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << "two workers in one batch";
    pb::CompleteResponse answered;
    st = batch(2, {{me, forged}, {me, *again}}, &answered);
    ASSERT_TRUE(st.ok()) << st.error_message();
    ASSERT_EQ(answered.results_size(), 2);
    EXPECT_EQ(answered.results(0).code(), int(grpc::StatusCode::PERMISSION_DENIED))
        << answered.results(0).message();
    EXPECT_EQ(answered.results(1).code(), int(grpc::StatusCode::INVALID_ARGUMENT))
        << "garbage under its own lease: " << answered.results(1).message();
    EXPECT_FALSE(answered.results(0).accepted() || answered.results(1).accepted());
  }
  EXPECT_EQ(farm.status(job)["state"], "running");
  farm.worker();
  EXPECT_EQ(farm.client("watch " + job).exit_code, 0);
  ASSERT_EQ(farm.client("fetch " + job + " -o " + farm.dir() + "/out-" + job).exit_code, 0);
  test::expect_same_image(farm.fetched(job, 1), farm.local(kJob + " --tile-size 16", 1));
  std::string log = farm.coordinator().log();
  EXPECT_NE(log.find("refused: worker " + me + " sent task " + other.task_id()), std::string::npos)
      << log;
}

// Without a token file the coordinator listens on loopback only, and says why; with one it
// listens anywhere. A second coordinator on the same state directory exits naming the first
// one's pid; a second one on the same port fails to bind instead of sharing it.
TEST(Security, LoopbackOnlyWithoutTokensAndOneCoordinatorPerStateDirectoryAndPort) {
  std::string dir = test::make_temp_dir("security-listen");
  auto run = [&](const std::string& args) {
    return test::run_command("timeout 20 " + test::rayfarm_binary() + " coordinator " + args);
  };
  test::CommandResult open = run("--listen 0.0.0.0:0 --state-dir " + dir + "/open");
  EXPECT_EQ(open.exit_code, 1) << open.output;
  EXPECT_NE(open.output.find("--token-file"), std::string::npos) << open.output;

  Token admin = make_token(dir, "admin", "--role admin --tenant ops");
  write_token_file(dir + "/tokens", {&admin});
  Farm farm("security-listen-farm", 30, dir + "/tokens");
  test::CommandResult same_dir = run("--listen 127.0.0.1:0 --state-dir " + farm.dir() + "/state");
  EXPECT_NE(same_dir.exit_code, 0);
  EXPECT_NE(same_dir.output.find("pid " + std::to_string(farm.coordinator().pid())),
            std::string::npos)
      << same_dir.output;
  test::CommandResult same_port =
      run("--listen " + farm.address() + " --state-dir " + dir + "/second");
  EXPECT_NE(same_port.exit_code, 0);
  EXPECT_NE(same_port.output.find("cannot listen"), std::string::npos) << same_port.output;
  EXPECT_TRUE(farm.coordinator().running());

  test::Process anywhere({test::rayfarm_binary(), "coordinator", "--listen", "0.0.0.0:0",
                          "--state-dir", dir + "/anywhere", "--token-file", dir + "/tokens"},
                         dir + "/anywhere.log");
  EXPECT_TRUE(anywhere.wait_for_log("listening on 0.0.0.0:0", 20)) << anywhere.log();
}

// The careless submit of the issue: 16384x16384 pixels in 8-pixel tiles (4.2 million tasks
// per pass) is refused at submit naming the limit, the coordinator's memory does not move, and
// it keeps serving and restarts cleanly. `status` pages its list.
TEST(Security, AHugeJobIsRefusedNamingItsLimitAndStatusPages) {
  Farm farm("security-limits");
  long before = rss_kib(farm.coordinator().pid());
  test::CommandResult huge =
      farm.client("submit scenes/cornell-box/scene.json --res 16384x16384 --tile-size 8");
  EXPECT_EQ(huge.exit_code, 1) << huge.output;
  EXPECT_NE(huge.output.find("RESOURCE_EXHAUSTED"), std::string::npos) << huge.output;
  EXPECT_NE(huge.output.find("pixels_per_frame"), std::string::npos) << huge.output;
  long after = rss_kib(farm.coordinator().pid());
  EXPECT_LT(after - before, 32 * 1024) << "RSS " << before << " -> " << after << " KiB";
  test::CommandResult tiles =
      farm.client("submit scenes/cornell-box/scene.json --res 4096x4096 --tile-size 8");
  EXPECT_NE(tiles.output.find("tiles_per_frame"), std::string::npos) << tiles.output;

  std::vector<std::string> jobs;
  for (int i = 0; i < 3; ++i) jobs.push_back(farm.submit(kJob + " --frames 1"));
  test::CommandResult page = farm.client("status --limit 2");
  EXPECT_EQ(page.exit_code, 0) << page.output;
  EXPECT_NE(page.output.find(jobs[1]), std::string::npos) << page.output;
  EXPECT_EQ(page.output.find(jobs[2]), std::string::npos) << page.output;
  EXPECT_NE(page.output.find("status --after " + jobs[1]), std::string::npos) << page.output;
  test::CommandResult rest = farm.client("status --after " + jobs[1]);
  EXPECT_NE(rest.output.find(jobs[2]), std::string::npos) << rest.output;
  EXPECT_EQ(rest.output.find(jobs[0]), std::string::npos) << rest.output;
  farm.restart_coordinator();
  EXPECT_EQ(farm.client("status").exit_code, 0);
  EXPECT_EQ(check_health(farm.address()), "SERVING");
}

// The same job admitted by raised limits: 16384x16384 pixels in 8-pixel tiles, 4 passes, is
// 16.8 million tasks. The coordinator makes a task only as it is handed out, so admitting the
// job, handing out and failing hundreds of its tasks, cancelling it and restarting keep its RSS
// within a bound (stated below) instead of the ~21 GB of task records made up front before.
// Merging results of such a frame would still need its accumulator, 104 bytes a pixel per
// pass in flight: pixels_per_frame is the limit that bounds that, and is not raised lightly.
TEST(Security, AHugeJobAdmittedByRaisedLimitsIsHeldInBoundedMemory) {
  if (test::kAddressSanitizer) GTEST_SKIP() << "RSS is meaningless under AddressSanitizer";
  Farm farm("security-huge", 30, "",
            {"--limit", "pixels_per_frame=268435456", "--limit", "tiles_per_frame=4194304",
             "--limit", "tasks_per_job=20000000"});
  long before = rss_kib(farm.coordinator().pid());
  std::string job = farm.submit(
      "scenes/cornell-box/scene.json --res 16384x16384 --tile-size 8 --spp 4 --passes 4");
  long submitted = rss_kib(farm.coordinator().pid());

  auto stub = pb::WorkerService::NewStub(farm.channel());
  std::string worker = test::register_worker(*stub, "huge");
  std::vector<pb::Task> held;
  for (int i = 0; i < 300; ++i) {
    std::optional<pb::Task> task = test::lease_task(*stub, worker);
    ASSERT_TRUE(task);
    held.push_back(*task);
  }
  EXPECT_EQ(held[0].task_id(), job + "/0/0/0");
  EXPECT_EQ(held[299].task_id(), job + "/0/0/299");
  for (const pb::Task& task : held) {  // handed back: queued again, not counted as failures
    grpc::ClientContext ctx;
    pb::FailRequest fr;
    fr.set_worker_id(worker);
    fr.set_lease_id(task.lease_id());
    fr.set_task_id(task.task_id());
    fr.set_message("draining");
    fr.set_handed_back(true);
    pb::FailResponse fresp;
    ASSERT_TRUE(stub->FailTask(&ctx, fr, &fresp).ok());
  }
  std::optional<pb::Task> again = test::lease_task(*stub, worker);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->task_id(), job + "/0/0/0") << "a handed-back task is first in line again";
  long leased = rss_kib(farm.coordinator().pid());
  test::CommandResult status = farm.client("status " + job);
  EXPECT_EQ(status.exit_code, 0) << status.output;
  EXPECT_EQ(farm.client("cancel " + job).exit_code, 0);
  long cancelled = rss_kib(farm.coordinator().pid());
  farm.restart_coordinator();
  long restarted = rss_kib(farm.coordinator().pid());
  EXPECT_EQ(farm.client("status " + job).exit_code, 0);
  EXPECT_EQ(check_health(farm.address()), "SERVING");
  // The bound: nothing per tile (the split is a TileGrid, three numbers: the 4.2 million tile
  // rectangles of 16 bytes each took 65-67 MiB when a job held them) and nothing per task.
  const long bound = 32 * 1024;
  std::ostringstream figures;
  figures << "RSS KiB: start " << before << ", submitted " << submitted << ", 300 leases " << leased
          << ", cancelled " << cancelled << ", restarted " << restarted;
  std::cout << figures.str() << "\n";
  EXPECT_LT(submitted - before, bound) << figures.str();
  EXPECT_LT(leased - before, bound) << figures.str();
  EXPECT_LT(cancelled - before, bound) << figures.str();
  EXPECT_LT(restarted, before + bound) << figures.str();
}

std::string file_text(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// A throwaway CA, made by the test with OpenSSL's command line: a server certificate for
// localhost / 127.0.0.1 and a worker certificate signed by it, and a worker certificate signed
// by another CA.
struct TestPki {
  std::string ca, server_cert, server_key, worker_cert, worker_key, rogue_cert, rogue_key;
};

TestPki make_pki(const std::string& dir) {
  const std::string key = "-newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes";
  std::string script =
      "set -e; cd " + dir +
      "; exec 2>pki.log"
      "; openssl req -x509 " +
      key +
      " -keyout ca.key -out ca.pem -days 2 -subj '/CN=test CA'"
      "; openssl req -x509 " +
      key +
      " -keyout other.key -out other.pem -days 2 -subj '/CN=other'"
      "; printf 'subjectAltName=DNS:localhost,IP:127.0.0.1\\n' > server.ext"
      "; openssl req " +
      key +
      " -keyout server.key -out server.csr -subj '/CN=localhost'"
      "; openssl x509 -req -in server.csr -CA ca.pem -CAkey ca.key -CAcreateserial -days 2"
      " -extfile server.ext -out server.pem"
      "; openssl req " +
      key +
      " -keyout worker.key -out worker.csr -subj '/CN=worker'"
      "; openssl x509 -req -in worker.csr -CA ca.pem -CAkey ca.key -CAcreateserial -days 2"
      " -out worker.pem"
      "; openssl req " +
      key +
      " -keyout rogue.key -out rogue.csr -subj '/CN=rogue'"
      "; openssl x509 -req -in rogue.csr -CA other.pem -CAkey other.key -CAcreateserial -days 2"
      " -out rogue.pem";
  test::CommandResult r = test::run_command("bash -c \"" + script + "\"");
  EXPECT_EQ(r.exit_code, 0) << r.output << file_text(dir + "/pki.log");
  return {dir + "/ca.pem",     dir + "/server.pem", dir + "/server.key", dir + "/worker.pem",
          dir + "/worker.key", dir + "/rogue.pem",  dir + "/rogue.key"};
}

grpc::StatusCode register_with(const std::string& address, const ClientCredentials& creds) {
  auto stub = pb::WorkerService::NewStub(coordinator_channel(address, creds));
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  pb::RegisterRequest req;
  req.set_hostname("probe");
  pb::RegisterResponse resp;
  return stub->Register(&ctx, req, &resp).error_code();
}

// TLS with mutual TLS for workers: a plaintext client cannot talk to the coordinator; a client
// that checks the server against the CA submits, fetches and watches with its token; a worker
// without a client certificate is UNAUTHENTICATED, one with a certificate from another CA fails
// the handshake, and one with a certificate from the CA renders the job to the local image. The
// plaintext health listener answers probes and serves nothing else.
TEST(Security, TlsWithClientCertificatesForWorkersAndAPlaintextHealthPort) {
  std::string dir = test::make_temp_dir("security-tls");
  TestPki pki = make_pki(dir);
  Token client = make_token(dir, "client", "--role client --tenant shot1");
  Token worker = make_token(dir, "worker", "--role worker --tenant farm");
  write_token_file(dir + "/tokens", {&client, &worker});
  Farm farm("security-tls-farm", 30, dir + "/tokens",
            {"--tls-cert", pki.server_cert, "--tls-key", pki.server_key, "--tls-client-ca", pki.ca,
             "--health-listen", "127.0.0.1:0"});
  farm.client_token_file = client.file;
  // Without TLS, the client cannot speak to it: UNAVAILABLE, retried within --timeout, saying why.
  test::CommandResult plain = farm.client("status --timeout 2");
  EXPECT_NE(plain.exit_code, 0) << plain.output;
  EXPECT_NE(plain.output.find("unavailable"), std::string::npos) << plain.output;
  farm.client_args = " --tls-ca " + pki.ca;
  EXPECT_EQ(farm.client("status").exit_code, 0);
  std::string job = farm.submit(kJob + " --frames 1");

  const std::string ca = file_text(pki.ca);
  EXPECT_EQ(register_with(farm.address(), {worker.token, ca, "", ""}),
            grpc::StatusCode::UNAUTHENTICATED)
      << "a worker without a client certificate";
  EXPECT_EQ(register_with(farm.address(),
                          {worker.token, ca, file_text(pki.rogue_cert), file_text(pki.rogue_key)}),
            grpc::StatusCode::UNAVAILABLE)
      << "a client certificate from another CA fails the handshake";
  EXPECT_EQ(register_with(farm.address(), {worker.token, "", "", ""}),
            grpc::StatusCode::UNAVAILABLE)
      << "plaintext to a TLS port";

  farm.worker_token_file = worker.file;
  farm.worker_args = {"--exit-when-idle", "--tls-ca",  pki.ca,        "--tls-cert",
                      pki.worker_cert,    "--tls-key", pki.worker_key};
  farm.worker({});
  EXPECT_EQ(farm.client("watch " + job).exit_code, 0);
  ASSERT_EQ(farm.client("fetch " + job + " -o " + farm.dir() + "/out-" + job).exit_code, 0);
  test::expect_same_image(farm.fetched(job, 1), farm.local(kJob, 1));

  std::smatch m;
  std::string log = farm.coordinator().log();
  ASSERT_TRUE(std::regex_search(log, m, std::regex("health port ([0-9]+)"))) << log;
  std::string health = "127.0.0.1:" + m[1].str();
  EXPECT_EQ(check_health(health), "SERVING");
  auto on_health = pb::JobService::NewStub(coordinator_channel(health, {client.token, "", "", ""}));
  grpc::ClientContext ctx;
  pb::ListJobsResponse resp;
  EXPECT_EQ(on_health->ListJobs(&ctx, pb::ListJobsRequest{}, &resp).error_code(),
            grpc::StatusCode::UNIMPLEMENTED);
  test::CommandResult probe = test::run_command(test::rayfarm_binary() + " health " +
                                                farm.address() + " --tls-ca " + pki.ca);
  EXPECT_EQ(probe.exit_code, 0) << probe.output;

  // The TLS failures are named (before: "tcp handshaker shutdown (is a coordinator running at
  // ...?)"; a worker retried past --give-up-after; swapped files: "cannot listen").
  test::CommandResult wrong_ca = test::run_command(
      test::rayfarm_binary() + " status --timeout 2 --coordinator " + farm.address() +
      " --token-file " + client.file + " --tls-ca " + dir + "/other.pem");
  EXPECT_EQ(wrong_ca.exit_code, 1) << wrong_ca.output;
  EXPECT_NE(wrong_ca.output.find("the TLS handshake with"), std::string::npos) << wrong_ca.output;
  auto t0 = std::chrono::steady_clock::now();
  test::CommandResult rogue = test::run_command(
      test::rayfarm_binary() + " worker --give-up-after 3 --cache-dir " + dir + "/cache" +
      " --coordinator " + farm.address() + " --token-file " + worker.file + " --tls-ca " + pki.ca +
      " --tls-cert " + pki.rogue_cert + " --tls-key " + pki.rogue_key);
  double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(rogue.exit_code, 1) << rogue.output;
  EXPECT_LT(took, 5) << rogue.output;
  EXPECT_NE(rogue.output.find("TLS handshake"), std::string::npos) << rogue.output;
  test::CommandResult swapped = test::run_command(
      test::rayfarm_binary() + " coordinator --listen 127.0.0.1:0 --state-dir " + dir +
      "/swapped --tls-cert " + pki.server_key + " --tls-key " + pki.server_cert);
  EXPECT_EQ(swapped.exit_code, 1) << swapped.output;
  EXPECT_NE(swapped.output.find("are --tls-cert and --tls-key swapped?"), std::string::npos)
      << swapped.output;
}

// --verify-fraction with real workers: about half the tasks are rendered by both workers, the
// pairs agree bit for bit (the determinism contract), and the image equals the local render.
TEST(Security, VerifiedTasksOnTwoRealWorkersGiveTheLocalImage) {
  Farm farm("security-verify", 30, "", {"--verify-fraction", "0.5"});
  const std::string args = kJob + " --tile-size 16";
  std::string job = farm.submit(args + " --frames 1");
  farm.worker();
  farm.worker();
  EXPECT_EQ(farm.client("watch " + job).exit_code, 0);
  ASSERT_EQ(farm.client("fetch " + job + " -o " + farm.dir() + "/out-" + job).exit_code, 0);
  test::expect_same_image(farm.fetched(job, 1), farm.local(args, 1));
  std::string log = farm.coordinator().log();
  size_t held = 0;
  for (size_t p = 0; (p = log.find("held until another worker", p)) != std::string::npos; ++p)
    ++held;
  EXPECT_GE(held, 2u) << "16 tasks at fraction 0.5 were verified";
  EXPECT_LE(held, 14u);
  EXPECT_EQ(log.find("outvoted"), std::string::npos) << log;
}

}  // namespace
}  // namespace rf
