#include "coordinator/scene_check.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <spdlog/spdlog.h>
#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <memory>
#include <mutex>
#include <new>
#include <set>
#include <sstream>

#include "coordinator/errors.h"
#include "coordinator/spec_codec.h"
#include "farm/frame_range.h"

extern char** environ;

// AddressSanitizer reserves terabytes of address space for its shadow before main: under it the
// child cannot have RLIMIT_AS (its CPU and wall limits still hold).
#if defined(__SANITIZE_ADDRESS__)
#define RAYFARM_SCENE_CHECK_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define RAYFARM_SCENE_CHECK_ASAN 1
#endif
#endif

namespace rf {

namespace {

constexpr size_t kMaxAnswerBytes = size_t(64) << 20;  // the child's stdout
constexpr size_t kStderrTail = 2048;                  // kept for the log when a child dies
constexpr size_t kMaxSpecBytes = size_t(256) << 20;   // the child's stdin

[[noreturn]] void refuse(ErrorCode code, const std::string& message) {
  throw CoordinatorError(code, message);
}

std::string scene_named(const std::string& scene) {
  return "scene '" + printable(scene.substr(0, 200)) + "'";
}

// One scene parsed, checked and summarised; `path` is where to read it from.
SceneSummary summarize_file(const std::string& path, const JobSpec& spec,
                            const ImportLimits& limits, size_t* warnings = nullptr) {
  Scene scene = load_scene(path, spec.overrides, limits);
  check_renderable(scene);
  if (warnings) *warnings = scene.warnings.size();
  return summarize(scene);
}

// ---- The child's side.

void emit(const nlohmann::json& line) {
  std::string s = line.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
  s += '\n';
  std::fwrite(s.data(), 1, s.size(), stdout);
  std::fflush(stdout);
}

void emit_error(const std::string& code, const std::string& message) {
  emit({{"error", message}, {"code", code}});
}

void set_limit(int resource, rlim_t soft, rlim_t hard) {
  rlimit r{soft, hard};
  if (::setrlimit(resource, &r) != 0)
    throw std::runtime_error(std::string("setrlimit: ") + std::strerror(errno));
}

// ---- The parent's side.

// At most `children` checks at once; a check waits its turn up to the wall time, and the queue
// holds at most 64 per child. A check that cannot start is UNAVAILABLE: the client retries within
// its --timeout, and its request id keeps the retry from making a second job.
struct Gate {
  std::mutex m;
  std::condition_variable cv;
  uint64_t running = 0, waiting = 0;
};

class GateTicket {
 public:
  GateTicket(Gate& g, const SceneCheckLimits& limits) : g_(g) {
    std::unique_lock lock(g_.m);
    uint64_t slots = std::max<uint64_t>(1, limits.children);
    if (g_.running >= slots && g_.waiting >= 64 * slots)
      refuse(ErrorCode::Unavailable, std::to_string(g_.running) + " scene checks are running and " +
                                         std::to_string(g_.waiting) +
                                         " waiting (the limit parse_children is " +
                                         std::to_string(slots) + "); submit again later");
    ++g_.waiting;
    bool got = g_.cv.wait_for(lock, std::chrono::seconds(limits.wall_seconds),
                              [&] { return g_.running < slots; });
    --g_.waiting;
    if (!got)
      refuse(ErrorCode::Unavailable,
             "no scene check could start within " + std::to_string(limits.wall_seconds) +
                 " s (parse_children = " + std::to_string(slots) + " checks at once are busy)");
    ++g_.running;
  }
  ~GateTicket() {
    std::lock_guard lock(g_.m);
    --g_.running;
    g_.cv.notify_one();
  }
  GateTicket(const GateTicket&) = delete;
  GateTicket& operator=(const GateTicket&) = delete;

