// `rayfarm`: every command of the project in one binary (commands.h lists the groups).
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <cstdio>
#include <memory>
#include <new>

#include "cli/commands.h"
#include "client/commands.h"
#include "engine/build_info.h"

int main(int argc, char** argv) {
  // Log lines (warnings of the scene importers, progress of services) go to stderr: stdout
  // carries what scripts read (`submit` prints the job id, `status --json`).
  spdlog::set_default_logger(spdlog::stderr_color_mt("rayfarm"));
  CLI::App app{"rayfarm: a distributed batch renderer"};
  app.require_subcommand(1);
  // Flags from a file (TOML: `key = value`, a command's own under `[command]`). Precedence: the
  // command line, then this file (named on the command line, so chosen for this run), then
  // RAYFARM_* variables (RAYFARM_COORDINATOR, RAYFARM_LOG_LEVEL, RAYFARM_LOG_FORMAT,
  // RAYFARM_TOKEN_FILE, RAYFARM_TLS_*), then defaults
  // (Cli.FlagsComeFromTheCommandLineThenTheConfigFileThenTheEnvironment). No render setting is
  // read from the environment.
  app.set_config("--config", "", "read flags from this TOML file ([command] sections)");
  app.set_version_flag("--version",
                       std::string(rf::build_id()) + "; kernels for this CPU: " + rf::cpu_isa());
  rf::cli::SharedOptions shared;
  shared.coordinator = rf::default_coordinator();
  app.add_option("--threads", shared.threads, "worker threads (default: all cores)")
      ->check(rf::cli::finite_in(0, 4096));
  std::vector<rf::cli::Command> commands;
  rf::cli::add_local_commands(app, shared, commands);
  rf::cli::add_service_commands(app, shared, commands);
  rf::cli::add_client_commands(app, shared, commands);
  rf::cli::add_completion_command(app, commands);  // last: it lists the others

  // Exit codes, the same for every command (README): 0 success, 1 failure at run time, 2 bad
  // usage (parse errors included), 3 cancelled (watch).
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;
  }
  std::unique_ptr<tbb::global_control> limit;
  if (shared.threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  size_t(shared.threads));
  try {
    for (const rf::cli::Command& c : commands) {
      if (!c.app->parsed()) continue;
      rf::cli::configure_logging(c.log ? *c.log : rf::cli::LogOptions{}, c.long_running);
      return c.run();
    }
  } catch (const rf::FarmError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return e.exit_status;
  } catch (const rf::cli::UsageError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr,
                 "error: out of memory (an allocation failed; smaller settings or more "
                 "memory needed)\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
