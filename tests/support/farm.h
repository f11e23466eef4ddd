// The farm harness for end-to-end tests with real processes on loopback (no mocks of gRPC): a
// coordinator process on a temporary state directory, worker processes, the client commands,
// local renders to compare with, and raw gRPC stubs for requests the CLI would never send.
#pragma once

#include <grpcpp/grpcpp.h>

#include <csignal>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "engine/frame.h"
#include "proto/rayfarm.grpc.pb.h"
#include "tests/support/process.h"
#include "tests/support/test_support.h"

namespace rf::test {

// Every channel (RGBA and variance) of two EXRs within DESIGN.md's merge tolerance,
// |a-b| <= 1e-6 * max(|a|,|b|) + 1e-12 (in practice the farm's images are bit-identical).
void expect_same_image(const std::string& farm, const std::string& local);

// Where a farm's coordinator runs: by default on loopback in the test's own network namespace.
// With `netns`, the coordinator and the client commands run in that namespace (ip netns exec),
// the coordinator listens on listen_host and the clients call it at host.
struct FarmNetwork {
  std::string netns;
  std::string listen_host = "127.0.0.1";
  std::string host = "127.0.0.1";
};

class Farm {
 public:
  // A coordinator with this lease time; with a token file, it authenticates every call, and
  // client() and worker() show the tokens in client_token_file / worker_token_file.
  explicit Farm(const std::string& tag, double lease_seconds = 30,
                const std::string& coordinator_token_file = "",
                const std::vector<std::string>& coordinator_args = {}, FarmNetwork network = {});

  void start_coordinator(int port);  // and waits until it logs its port
  // Stops the coordinator with `sig` (SIGKILL: a crash; SIGTERM: a graceful stop), waits for it
  // to exit, and starts it again on the same port and state directory after `pause` seconds.
  void restart_coordinator(int sig = SIGKILL, double pause = 0);
  void stop_coordinator(int sig = SIGTERM);  // and waits for it to exit; start_coordinator(port())
  int port() const { return port_; }

  Process& worker(const std::vector<std::string>& extra = {"--exit-when-idle"});
  // A worker in network namespace `netns` (empty: the test's own) calling the coordinator at
  // `coordinator_address`.
  Process& worker_in(const std::string& netns, const std::string& coordinator_address,
                     const std::vector<std::string>& extra);
  // A client command against this coordinator (run from the source tree), output 2>&1.
  CommandResult client(const std::string& args) const;
  CommandResult client_stdout(const std::string& args) const;  // its stdout alone
  std::string submit(const std::string& args) const;    // the job id; expects success
  nlohmann::json status(const std::string& job) const;  // "": every job (status --json)
  // A local render of the same job and frame, for comparison; returns the EXR's path.
  std::string local(const std::string& args, FrameNumber frame) const;
  // Where `fetch JOB -o DIR/out-JOB` puts a frame.
  std::string fetched(const std::string& job, FrameNumber frame) const;

  std::string worker_log(size_t i) const { return workers_.at(i)->log(); }
  std::string address() const { return network_.host + ":" + std::to_string(port_); }
  const std::string& dir() const { return dir_; }
  Process& coordinator() { return *coordinator_; }
  // A plain channel; with a token, it sends "authorization: Bearer TOKEN" on every call.
  std::shared_ptr<grpc::Channel> channel(const std::string& token = "") const;

  std::string client_token_file, worker_token_file;
  std::string client_args;               // appended to every client command (e.g. --tls-ca)
  std::vector<std::string> worker_args;  // appended to every worker's command line

 private:
  std::string dir_;
  double lease_seconds_;
  std::string token_file_;
  std::vector<std::string> coordinator_args_;
  FarmNetwork network_;
  int port_ = 0, starts_ = 0;
  mutable int local_count_ = 0;
  std::unique_ptr<Process> coordinator_;
  std::vector<std::unique_ptr<Process>> workers_;

  // "ip netns exec NS " when the coordinator has a namespace, for client command lines.
  std::string netns_prefix() const;
  std::string client_command(const std::string& args) const;  // a shell command line
};

// A token made by `rayfarm token new` (written to DIR/NAME.token): the token and its token-file
// line.
struct Token {
  std::string token, line, file;
};
Token make_token(const std::string& dir, const std::string& name, const std::string& args);
// A coordinator's token file accepting these tokens.
void write_token_file(const std::string& path, const std::vector<const Token*>& tokens);

// Registers a worker under `hostname` through a raw stub; the id the coordinator issued.
std::string register_worker(rayfarm::v1::WorkerService::Stub& stub, const std::string& hostname);
// Leases a task for a registered worker; nothing (and a test failure) when none is given.
std::optional<rayfarm::v1::Task> lease_task(rayfarm::v1::WorkerService::Stub& stub,
                                            const std::string& worker_id);
// Registers as `hostname`, leases a task and reports it failed with `message` (and these log
// lines of the attempt).
void lease_and_fail(rayfarm::v1::WorkerService::Stub& stub, const std::string& hostname,
                    const std::string& message, const std::vector<std::string>& log = {});
// CompleteTask with a header naming worker_id and the task's lease, then these chunks.
grpc::Status complete_with(rayfarm::v1::WorkerService::Stub& stub, const std::string& worker_id,
                           const rayfarm::v1::Task& task,
                           const std::vector<rayfarm::v1::Chunk>& chunks);
std::vector<rayfarm::v1::Chunk> chunks_of(const std::string& bytes);

// A file of a bundle sent by submit_files: its path in the bundle and its bytes.
struct BundleFile {
  std::string path, bytes;
};
// Submits, through a raw stub, a job of scene_path over these files (each uploaded; none parsed
// here, as a hostile client would send them), with `frames` as its range and `edit` applied to
// the spec last; the call's status, and the job id in *job_id when it was accepted.
grpc::Status submit_files(rayfarm::v1::JobService::Stub& stub, const std::string& scene_path,
                          const std::vector<BundleFile>& files, const std::string& frames = "",
                          std::string* job_id = nullptr,
                          const std::function<void(rayfarm::v1::JobSpec&)>& edit = {});

}  // namespace rf::test
