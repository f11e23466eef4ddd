#include "coordinator/group_sync.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace rf {

GroupSync::GroupSync(const std::string& dir) : dir_(dir) {
  fd_ = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd_ < 0) throw std::runtime_error(dir + ": cannot open: " + std::strerror(errno));
}

GroupSync::~GroupSync() {
  if (fd_ >= 0) ::close(fd_);
}

void GroupSync::sync() {
  std::unique_lock lock(mu_);
  const uint64_t mine = ++requested_;  // the caller's writes precede this ticket
  while (durable_ < mine) {
    if (flushing_) {  // a flush runs, perhaps begun before these writes: wait, then look again
      done_cv_.wait(lock);
      continue;
    }
    flushing_ = true;
    const uint64_t upto = requested_;  // every write of these tickets was made before this point
    lock.unlock();
    int rc = ::syncfs(fd_);
    int err = errno;
    lock.lock();
    flushing_ = false;
    ++flushes_;
    done_cv_.notify_all();
    if (rc != 0)
      throw std::runtime_error(dir_ + ": syncfs failed: " + std::strerror(err) +
                               " (the results written since the last flush may be lost)");
    durable_ = std::max(durable_, upto);
  }
}

uint64_t GroupSync::flushes() const {
  std::lock_guard lock(mu_);
  return flushes_;
}

}  // namespace rf
