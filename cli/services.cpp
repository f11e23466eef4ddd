// The farm's long-running processes: `rayfarm coordinator` and `rayfarm worker`.
#include "cli/commands.h"
#include "client/commands.h"
#include "coordinator/scene_check.h"
#include "coordinator/service.h"
#include "farm/auth.h"
#include "farm/tags.h"
#include "worker/worker.h"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <ctime>

namespace rf::cli {

namespace {

// HOST:PORT with a port in 0..65535 (0 picks one), [IPv6]:PORT, or unix:PATH; gRPC would take
// "127.0.0.1:99999" as port 34463 (99999 mod 65536).
CLI::Validator listen_address() {
  return CLI::Validator(
      [](std::string& s) -> std::string {
        if (s.rfind("unix:", 0) == 0 && s.size() > 5) return "";
        size_t colon = s.rfind(':');
        std::string host = colon == std::string::npos ? "" : s.substr(0, colon);
        std::string port = colon == std::string::npos ? "" : s.substr(colon + 1);
        bool digits = !port.empty() && port.size() <= 5 &&
                      port.find_first_not_of("0123456789") == std::string::npos;
        if (host.empty() || !digits)
          return "'" + s + "' is not an address (HOST:PORT, e.g. 127.0.0.1:7070 or 0.0.0.0:0)";
        if (std::stoul(port) > 65535) return "port " + port + " is outside 0..65535";
        return "";
      },
      "HOST:PORT");
}

}  // namespace

namespace {

// A duration option: a number of seconds with a unit (s, m, h, d; none: seconds), or "never"
// (<= 0) where `never_ok`.
double duration_option(const std::string& name, const std::string& v, bool never_ok) {
  if (never_ok && v == "never") return 0;
  size_t end = 0;
  double n = -1;
  try {
    n = std::stod(v, &end);
  } catch (const std::exception&) {
  }
  const std::string unit = v.substr(std::min(end, v.size()));
  const double scale = unit.empty() || unit == "s" ? 1
                       : unit == "m"               ? 60
                       : unit == "h"               ? 3600
                       : unit == "d"               ? 86400
                                                   : -1;
  if (!(n > 0) || scale < 0 || !std::isfinite(n * scale) || n * scale > 1e10)
    throw CLI::ValidationError(
        name, "'" + v + "' is not a duration (90s, 30m, 12h, 7d" + (never_ok ? ", never)" : ")"));
  return n * scale;
}

}  // namespace

void add_service_commands(CLI::App& app, SharedOptions& shared, std::vector<Command>& out) {
  auto co = std::make_shared<CoordinatorOptions>();
  auto* coord = app.add_subcommand("coordinator", "serve jobs to workers (gRPC)");
  coord->add_option("--listen", co->listen, "address to listen on (HOST:PORT; port 0 picks one)")
      ->check(listen_address());
  coord->add_option("--state-dir", co->state_dir, "durable state: database, checkpoints, blobs")
      ->required();
  coord->add_option("--lease-seconds", co->lease_seconds, "lease time of a task")
      ->check(finite_in(0.1, 86400));
  coord
      ->add_option_function<std::string>(
          "--keep-finished",
          [co](const std::string& v) {
            co->keep_finished_seconds = duration_option("--keep-finished", v, true);
          },
          "how long finished jobs (completed, failed, cancelled) are kept after they end before "
          "their images, checkpoints and records are removed: 90s, 30m, 12h, 7d, or never "
          "(default 7d)")
      ->default_str("7d");
  coord
      ->add_option_function<std::string>(
          "--frame-memory",
          [co](const std::string& v) { co->frame_memory = byte_size_option("--frame-memory", v); },
          "bytes of a frame's merged prefix and waiting results held in memory; a larger frame "
          "is kept in tiles in unlinked files in its checkpoint folder (0: every frame whole)")
      ->default_str("1G");
  coord
      ->add_option_function<std::string>(
          "--blob-grace",
          [co](const std::string& v) {
            co->blob_grace_seconds = duration_option("--blob-grace", v, false);
          },
          "how long an uploaded scene file that no job uses is kept after it was last uploaded "
          "or asked for (default 1h)")
      ->default_str("1h");
  coord->add_option("--window", co->window_frames, "frames open at once per job")
      ->check(finite_in(1, 10000));
  coord
      ->add_option("--fair-share", co->share,
                   "between jobs of equal priority, share workers by tenant, then job (tenants), "
                   "by job (jobs), or not at all: submission order (none)")
      ->transform(
          CLI::CheckedTransformer(std::map<std::string, FairShare>{{"tenants", FairShare::Tenants},
                                                                   {"jobs", FairShare::Jobs},
                                                                   {"none", FairShare::None}},
                                  CLI::ignore_case));
  coord->add_option_function<std::vector<std::string>>(
      "--limit",
      [co](const std::vector<std::string>& items) {
        for (const std::string& item : items) {
          size_t eq = item.find('=');
          uint64_t value = 0;
          bool ok = eq != std::string::npos && eq + 1 < item.size() &&
                    std::isdigit(static_cast<unsigned char>(item[eq + 1]));
          try {
            if (ok) value = std::stoull(item.substr(eq + 1));
          } catch (const std::exception&) {
            ok = false;
          }
          try {
            ok = ok && co->limits.set(item.substr(0, eq), value);
          } catch (const std::invalid_argument& e) {
            throw CLI::ValidationError("--limit", "'" + item + "': " + e.what());
          }
          if (!ok) {
            std::string names;
            for (const std::string& n : JobLimits::names()) names += " " + n;
            throw CLI::ValidationError("--limit",
                                       "'" + item + "' is not NAME=VALUE with NAME one of" + names);
          }
        }
      },
      "a per-job limit, NAME=VALUE (docs/security.md; repeatable)");
  coord
      ->add_option("--verify-fraction", co->verify_fraction,
                   "render this fraction of tasks on two workers and merge only bit-identical "
                   "results; a third settles a disagreement and the outvoted worker is refused")
      ->check(finite_in(0, 1));
  coord->add_option("--tls-cert", co->tls_cert, "serve TLS with this certificate chain (PEM)");
  coord->add_option("--tls-key", co->tls_key, "the key of --tls-cert (PEM)");
  coord->add_option("--tls-client-ca", co->tls_client_ca,
                    "mutual TLS: verify client certificates against this CA (PEM); the worker "
                    "methods then require one");
  coord
      ->add_option("--health-listen", co->health_listen,
                   "also serve the health service alone, in plaintext, here (HOST:PORT; for "
                   "probes that cannot speak TLS)")
      ->check(listen_address());
  coord
      ->add_option("--metrics-listen", co->metrics_listen,
                   "serve Prometheus metrics over HTTP at /metrics here (IP:PORT, e.g. "
                   "0.0.0.0:9464; docs/deploy.md)")
      ->check(listen_address());
  coord
      ->add_option("--monitor-listen", co->monitor_listen,
                   "serve the web monitor here (HOST:PORT; HTTPS with --tls-cert; loopback only "
                   "without --token-file; docs/farm.md)")
      ->check(listen_address());
  coord->add_option("--token-file", co->token_file,
                    "accepted tokens, one 'SHA256 ROLE TENANT [expires=...]' per line; re-read "
                    "on SIGHUP (without it: loopback only, no authentication)");
  auto coord_log = add_log_options(coord);
  out.push_back({coord,
                 [co] {
                   if (co->tls_cert.empty() != co->tls_key.empty())
                     throw UsageError(co->tls_cert.empty() ? "--tls-key needs --tls-cert"
                                                           : "--tls-cert needs --tls-key");
                   if (!co->tls_client_ca.empty() && co->tls_cert.empty())
                     throw UsageError("--tls-client-ca needs --tls-cert and --tls-key");
                   return run_coordinator(*co);
                 },
                 true, coord_log});

  // The coordinator's scene check (coordinator/scene_check.h): a child it starts itself, hidden
  // from --help.
  struct CheckArgs {
    std::string bundle;
    SceneCheckLimits limits;
  };
  auto ca = std::make_shared<CheckArgs>();
  auto* check = app.add_subcommand("check-scenes", "(internal) the coordinator's scene check");
  check->group("");
  check->add_option("--bundle", ca->bundle, "the materialised bundle")->required();
  check->add_option("--memory-mb", ca->limits.memory_mb)->check(finite_in(64, 1e12));
  check->add_option("--cpu-seconds", ca->limits.cpu_seconds)->check(finite_in(1, 1e9));
  check->add_option_function<std::vector<std::string>>(
      "--import-limit", [ca](const std::vector<std::string>& items) {
        for (const std::string& item : items) {
          size_t eq = item.find('=');
          bool ok = eq != std::string::npos;
          try {
            ok = ok && ca->limits.import.set(item.substr(0, eq), std::stoull(item.substr(eq + 1)));
          } catch (const std::exception&) {
            ok = false;
          }
          if (!ok) throw CLI::ValidationError("--import-limit", "'" + item + "' is not NAME=VALUE");
        }
      });
  out.push_back({check, [ca] { return run_scene_check_child(ca->bundle, ca->limits); }});

  auto wo = std::make_shared<WorkerOptions>();
  auto* worker = app.add_subcommand("worker", "lease and render tasks from a coordinator");
  worker->add_option("--coordinator", shared.coordinator,
                     "coordinator address (default: $RAYFARM_COORDINATOR, else 127.0.0.1:7070)");
  worker->add_option("--cache-dir", wo->cache_dir, "blob cache (default ~/.cache/rayfarm)");
  worker
      ->add_option_function<std::string>(
          "--cache-bytes",
          [wo](const std::string& v) { wo->cache_bytes = byte_size_option("--cache-bytes", v); },
          "bound of the blob cache: least recently used scene files are removed beyond it "
          "(bytes, or with K, M, G, T; 0: no bound; default 20G)")
      ->default_str("20G");
  worker
      ->add_option("--drain-seconds", wo->drain_seconds,
                   "on SIGTERM, finish the task in flight if done within this, else hand it back")
      ->check(finite_in(0, 86400));
  worker->add_flag("--exit-when-idle", wo->exit_when_idle,
                   "exit once the coordinator has no queued or leased work left");
  worker->add_option("--max-tasks", wo->max_tasks, "exit after this many tasks")
      ->check(finite_in(0, 2e9));
  worker
      ->add_option("--give-up-after", wo->give_up_after,
                   "exit 1 after this many seconds without an answer from the coordinator "
                   "(default: keep waiting; for batch schedulers)")
      ->check(finite_in(0, 1e9));
  worker
      ->add_option("--heartbeat-file", wo->heartbeat_file,
                   "rewrite this file at least every max(15 s, lease/3) while the worker runs, "
                   "for container health checks (default: $RAYFARM_HEARTBEAT_FILE; docs/deploy.md)")
      ->envname("RAYFARM_HEARTBEAT_FILE");
  worker
      ->add_option("--tag", wo->tags,
                   "a tag to advertise, NAME or NAME=VALUE (repeatable; jobs may require tags); "
                   "isa=, cores= and memory_gb= are automatic")
      ->check([](const std::string& t) { return tag_problem(t); });
  worker
      ->add_option_function<std::string>(
          "--pool", [wo](const std::string& p) { wo->tags.push_back("pool=" + p); },
          "the worker pool it belongs to (the tag pool=NAME)")
      ->check([](const std::string& p) { return tag_problem("pool=" + p); });
  worker->add_option("--threads", shared.threads, "render threads (default: all cores)")
      ->check(finite_in(0, 4096));
  add_credential_options(*worker, shared);
  auto worker_log = add_log_options(worker);
  out.push_back({worker,
                 [wo, &shared] {
                   wo->coordinator = shared.coordinator;
                   wo->creds = load_client_credentials(shared.token_file, shared.tls_ca,
                                                       shared.tls_cert, shared.tls_key);
                   return run_worker(*wo);
                 },
                 true, worker_log});

  struct TokenArgs {
    std::string role = "client", tenant = "default", expires;
  };
  auto ta = std::make_shared<TokenArgs>();
  auto* token = app.add_subcommand("token", "make tokens for a coordinator's --token-file");
  token->require_subcommand(1);
  auto* token_new = token->add_subcommand(
      "new", "print a new token (line 1) and the token-file line that accepts it (line 2)");
  token_new->add_option("--role", ta->role, "client, worker or admin")
      ->check(CLI::IsMember({"client", "worker", "admin"}));
  token_new->add_option("--tenant", ta->tenant, "whose jobs a client token sees");
  token_new->add_option("--expires", ta->expires, "expiry, UTC: YYYY-MM-DD[THH:MM:SSZ]");
  out.push_back({token_new, [ta] {
                   std::optional<int64_t> expires;
                   if (!ta->expires.empty()) {
                     expires = parse_utc_time(ta->expires);
                     if (!expires)
                       throw UsageError("--expires '" + ta->expires +
                                        "' is not YYYY-MM-DD or YYYY-MM-DDTHH:MM:SSZ");
                     if (*expires <= int64_t(std::time(nullptr)))
                       throw UsageError("--expires " + ta->expires +
                                        " is in the past: the token would never be accepted");
                   }
                   std::string t = new_token(), line;
                   try {
                     line = token_file_line(t, *parse_role(ta->role), ta->tenant, expires);
                   } catch (const std::invalid_argument& e) {
                     throw UsageError(std::string("--tenant: ") + e.what());
                   }
                   std::printf("%s\n%s\n", t.c_str(), line.c_str());
                   return 0;
                 }});
}

}  // namespace rf::cli
