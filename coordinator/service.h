// The coordinator's server (DESIGN.md "Coordinator"): the job service for users and the worker
// service for workers on one gRPC port, beside the standard health service and server
// reflection. The job logic, its state and its recovery are the core's (core.h); this side
// speaks gRPC, streams payloads in chunks and bounds their sizes.
#pragma once

#include <atomic>
#include <memory>
#include <string>

#include "coordinator/core.h"

namespace rf {

struct CoordinatorOptions {
  std::string listen = "127.0.0.1:7070";
  std::string state_dir;
  // Accepted tokens (farm/auth.h), re-read on SIGHUP. Without one every call is admitted as an
  // admin, and the coordinator listens on loopback only.
  std::string token_file;
  // TLS (PEM files): the server's certificate chain and key; with a client CA, client
  // certificates are verified when sent and the worker methods require one (mutual TLS).
  std::string tls_cert, tls_key, tls_client_ca;
  // A second, plaintext listener serving only the health service (for probes without TLS).
  std::string health_listen;
  // Prometheus metrics over plain HTTP at /metrics (coordinator/metrics.h); empty: none.
  std::string metrics_listen;
  // The web monitor (coordinator/monitor.h) over HTTP, HTTPS with --tls-cert; empty: none.
  std::string monitor_listen;
  double lease_seconds = 30;
  uint32_t window_frames = 4;
  FairShare share = FairShare::Tenants;    // between jobs of equal priority (scheduler.h)
  JobLimits limits;                        // per job (core.h)
  double verify_fraction = 0;              // CoreOptions::verify_fraction
  uint64_t max_blob_bytes = 1ull << 30;    // one scene asset
  uint64_t max_bundle_bytes = 4ull << 30;  // all assets of one submit
  uint64_t max_buffer_bytes = 4ull << 30;  // one task's sample buffer
  // Retention (CoreOptions): --keep-finished (<= 0: for ever) and --blob-grace, in seconds.
  double keep_finished_seconds = 7 * 86400.0;
  uint64_t frame_memory = uint64_t(1) << 30;  // CoreOptions::frame_memory
  double blob_grace_seconds = 3600;
  // The binary whose `check-scenes` command parses submitted scenes in child processes
  // (scene_check.h): this one.
  std::string scene_check_binary = "/proc/self/exe";
};

class CoordinatorServer {
 public:
  // Opens (or creates) the state directory, restores jobs from it and starts serving. Throws
  // with a message naming the address or file on failure.
  explicit CoordinatorServer(const CoordinatorOptions& options);
  ~CoordinatorServer();
  int port() const;          // the bound port (useful with --listen HOST:0)
  int health_port() const;   // --health-listen's bound port (0 without it)
  int metrics_port() const;  // --metrics-listen's bound port (0 without it)
  int monitor_port() const;  // --monitor-listen's bound port (0 without it)
  void wait();               // until shutdown() is called
  void shutdown();           // stops accepting, ends streams, waits for handlers
  // Re-reads the token file and ends the monitor's sessions; on an error keeps the tokens it
  // has and rethrows.
  void reload_tokens();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// `rayfarm coordinator`: serves until SIGINT or SIGTERM.
int run_coordinator(const CoordinatorOptions& options);

}  // namespace rf
