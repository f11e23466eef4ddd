// What a probe of the farm found lenient, silent or unclear, each tried again with real processes
// on loopback (docs/security.md, docs/reliability.md): a worker token reading other jobs' blobs,
// client text that writes into an operator's terminal, bundles that name a path twice or a file
// as a folder, refused submits that used up job ids, an upload refused without ending its lease,
// an unbounded refusal log, idle HTTP connections that held off the metrics scrape, connections
// that never finish their handshake, and a worker that told the coordinator the wrong core count.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <regex>
#include <thread>
#include <vector>

#include "engine/digest.h"
#include "farm/job.h"
#include "proto/rayfarm.grpc.pb.h"
#include "tests/support/farm.h"
#include "tests/support/net.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

namespace pb = rayfarm::v1;
using test::Farm;
using test::Token;

const std::string kCornell = "scenes/cornell-box/scene.json";

bool has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

std::string cornell_scene() { return read_file_bytes(test::source_dir() + "/" + kCornell); }

// A scene in one file: an emissive sphere, 8x8 pixels, 1 spp.
const std::string kSphere =
    "{\"format\": \"rayfarm-scene\", \"version\": 1, \"camera\": {\"fov_deg\": 40, "
    "\"look_at\": {\"eye\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}, "
    "\"film\": {\"resolution\": [8, 8]}, \"render\": {\"spp\": 1, \"passes\": 1}, "
    "\"materials\": {\"m\": {\"type\": \"diffuse\", \"reflectance\": [0.5, 0.5, 0.5]}}, "
    "\"shapes\": [{\"type\": \"sphere\", \"material\": \"m\", \"emission\": "
    "{\"radiance\": [1, 1, 1]}}]}";

grpc::Status fetch_blob(pb::WorkerService::Stub& stub, const std::string& sha256,
                        std::string* bytes = nullptr) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
  pb::BlobRequest req;
  req.set_sha256(sha256);
  auto r = stub.FetchBlob(&ctx, req);
  pb::Chunk c;
  while (r->Read(&c))
    if (bytes) bytes->append(c.data());
  return r->Finish();
}

// The one check and the one escape of client text (farm/job.h).
TEST(Hardening, TextProblemsAndPrintableText) {
  EXPECT_EQ(text_problem("shot 010, café ünïcode 🎬"), "");
  EXPECT_EQ(text_problem("a\nb"), "byte 1 is a control character");
  EXPECT_EQ(text_problem("\x1b[31m"), "byte 0 is a control character");
  EXPECT_EQ(text_problem("ok\xc2\x85"), "byte 2 is a control character");  // U+0085, C1
  EXPECT_EQ(text_problem("caf\xe9"), "byte 3 is not UTF-8");
  EXPECT_EQ(text_problem("\xc0\xaf"), "byte 0 is not UTF-8");      // an overlong '/'
  EXPECT_EQ(text_problem("\xed\xa0\x80"), "byte 0 is not UTF-8");  // a surrogate
  EXPECT_EQ(text_problem(std::string("a\0", 2)), "byte 1 is a control character");
  EXPECT_EQ(printable("a\n\x1b[31mb caf\xe9 é"), "a\\x0a\\x1b[31mb caf\\xe9 é");
}

// A worker token reads a job's scene blobs only while one of its workers holds a lease of that
// job; before (and for a digest it has no lease for) the answer is NOT_FOUND, as for a blob the
// store lacks. An admin token reads any.
TEST(Hardening, AWorkerTokenFetchesOnlyBlobsOfJobsItsWorkersHoldALeaseOf) {
  std::string dir = test::make_temp_dir("hardening-blobs");
  Token client = test::make_token(dir, "client", "--role client --tenant shot1");
  Token worker = test::make_token(dir, "worker", "--role worker --tenant farm");
  Token other = test::make_token(dir, "other", "--role worker --tenant farm");
  Token admin = test::make_token(dir, "admin", "--role admin --tenant ops");
  test::write_token_file(dir + "/tokens", {&client, &worker, &other, &admin});
  Farm farm("hardening-blobs-farm", 30, dir + "/tokens");
  farm.client_token_file = client.file;
  std::string job = farm.submit(kCornell + " --spp 4 --passes 2 --res 16x16");
  const std::string scene = sha256_hex(cornell_scene());

  auto stub = pb::WorkerService::NewStub(farm.channel(worker.token));
  auto stranger = pb::WorkerService::NewStub(farm.channel(other.token));
  std::string me = test::register_worker(*stub, "w");
  EXPECT_EQ(fetch_blob(*stub, scene).error_code(), grpc::StatusCode::NOT_FOUND) << "no lease yet";
  std::optional<pb::Task> task = test::lease_task(*stub, me);
  ASSERT_TRUE(task);
  std::string bytes;
  grpc::Status st = fetch_blob(*stub, scene, &bytes);
  EXPECT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(sha256_hex(bytes), scene);
  // Another worker token, with a registration of its own but no lease of the job.
  test::register_worker(*stranger, "s");
  st = fetch_blob(*stranger, scene);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::NOT_FOUND) << st.error_message();
  EXPECT_EQ(fetch_blob(*stub, std::string(64, 'a')).error_code(), grpc::StatusCode::NOT_FOUND);
  auto as_admin = pb::WorkerService::NewStub(farm.channel(admin.token));
  EXPECT_TRUE(fetch_blob(*as_admin, scene).ok());
}

