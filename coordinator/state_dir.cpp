#include "coordinator/state_dir.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include "coordinator/job_store.h"  // StoreError

namespace rf {

StateDirLock::StateDirLock(const std::string& dir) {
  if (dir.empty()) throw StoreError("the coordinator's state directory is not set");
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec)
    throw StoreError(dir + ": cannot create the state directory: " + ec.message() +
                     (ec == std::errc::read_only_file_system || ec == std::errc::permission_denied
                          ? " (the coordinator needs a writable --state-dir)"
                          : ""));
  std::string path = dir + "/lock";
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw StoreError(path + ": cannot open: " + std::strerror(errno));
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    int err = errno;
    char pid[32] = {};
    ssize_t n = ::pread(fd_, pid, sizeof pid - 1, 0);
    std::string holder = n > 0 ? std::string(pid, size_t(n)) : std::string("unknown");
    while (!holder.empty() && (holder.back() == '\n' || holder.back() == ' ')) holder.pop_back();
    ::close(fd_);
    fd_ = -1;
    if (err == EWOULDBLOCK)
      throw StoreError("state directory " + dir + " is in use by another coordinator (pid " +
                       holder + ", " + path + "); one coordinator per state directory");
    throw StoreError(path + ": cannot lock: " + std::strerror(err));
  }
  std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, pid.data(), pid.size(), 0) < 0) {
    // The lock holds without the pid; a second coordinator then names it "unknown".
  }
}

StateDirLock::~StateDirLock() {
  if (fd_ >= 0) ::close(fd_);
}

void rename_durably(const std::string& from, const std::string& to) {
  std::error_code ec;
  std::filesystem::rename(from, to, ec);
  if (ec) throw StoreError(from + ": cannot rename to " + to + ": " + ec.message());
  const std::string dir = std::filesystem::path(to).parent_path().string();
  int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (fd < 0 || ::fsync(fd) != 0) {
    const int e = errno;
    if (fd >= 0) ::close(fd);
    throw StoreError(dir + ": cannot flush the directory: " + std::strerror(e));
  }
  ::close(fd);
}

}  // namespace rf
