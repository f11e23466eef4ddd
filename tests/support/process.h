// Child processes for the farm tests: real coordinator and worker processes on loopback, with
// their output in a log file, that a test can signal (SIGKILL a worker mid-task) and wait for.
#pragma once

#include <sys/types.h>

#include <string>
#include <vector>

namespace rf::test {

class Process {
 public:
  // Starts argv[0] with argv, stdout and stderr appended to log_path.
  Process(const std::vector<std::string>& argv, const std::string& log_path);
  ~Process();  // SIGKILLs it if still running
  Process(const Process&) = delete;
  Process& operator=(const Process&) = delete;

  void signal(int sig) const;
  // Waits up to timeout_s; the exit status (128 + signal for a signalled exit), or -1 on timeout.
  int wait(double timeout_s);
  bool running();
  std::string log() const;  // the log so far
  // Polls the log until it contains `text`; false after timeout_s.
  bool wait_for_log(const std::string& text, double timeout_s) const;
  pid_t pid() const { return pid_; }

 private:
  pid_t pid_ = -1;
  int status_ = -1;
  bool reaped_ = false;
  std::string log_path_;
};

// A field of /proc/PID/status in KiB ("VmRSS", "VmHWM"), or -1.
long proc_status_kib(pid_t pid, const std::string& field);

}  // namespace rf::test