// Client text reaches operators' terminals and logs: a job name with a newline or an ANSI
// escape is refused (protobuf refuses bytes that are not UTF-8 in its strings, and so does
// text_problem for any other source); a bundle path with a NUL, a path listed twice
// and a path that is a file and a folder are refused naming the path, never a server directory.
// None of these refusals takes a job id: the next job accepted is j000001. A second cancel of a
// cancelled job succeeds; cancelling a completed one is refused.
TEST(Hardening, ClientTextAndBundlesAreCheckedAndRefusedSubmitsTakeNoJobId) {
  Farm farm("hardening-text");
  auto jobs = pb::JobService::NewStub(farm.channel());
  const std::string scene = kSphere;
  auto refused = [&](const std::vector<test::BundleFile>& files, const std::string& name,
                     const std::string& expect) {
    grpc::Status st = test::submit_files(*jobs, "scene.json", files, "", nullptr,
                                         [&](pb::JobSpec& s) { s.set_name(name); });
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << st.error_message();
    EXPECT_TRUE(has(st.error_message(), expect)) << st.error_message();
    EXPECT_FALSE(has(st.error_message(), farm.dir())) << st.error_message();
  };
  std::vector<test::BundleFile> ok = {{"scene.json", scene}};
  refused(ok, "shot\n[ok] job j999 completed", "name: byte 4 is a control character");
  refused(ok, "\x1b[31mred", "name: byte 0 is a control character");
  refused({{"scene.json", scene}, {std::string("a\0b", 3), "x"}}, "nul",
          "bundle path 'a\\x00b': byte 1 is a control character");
  refused({{"scene.json", scene}, {"scene.json", "{}"}}, "twice", "'scene.json' is listed twice");
  refused({{"scene.json", scene}, {"m", "x"}, {"m/a.obj", "y"}}, "both",
          "'m' is both a file and the folder of another file");

  std::string id;
  grpc::Status st = test::submit_files(*jobs, "scene.json", ok, "", &id,
                                       [](pb::JobSpec& s) { s.set_name("café ok"); });
  ASSERT_TRUE(st.ok()) << st.error_message();
  EXPECT_EQ(id, "j000001") << "refused submits take no id";

  EXPECT_EQ(farm.client("cancel " + id).exit_code, 0);
  test::CommandResult again = farm.client("cancel " + id);
  EXPECT_EQ(again.exit_code, 0) << again.output;
  std::string done = farm.submit(kCornell + " --spp 1 --passes 1 --res 8x8");
  EXPECT_EQ(done, "j000002");
  farm.worker();
  EXPECT_EQ(farm.client("watch " + done).exit_code, 0);
  test::CommandResult completed = farm.client("cancel " + done);
  EXPECT_EQ(completed.exit_code, 1) << completed.output;
  EXPECT_TRUE(has(completed.output, "completed")) << completed.output;
}

