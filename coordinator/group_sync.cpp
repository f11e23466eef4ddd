#include "coordinator/group_sync.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>

namespace rf {

GroupSync::GroupSync(const std::string& dir, double gather_seconds)
    : dir_(dir), gather_seconds_(gather_seconds) {
  fd_ = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd_ < 0) throw std::runtime_error(dir + ": cannot open: " + std::strerror(errno));
}

GroupSync::~GroupSync() {
  if (fd_ >= 0) ::close(fd_);
}

void GroupSync::sync() {
  std::unique_lock lock(mu_);
  wait_durable(lock, ++requested_);  // the caller's writes precede this ticket
}

void GroupSync::wait_durable(std::unique_lock<std::mutex>& lock, uint64_t mine) {
  while (durable_ < mine) {
    if (flushing_) {  // a flush runs, perhaps begun before these writes: wait, then look again
      done_cv_.wait(lock);
      continue;
    }
    flushing_ = true;
    // Writers on their way: wait a moment for them to join this flush.
    if (writing_ > 0 && gather_seconds_ > 0)
      done_cv_.wait_for(lock, std::chrono::duration<double>(gather_seconds_),
                        [&] { return writing_ == 0; });
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

GroupSync::Writer::Writer(GroupSync& g) : g_(g) {
  std::lock_guard lock(g_.mu_);
  ++g_.writing_;
}

GroupSync::Writer::~Writer() {
  if (synced_) return;
  std::lock_guard lock(g_.mu_);
  --g_.writing_;
  g_.done_cv_.notify_all();
}

void GroupSync::Writer::sync() {
  std::unique_lock lock(g_.mu_);
  --g_.writing_;  // and its ticket taken at once: a gathering flush covers it
  synced_ = true;
  const uint64_t mine = ++g_.requested_;
  g_.done_cv_.notify_all();
  g_.wait_durable(lock, mine);
}

uint64_t GroupSync::flushes() const {
  std::lock_guard lock(mu_);
  return flushes_;
}

}  // namespace rf
