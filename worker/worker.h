// The worker (DESIGN.md "Worker"): registers with one coordinator, leases tasks, fetches the
// scene bundle's blobs it lacks by digest, renders each task with the engine on all cores,
// renews the lease while rendering, uploads the sample buffer in chunks, and repeats.
//
// Scenes and their Embree BVH are cached by (bundle, scene file, settings), so consecutive tasks
// of one scene file, across frames, neither re-parse nor rebuild (a frame only selects the seed
// stream). Blobs are cached on local disk by digest.
// On SIGTERM or SIGINT it stops leasing; a task in flight is finished and uploaded if that takes
// less than drain_seconds from the signal, else handed back (re-queued without counting as a
// failure). With exit_when_idle it exits once the coordinator has no queued or leased work left
// that it could get.
#pragma once

#include <string>
#include <vector>

#include "farm/channel.h"

namespace rf {

struct WorkerOptions {
  std::string coordinator = "127.0.0.1:7070";
  ClientCredentials creds;  // token and TLS material (farm/channel.h)
  std::string cache_dir;    // default: $XDG_CACHE_HOME/rayfarm or ~/.cache/rayfarm
  // The blob cache's bound: after each new scene, the least recently used blobs go until the
  // cache holds at most this many bytes (never the blobs of the scene being set up). 0: no bound.
  uint64_t cache_bytes = uint64_t(20) << 30;
  double drain_seconds = 60;
  bool exit_when_idle = false;
  double idle_poll_seconds = 1;
  int max_tasks = 0;  // exit after this many tasks (0: no limit); for tests and benches
  // Exit 1 after this long without an answer from the coordinator (0: keep trying for ever).
  double give_up_after = 0;
  // Rewritten (its time, in Unix seconds) at least every max(15 s, lease / 3) while the worker's
  // loops turn, whether or not the coordinator answers: a container health check reads its age
  // (deploy/Dockerfile). Empty: none.
  std::string heartbeat_file;
  // Tags it advertises besides the automatic ones (farm/tags.h): "gpu", "pool=lighting", ...
  std::vector<std::string> tags;
};

// Runs until signalled (or idle with exit_when_idle). A coordinator that goes away (stopped,
// restarted, unreachable) is waited for with capped, jittered backoff; the worker exits only on
// a signal, when idle with exit_when_idle, after give_up_after seconds without a coordinator,
// or when the coordinator refuses it (UNAUTHENTICATED, PERMISSION_DENIED: throws with the
// reason). Returns the process exit status.
int run_worker(const WorkerOptions& options);

}  // namespace rf