// An upload refused on its way in (its checksum fails) ends its lease and queues the task again,
// as a refused result does: renewing the lease is then FAILED_PRECONDITION.
TEST(Hardening, AnUploadRefusedOnItsWayInEndsItsLease) {
  Farm farm("hardening-upload");
  std::string job = farm.submit(kCornell + " --spp 4 --passes 2 --res 16x16");
  auto workers = pb::WorkerService::NewStub(farm.channel());
  std::string me = test::register_worker(*workers, "w");
  std::optional<pb::Task> task = test::lease_task(*workers, me);
  ASSERT_TRUE(task);
  std::vector<pb::Chunk> corrupt = test::chunks_of(std::string(5000, 'x'));
  corrupt[0].mutable_data()->at(10) ^= 1;
  grpc::Status st = test::complete_with(*workers, me, *task, corrupt);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::DATA_LOSS) << st.error_message();
  grpc::ClientContext ctx;
  pb::RenewRequest rr;
  rr.set_worker_id(me);
  rr.set_lease_id(task->lease_id());
  pb::RenewResponse resp;
  st = workers->RenewLease(&ctx, rr, &resp);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << st.error_message();
  std::optional<pb::Task> again = test::lease_task(*workers, me);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->task_id(), task->task_id()) << "the task was queued again";
}

int metrics_port(Farm& farm) {
  std::smatch m;
  std::string log = farm.coordinator().log();
  EXPECT_TRUE(std::regex_search(log, m, std::regex("metrics port ([0-9]+)"))) << log;
  return m.empty() ? 0 : std::stoi(m[1]);
}

double sample(const std::string& text, const std::string& name) {
  std::smatch m;
  if (!std::regex_search(text, m, std::regex("\n" + name + " ([0-9.e+]+)"))) return -1;
  return std::stod(m[1]);
}

// A flood of refused calls costs the log at most its rate (20 lines a second after a burst of
// 100) and is counted in full in the metrics; 200 idle connections to the metrics port do not
// hold off a scrape; a connection that never sends gRPC's preface is closed within the handshake
// timeout (10 s); and a worker started with --threads 1 registers one core.
TEST(Hardening, RefusalsIdleConnectionsAndCoresAreBounded) {
  std::string dir = test::make_temp_dir("hardening-bounds");
  Token client = test::make_token(dir, "client", "--role client --tenant shot1");
  Token worker = test::make_token(dir, "worker", "--role worker --tenant farm");
  test::write_token_file(dir + "/tokens", {&client, &worker});
  Farm farm("hardening-bounds-farm", 30, dir + "/tokens", {"--metrics-listen", "127.0.0.1:0"});
  farm.client_token_file = client.file;
  farm.worker_token_file = worker.file;
  int port = metrics_port(farm);
  ASSERT_GT(port, 0);

  const int kCalls = 1000;
  auto jobs = pb::JobService::NewStub(farm.channel("rft_" + std::string(64, '0')));
  for (int i = 0; i < kCalls; ++i) {
    grpc::ClientContext ctx;
    pb::JobRef ref;
    ref.set_job_id("j000001");
    pb::JobStatus s;
    EXPECT_EQ(jobs->GetJob(&ctx, ref, &s).error_code(), grpc::StatusCode::UNAUTHENTICATED);
  }
  std::string error;
  std::string metrics = test::http_get(port, "/metrics", error);
  ASSERT_EQ(error, "");
  EXPECT_EQ(sample(metrics, "rayfarm_calls_refused_total"), kCalls);
  double suppressed = sample(metrics, "rayfarm_refusal_log_lines_suppressed_total");
  EXPECT_GT(suppressed, 0);
  std::string log = farm.coordinator().log();
  size_t lines = 0;
  for (size_t at = log.find("refused GetJob"); at != std::string::npos;
       at = log.find("refused GetJob", at + 1))
    ++lines;
  EXPECT_EQ(lines + size_t(suppressed), size_t(kCalls));
  EXPECT_LT(lines, 400u) << "100 at once, then 20 a second";

  std::vector<int> idle;
  for (int i = 0; i < 200; ++i) idle.push_back(test::connect_loopback(port));
  auto t0 = std::chrono::steady_clock::now();
  metrics = test::http_get(port, "/metrics", error);
  double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(error, "");
  EXPECT_LT(took, 15) << "a scrape behind 200 idle connections";
  for (int fd : idle) ::close(fd);

  int silent = test::connect_loopback(farm.port());
  ASSERT_GE(silent, 0);
  EXPECT_TRUE(test::closed_by_peer(silent, 20)) << "a connection that never says a word";
  ::close(silent);

  std::string job = farm.submit(kCornell + " --spp 1 --passes 1 --res 8x8");
  farm.worker({"--exit-when-idle", "--threads", "1"});
  EXPECT_EQ(farm.client("watch " + job).exit_code, 0);
  EXPECT_TRUE(has(farm.coordinator().log(), ": 1 cores,")) << farm.coordinator().log();
}

}  // namespace
}  // namespace rf