 private:
  Gate& g_;
};

struct Fd {
  int fd = -1;
  Fd() = default;
  explicit Fd(int f) : fd(f) {}
  ~Fd() { reset(); }
  Fd(const Fd&) = delete;
  Fd& operator=(const Fd&) = delete;
  void reset() {
    if (fd >= 0) ::close(fd);
    fd = -1;
  }
};

struct ChildRun {
  std::string out, err_tail;
  int status = 0;
  bool timed_out = false, answer_too_long = false;
};

void write_all(int fd, const std::string& bytes) {
  size_t done = 0;
  while (done < bytes.size()) {
    ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) refuse(ErrorCode::Internal, std::string("scene check: ") + std::strerror(errno));
    done += size_t(n);
  }
}

// Runs argv with `input` on stdin, reading its stdout and stderr until it exits or the wall
// time runs out (then it is killed).
ChildRun run_child(const std::vector<std::string>& argv, const std::string& input,
                   double wall_seconds) {
  Fd in(::memfd_create("rayfarm-scene-check", MFD_CLOEXEC));
  if (in.fd < 0) refuse(ErrorCode::Internal, std::string("memfd_create: ") + std::strerror(errno));
  write_all(in.fd, input);
  ::lseek(in.fd, 0, SEEK_SET);
  int out_pipe[2], err_pipe[2];
  if (::pipe2(out_pipe, O_CLOEXEC) != 0)
    refuse(ErrorCode::Internal, std::string("pipe: ") + std::strerror(errno));
  Fd out_r(out_pipe[0]), out_w(out_pipe[1]);
  if (::pipe2(err_pipe, O_CLOEXEC) != 0)
    refuse(ErrorCode::Internal, std::string("pipe: ") + std::strerror(errno));
  Fd err_r(err_pipe[0]), err_w(err_pipe[1]);

  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_adddup2(&fa, in.fd, 0);
  posix_spawn_file_actions_adddup2(&fa, out_w.fd, 1);
  posix_spawn_file_actions_adddup2(&fa, err_w.fd, 2);
  posix_spawn_file_actions_addclosefrom_np(&fa, 3);  // no state directory lock, no sockets
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  pid_t pid = -1;
  int rc = ::posix_spawn(&pid, argv[0].c_str(), &fa, nullptr, args.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  if (rc != 0)
    refuse(ErrorCode::Unavailable,
           std::string("cannot start the scene check (") + std::strerror(rc) + ")");
  out_w.reset();
  err_w.reset();
  in.reset();

  ChildRun run;
  auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(wall_seconds);
  char buf[65536];
  while (out_r.fd >= 0 || err_r.fd >= 0) {
    auto left = std::chrono::duration_cast<std::chrono::milliseconds>(
        deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) {
      run.timed_out = true;
      break;
    }
    pollfd p[2] = {{out_r.fd, POLLIN, 0}, {err_r.fd, POLLIN, 0}};
    int n = ::poll(p, 2, int(std::min<int64_t>(left.count(), 1000)));
    if (n < 0 && errno != EINTR) break;
    for (int i = 0; i < 2; ++i) {
      if (p[i].fd < 0 || !(p[i].revents & (POLLIN | POLLHUP | POLLERR))) continue;
      ssize_t got = ::read(p[i].fd, buf, sizeof buf);
      if (got < 0 && errno == EINTR) continue;
      if (got <= 0) {
        (i == 0 ? out_r : err_r).reset();
        continue;
      }
      if (i == 0) {
        run.out.append(buf, size_t(got));
        if (run.out.size() > kMaxAnswerBytes) {
          run.answer_too_long = true;
          out_r.reset();
          err_r.reset();
        }
      } else {
        run.err_tail.append(buf, size_t(got));
        if (run.err_tail.size() > 2 * kStderrTail)
          run.err_tail.erase(0, run.err_tail.size() - kStderrTail);
      }
    }
  }
  if (run.timed_out || run.answer_too_long) ::kill(pid, SIGKILL);
  while (::waitpid(pid, &run.status, 0) < 0 && errno == EINTR) {
  }
  return run;
}

std::string signal_name(int sig) {
  switch (sig) {
    case SIGSEGV:
      return "SIGSEGV";
    case SIGABRT:
      return "SIGABRT";
    case SIGBUS:
      return "SIGBUS";
    case SIGKILL:
      return "SIGKILL";
    case SIGXCPU:
      return "SIGXCPU";
    case SIGFPE:
      return "SIGFPE";
    case SIGILL:
      return "SIGILL";
    default:
      return "signal " + std::to_string(sig);
  }
}

std::vector<SceneSummary> check_in_child(const std::string& binary, const SceneCheckLimits& limits,
                                         const std::string& bundle_dir, const JobSpec& spec) {
  std::vector<std::string> paths = job_scene_paths(spec);
  std::vector<std::string> argv = {binary,          "check-scenes",
                                   "--bundle",      bundle_dir,
                                   "--memory-mb",   std::to_string(limits.memory_mb),
                                   "--cpu-seconds", std::to_string(limits.cpu_seconds)};
  for (auto [name, value] : {std::pair<const char*, uint64_t>{"files", limits.import.files},
                             {"bytes", limits.import.bytes},
                             {"elements", limits.import.elements}}) {
    argv.push_back("--import-limit");
    argv.push_back(std::string(name) + "=" + std::to_string(value));
  }
  ChildRun run = run_child(argv, encode_spec(spec), double(limits.wall_seconds));

  std::vector<SceneSummary> out;
  std::optional<nlohmann::json> last;
  std::istringstream lines(run.out);
  for (std::string line; std::getline(lines, line);) {
    nlohmann::json j = nlohmann::json::parse(line, nullptr, false);
    if (j.is_discarded() || !j.is_object()) break;
    if (j.contains("summary")) {
      try {
        out.push_back(summary_from_json(j.at("summary")));
      } catch (const std::exception& e) {
        refuse(ErrorCode::Internal, std::string("the scene check's answer: ") + e.what());
      }
      continue;
    }
    last = j;
    break;
  }
  const std::string current =
      out.size() < paths.size() ? scene_named(paths[out.size()]) : std::string("the scenes");
  if (last && last->contains("ok") && out.size() == paths.size()) return out;
  if (last && last->contains("error") && (*last)["error"].is_string()) {
    std::string code = last->value("code", "");
    refuse(code == "resource_exhausted" ? ErrorCode::ResourceExhausted : ErrorCode::InvalidArgument,
           (*last)["error"].get<std::string>());
  }
  if (run.timed_out)
    refuse(ErrorCode::ResourceExhausted, current + ": the import was stopped after " +
                                             std::to_string(limits.wall_seconds) +
                                             " s (the limit parse_wall_seconds)");
  if (run.answer_too_long)
    refuse(ErrorCode::ResourceExhausted,
           "the scene check answered more than " + std::to_string(kMaxAnswerBytes) + " bytes");
  if (WIFSIGNALED(run.status)) {
    int sig = WTERMSIG(run.status);
    if (sig == SIGXCPU || sig == SIGKILL)
      refuse(ErrorCode::ResourceExhausted, current + ": the import used more than " +
                                               std::to_string(limits.cpu_seconds) +
                                               " s of CPU time (the limit parse_cpu_seconds)");
    spdlog::warn("scene check: the importer died of {}; its last words: {}", signal_name(sig),
                 printable(run.err_tail.size() > kStderrTail
                               ? run.err_tail.substr(run.err_tail.size() - kStderrTail)
                               : run.err_tail));
    refuse(ErrorCode::InvalidArgument,
           current + ": the importer crashed (" + signal_name(sig) + ") on it, within " +
               std::to_string(limits.memory_mb) +
               " MiB of memory (the limit parse_memory_mb); the scene is refused");
  }
  refuse(ErrorCode::InvalidArgument,
         current + ": the scene check exited with status " +
             std::to_string(WIFEXITED(run.status) ? WEXITSTATUS(run.status) : -1) +
             " without an answer, within " + std::to_string(limits.memory_mb) +
             " MiB of memory (the limit parse_memory_mb)");
}

}  // namespace

std::vector<std::string> job_scene_paths(const JobSpec& spec) {
  std::vector<FrameNumber> frames =
      spec.frames.empty() ? std::vector<FrameNumber>{0} : parse_frame_range(spec.frames);
  std::vector<std::string> paths;
  std::set<std::string> seen;
  for (FrameNumber f : frames) {
    std::string p = expand_frame_pattern(spec.scene_path, f);
    if (seen.insert(p).second) paths.push_back(p);
  }
  return paths;
}

SceneChecker child_scene_checker(std::string binary, SceneCheckLimits limits) {
  auto gate = std::make_shared<Gate>();
  return [binary = std::move(binary), limits, gate](const std::string& bundle_dir,
                                                    const JobSpec& spec) {
    GateTicket ticket(*gate, limits);
    return check_in_child(binary, limits, bundle_dir, spec);
  };
}

SceneChecker in_process_scene_checker(ImportLimits limits) {
  return [limits](const std::string& bundle_dir, const JobSpec& spec) {
    std::vector<SceneSummary> out;
    for (const std::string& p : job_scene_paths(spec)) {
      try {
        out.push_back(summarize_file(bundle_dir + "/" + p, spec, limits));
      } catch (const std::exception& e) {
        refuse(ErrorCode::InvalidArgument, e.what());
      }
    }
    return out;
  };
}

int run_scene_check_child(const std::string& bundle_dir, const SceneCheckLimits& limits) {
  std::string current;
  try {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // a coordinator that dies takes its checks with it
    if (::getppid() == 1) return 1;
    set_limit(RLIMIT_CORE, 0, 0);
#ifndef RAYFARM_SCENE_CHECK_ASAN
    set_limit(RLIMIT_AS, rlim_t(limits.memory_mb) << 20, rlim_t(limits.memory_mb) << 20);
#endif
    set_limit(RLIMIT_CPU, rlim_t(limits.cpu_seconds), rlim_t(limits.cpu_seconds) + 1);
    set_import_threads(1);
    if (::chdir(bundle_dir.c_str()) != 0) {
      emit_error("invalid_argument", "the bundle cannot be read");
      return 1;
    }
    std::string request;
    char buf[65536];
    for (ssize_t n; (n = ::read(0, buf, sizeof buf)) != 0;) {
      if (n < 0 && errno == EINTR) continue;
      if (n < 0 || request.size() + size_t(n) > kMaxSpecBytes) {
        emit_error("invalid_argument", "the scene check's request cannot be read");
        return 1;
      }
      request.append(buf, size_t(n));
    }
    std::optional<JobSpec> spec = decode_spec(request);
    if (!spec) {
      emit_error("invalid_argument", "the scene check's request is not a job spec");
      return 1;
    }
    std::vector<std::string> paths = job_scene_paths(*spec);
    for (size_t i = 0; i < paths.size(); ++i) {
      current = paths[i];
      size_t warnings = 0;
      SceneSummary s = summarize_file(paths[i], *spec, limits.import, &warnings);
      emit({{"scene", i}, {"summary", to_json(s)}, {"warnings", warnings}});
    }
    emit({{"ok", true}});
    return 0;
  } catch (const std::bad_alloc&) {
    emit_error("resource_exhausted",
               (current.empty() ? std::string("the scenes") : scene_named(current)) +
                   ": the import needed more than " + std::to_string(limits.memory_mb) +
                   " MiB of memory (the limit parse_memory_mb)");
  } catch (const std::exception& e) {
    emit_error("invalid_argument", e.what());
  }
  return 1;
}

}  // namespace rf
