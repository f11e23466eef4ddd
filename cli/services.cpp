// The farm's long-running processes: `rayfarm coordinator` and `rayfarm worker`.
#include "cli/commands.h"
#include "client/commands.h"
#include "coordinator/service.h"
#include "worker/worker.h"

namespace rf::cli {

void add_service_commands(CLI::App& app, SharedOptions& shared, std::vector<Command>& out) {
  auto co = std::make_shared<CoordinatorOptions>();
  auto* coord = app.add_subcommand("coordinator", "serve jobs to workers (gRPC)");
  coord->add_option("--listen", co->listen, "address to listen on (HOST:PORT; port 0 picks one)");
  coord->add_option("--state-dir", co->state_dir, "durable state: database, checkpoints, blobs")
      ->required();
  coord->add_option("--lease-seconds", co->lease_seconds, "lease time of a task")
      ->check(CLI::PositiveNumber);
  coord->add_option("--window", co->window_frames, "frames open at once per job")
      ->check(CLI::PositiveNumber);
  out.push_back({coord, [co] { return run_coordinator(*co); }, true});

  auto wo = std::make_shared<WorkerOptions>();
  auto* worker = app.add_subcommand("worker", "lease and render tasks from a coordinator");
  worker->add_option("--coordinator", shared.coordinator,
                     "coordinator address (default: $RAYFARM_COORDINATOR, else 127.0.0.1:7070)");
  worker->add_option("--cache-dir", wo->cache_dir, "blob cache (default ~/.cache/rayfarm)");
  worker->add_option("--drain-seconds", wo->drain_seconds,
                     "on SIGTERM, finish the task in flight if done within this, else hand it back");
  worker->add_flag("--exit-when-idle", wo->exit_when_idle,
                   "exit once the coordinator has no queued or leased work left");
  worker->add_option("--max-tasks", wo->max_tasks, "exit after this many tasks");
  worker->add_option("--threads", shared.threads, "render threads (default: all cores)");
  out.push_back({worker,
                 [wo, &shared] {
                   wo->coordinator = shared.coordinator;
                   return run_worker(*wo);
                 },
                 true});
}

}  // namespace rf::cli
