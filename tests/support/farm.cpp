#include "tests/support/farm.h"

#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cmath>
#include <regex>
#include <sstream>
#include <thread>

#include "engine/digest.h"
#include "farm/channel.h"
#include "farm/chunking.h"
#include "tests/support/exr.h"

namespace rf::test {

namespace pb = rayfarm::v1;

void expect_same_image(const std::string& farm, const std::string& local) {
  Exr a = read_exr(farm), b = read_exr(local);
  ASSERT_EQ(a.w, b.w);
  ASSERT_EQ(a.h, b.h);
  ASSERT_EQ(a.nch, b.nch);
  size_t bad = 0;
  for (size_t i = 0; i < a.px.size(); ++i) {
    double x = a.px[i], y = b.px[i];
    if (std::fabs(x - y) > 1e-6 * std::max(std::fabs(x), std::fabs(y)) + 1e-12) ++bad;
  }
  EXPECT_EQ(bad, 0u) << farm << " differs from " << local << " in " << bad << " of " << a.px.size()
                     << " values";
}

namespace {

// argv run in network namespace `netns` (empty: as it is).
std::vector<std::string> in_netns(const std::string& netns, std::vector<std::string> argv) {
  if (!netns.empty()) argv.insert(argv.begin(), {"/usr/sbin/ip", "netns", "exec", netns});
  return argv;
}

}  // namespace

Farm::Farm(const std::string& tag, double lease_seconds, const std::string& token_file,
           const std::vector<std::string>& coordinator_args, FarmNetwork network)
    : dir_(make_temp_dir(tag)),
      lease_seconds_(lease_seconds),
      token_file_(token_file),
      coordinator_args_(coordinator_args),
      network_(std::move(network)) {
  start_coordinator(0);
}

void Farm::start_coordinator(int port) {
  std::vector<std::string> argv{
      rayfarm_binary(),  "coordinator",
      "--listen",        network_.listen_host + ":" + std::to_string(port),
      "--state-dir",     dir_ + "/state",
      "--lease-seconds", std::to_string(lease_seconds_)};
  if (!token_file_.empty()) argv.insert(argv.end(), {"--token-file", token_file_});
  argv.insert(argv.end(), coordinator_args_.begin(), coordinator_args_.end());
  coordinator_ = std::make_unique<Process>(
      in_netns(network_.netns, argv), dir_ + "/coordinator" + std::to_string(starts_++) + ".log");
  std::smatch m;
  std::regex re("\\(port ([0-9]+)\\)");
  std::string log;
  for (int i = 0; i < 500; ++i) {
    log = coordinator_->log();
    if (std::regex_search(log, m, re)) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_TRUE(std::regex_search(log, m, re)) << log;
  port_ = std::stoi(m[1]);
}

void Farm::stop_coordinator(int sig) {
  coordinator_->signal(sig);
  coordinator_->wait(30);
}

void Farm::restart_coordinator(int sig, double pause) {
  stop_coordinator(sig);
  if (pause > 0) std::this_thread::sleep_for(std::chrono::duration<double>(pause));
  start_coordinator(port_);
}

Process& Farm::worker(const std::vector<std::string>& extra) {
  return worker_in("", address(), extra);
}

Process& Farm::worker_in(const std::string& netns, const std::string& coordinator_address,
                         const std::vector<std::string>& extra) {
  std::vector<std::string> argv{rayfarm_binary(),    "worker",      "--coordinator",
                                coordinator_address, "--cache-dir", dir_ + "/cache"};
  if (!worker_token_file.empty()) argv.insert(argv.end(), {"--token-file", worker_token_file});
  argv.insert(argv.end(), worker_args.begin(), worker_args.end());
  argv.insert(argv.end(), extra.begin(), extra.end());
  workers_.push_back(std::make_unique<Process>(
      in_netns(netns, argv), dir_ + "/worker" + std::to_string(workers_.size()) + ".log"));
  return *workers_.back();
}

std::string Farm::client_command(const std::string& args) const {
  std::string token =
      (client_token_file.empty() ? "" : " --token-file " + client_token_file) + client_args;
  return "cd " + source_dir() + " && " + netns_prefix() + rayfarm_binary() + " " + args +
         " --coordinator " + address() + token;
}

CommandResult Farm::client(const std::string& args) const {
  return run_command(client_command(args));
}

CommandResult Farm::client_stdout(const std::string& args) const {
  // run_command adds 2>&1 outside the braces.
  return run_command("{ " + client_command(args) + " 2>/dev/null; }");
}

std::string Farm::submit(const std::string& args) const {
  // The job id is stdout alone (the importers' warnings go to stderr).
  CommandResult r = client_stdout("submit " + args);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  std::string id = r.output;
  while (!id.empty() && (id.back() == '\n' || id.back() == ' ')) id.pop_back();
  EXPECT_NE(id, "");
  return id;
}

nlohmann::json Farm::status(const std::string& job) const {
  // stdout alone: a retry's note goes to stderr.
  CommandResult r =
      run_command("{ " + client_command("status " + job + " --json") + " 2>/dev/null; }");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  return nlohmann::json::parse(r.output, nullptr, false);
}

std::string Farm::local(const std::string& args, FrameNumber frame) const {
  std::string out = dir_ + "/local-" + std::to_string(local_count_++) + ".exr";
  CommandResult r = run_command("cd " + source_dir() + " && " + rayfarm_binary() + " render " +
                                args + " --frame " + std::to_string(frame) + " -q -o " + out);
  EXPECT_EQ(r.exit_code, 0) << r.output;
  return out;
}

std::string Farm::fetched(const std::string& job, FrameNumber frame) const {
  char name[64];
  std::snprintf(name, sizeof name, "%s.%04u.exr", job.c_str(), frame);
  return dir_ + "/out-" + job + "/" + name;
}

std::string Farm::netns_prefix() const {
  return network_.netns.empty() ? "" : "/usr/sbin/ip netns exec " + network_.netns + " ";
}

std::shared_ptr<grpc::Channel> Farm::channel(const std::string& token) const {
  return coordinator_channel(address(), ClientCredentials{token, "", "", ""});
}

Token make_token(const std::string& dir, const std::string& name, const std::string& args) {
  CommandResult r = run_command("{ " + rayfarm_binary() + " token new " + args + " 2>/dev/null; }");
  EXPECT_EQ(r.exit_code, 0) << r.output;
  Token t;
  std::istringstream in(r.output);
  std::getline(in, t.token);
  std::getline(in, t.line);
  EXPECT_EQ(t.token.rfind("rft_", 0), 0u) << r.output;
  EXPECT_EQ(t.line.substr(0, 64), sha256_hex(t.token)) << "line 2 holds the digest";
  t.file = dir + "/" + name + ".token";
  write_text(t.file, t.token + "\n");
  return t;
}

void write_token_file(const std::string& path, const std::vector<const Token*>& tokens) {
  std::string text = "# accepted tokens\n";
  for (const Token* t : tokens) text += t->line + "\n";
  write_text(path, text);
}

std::string register_worker(pb::WorkerService::Stub& stub, const std::string& hostname) {
  grpc::ClientContext ctx;
  ctx.set_wait_for_ready(true);
  pb::RegisterRequest req;
  req.set_hostname(hostname);
  pb::RegisterResponse resp;
  grpc::Status s = stub.Register(&ctx, req, &resp);
  EXPECT_TRUE(s.ok()) << s.error_message();
  return resp.worker_id();
}

std::optional<pb::Task> lease_task(pb::WorkerService::Stub& stub, const std::string& worker_id) {
  grpc::ClientContext ctx;
  pb::LeaseRequest req;
  req.set_worker_id(worker_id);
  pb::LeaseResponse resp;
  grpc::Status s = stub.LeaseTask(&ctx, req, &resp);
  EXPECT_TRUE(s.ok()) << s.error_message();
  EXPECT_TRUE(resp.has_task()) << "no task for " << worker_id;
  if (!s.ok() || !resp.has_task()) return std::nullopt;
  return resp.task();
}

void lease_and_fail(pb::WorkerService::Stub& stub, const std::string& hostname,
                    const std::string& message, const std::vector<std::string>& log) {
  std::string id = register_worker(stub, hostname);
  std::optional<pb::Task> task = lease_task(stub, id);
  ASSERT_TRUE(task);
  grpc::ClientContext ctx;
  pb::FailRequest fr;
  fr.set_worker_id(id);
  fr.set_lease_id(task->lease_id());
  fr.set_task_id(task->task_id());
  fr.set_message(message);
  for (const std::string& l : log) fr.add_log(l);
  pb::FailResponse fresp;
  ASSERT_TRUE(stub.FailTask(&ctx, fr, &fresp).ok());
}

grpc::Status complete_with(pb::WorkerService::Stub& stub, const std::string& worker_id,
                           const pb::Task& task, const std::vector<pb::Chunk>& chunks) {
  grpc::ClientContext ctx;
  pb::CompleteResponse resp;
  auto w = stub.CompleteTask(&ctx, &resp);
  pb::CompleteRequest head;
  head.mutable_header()->set_worker_id(worker_id);
  head.mutable_header()->set_lease_id(task.lease_id());
  head.mutable_header()->set_task_id(task.task_id());
  w->Write(head);
  for (const pb::Chunk& c : chunks) {
    pb::CompleteRequest m;
    *m.mutable_chunk() = c;
    if (!w->Write(m)) break;
  }
  w->WritesDone();
  return w->Finish();
}

std::vector<pb::Chunk> chunks_of(const std::string& bytes) {
  std::vector<pb::Chunk> out;
  for_each_chunk(bytes, [&](pb::Chunk&& c) { out.push_back(std::move(c)); });
  return out;
}

grpc::Status submit_files(pb::JobService::Stub& stub, const std::string& scene_path,
                          const std::vector<BundleFile>& files, const std::string& frames,
                          std::string* job_id, const std::function<void(pb::JobSpec&)>& edit) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
  pb::SubmitResponse resp;
  auto w = stub.Submit(&ctx, &resp);
  pb::SubmitRequest head;
  head.mutable_spec()->set_scene_path(scene_path);
  head.mutable_spec()->set_frames(frames);
  for (const BundleFile& f : files) {
    pb::BundleFile* e = head.mutable_spec()->add_files();
    e->set_path(f.path);
    e->set_sha256(sha256_hex(f.bytes));
  }
  if (edit) edit(*head.mutable_spec());
  w->Write(head);
  for (const BundleFile& f : files)
    for (pb::Chunk& c : chunks_of(f.bytes)) {
      pb::SubmitRequest m;
      *m.mutable_blob_chunk() = c;
      if (!w->Write(m)) break;
    }
  w->WritesDone();
  grpc::Status st = w->Finish();
  if (st.ok() && job_id) *job_id = resp.job_id();
  return st;
}

}  // namespace rf::test
