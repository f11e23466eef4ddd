// The rayfarm command line: main.cpp builds the app and runs the one command given; each command
// group registers its subcommands from its own file:
//   local.cpp     render, merge, compare, bench  (one machine, no server)
//   services.cpp  coordinator, worker, token     (the farm's long-running processes, tokens)
//   client.cpp    submit, status, watch, fetch, cancel, health  (talking to a coordinator)
#pragma once

#include <CLI/CLI.hpp>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "engine/scene.h"

namespace rf::cli {

// Thrown for bad command-line values that CLI11 cannot check by itself (exit status 2).
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct LogOptions {
  std::string level = "info", format = "text";
};

// A registered subcommand and what runs it; run() returns the process exit status.
struct Command {
  CLI::App* app;
  std::function<int()> run;
  bool long_running = false;  // a service: its log lines carry timestamps
  std::shared_ptr<LogOptions> log = {};  // its --log-level and --log-format, if it has them
};

// Options several groups bind: render threads, the coordinator address.
struct SharedOptions {
  int threads = 0;  // 0: all cores
  std::string coordinator;
  std::string token_file;  // the token shown to the coordinator (farm/auth.h client_token)
  std::string tls_ca, tls_cert, tls_key;  // PEM files (farm/channel.h load_client_credentials)
};

// `completion bash`: a completion script from the app's own commands and flags.
void add_completion_command(CLI::App& app, std::vector<Command>& out);
// A service's --log-level and --log-format (coordinator, worker). Each command has its own:
// CLI11 reads a variable (RAYFARM_LOG_LEVEL, RAYFARM_LOG_FORMAT) into every command's option the
// command line did not set, parsed or not, so one shared by two commands would let the
// environment overwrite the flag given.
std::shared_ptr<LogOptions> add_log_options(CLI::App* c);
// spdlog as the options say: JSON lines, or text (timestamped for a service).
void configure_logging(const LogOptions& log, bool long_running);

// A CLI11 check: a finite number in [lo, hi]. (CLI11's Range and PositiveNumber let NaN through,
// and an unsigned option takes "-1" as 2^64-1: every numeric flag gets one of these.)
CLI::Validator finite_in(double lo, double hi);
// --progress text|openjd (render, watch, submit --wait): Open Job Description progress lines.
void add_progress_option(CLI::App* c, std::string* progress);
// A size in bytes, with an optional binary unit (K, M, G, T). Throws CLI::ValidationError.
uint64_t byte_size_option(const std::string& name, const std::string& v);

// The paths a command writes: each must not be an existing non-regular file (a device, a FIFO,
// a directory), and no two may be the same file. Throws UsageError naming the flag.
void check_outputs(const std::vector<std::pair<std::string, std::string>>& flag_and_path);
// -o of render and merge: an .exr (its PNG preview goes beside it), or for merge also .rfb.
void check_extension(const std::string& flag, const std::string& path,
                     const std::vector<std::string>& allowed);

// --token-file, --tls-ca, --tls-cert, --tls-key on a command that talks to a coordinator.
void add_credential_options(CLI::App& cmd, SharedOptions& shared);

// The scene overrides `render` and `submit` share (--spp, --passes, --integrator, ...).
struct OverrideArgs {
  std::string res, integrator, filter, sampler, light_selection, shutter;
  std::optional<uint64_t> spp, seed;
  std::optional<uint32_t> passes;
  std::optional<int> max_depth;
  std::optional<double> noise_target;
  std::optional<std::string> aovs;
};
void add_override_options(CLI::App& cmd, OverrideArgs& args);
SceneOverrides overrides_of(const OverrideArgs& args);  // throws UsageError

void add_local_commands(CLI::App& app, SharedOptions& shared, std::vector<Command>& out);
void add_service_commands(CLI::App& app, SharedOptions& shared, std::vector<Command>& out);
void add_client_commands(CLI::App& app, SharedOptions& shared, std::vector<Command>& out);

}  // namespace rf::cli
