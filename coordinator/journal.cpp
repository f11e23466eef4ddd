#include "coordinator/journal.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>

namespace rf {

namespace {

constexpr size_t kMaxBatchWrites = 4096;             // one transaction's writes at most
constexpr double kRetryFirst = 0.25, kRetryCap = 5;  // seconds between tries of a refused batch

}  // namespace

Journal::Journal(JobStore& store, std::function<void(const std::string&)> on_problem)
    : store_(store), on_problem_(std::move(on_problem)), writer_([this] { run(); }) {}

Journal::~Journal() {
  {
    std::lock_guard lock(mu_);
    stopping_ = true;
  }
  changed_.notify_all();
  writer_.join();
}

Journal::Ticket Journal::append(std::vector<StoreWrite> writes) {
  std::lock_guard lock(mu_);
  if (writes.empty()) return next_ - 1;
  queue_.push_back({next_, std::move(writes), nullptr});
  changed_.notify_all();
  return next_++;
}

void Journal::write_ahead(std::vector<StoreWrite> writes, double timeout_seconds) {
  std::unique_lock lock(mu_);
  auto ahead = std::make_shared<Ahead>();
  Ticket ticket = next_++;
  queue_.push_back({ticket, std::move(writes), ahead});
  changed_.notify_all();
  if (!changed_.wait_for(lock, std::chrono::duration<double>(timeout_seconds),
                         [&] { return stored_ >= ticket || ahead->started; })) {
    ahead->cancelled = true;  // never written: the writer thread drops it
    throw StoreError("the job store did not take the write within " +
                     std::to_string(int(timeout_seconds)) + " s (" + problem_ + ")");
  }
  changed_.wait(lock, [&] { return stored_ >= ticket; });  // started: stored or refused soon
  if (!ahead->refused.empty()) throw StoreError(ahead->refused);
}

bool Journal::wait(Ticket ticket, double timeout_seconds) const {
  std::unique_lock lock(mu_);
  return changed_.wait_for(lock, std::chrono::duration<double>(timeout_seconds),
                           [&] { return stored_ >= ticket; });
}

std::string Journal::problem() const {
  std::lock_guard lock(mu_);
  return problem_;
}

uint64_t Journal::batches() const {
  std::lock_guard lock(mu_);
  return batches_;
}

Journal::Hold::Hold(Journal& j) : j_(j) {
  std::lock_guard lock(j_.mu_);
  ++j_.holds_;
}

Journal::Hold::~Hold() {
  std::lock_guard lock(j_.mu_);
  --j_.holds_;
  j_.changed_.notify_all();
}

void Journal::run() {
  double retry = kRetryFirst;
  std::unique_lock lock(mu_);
  for (;;) {
    changed_.wait(lock, [&] { return !queue_.empty() || stopping_; });
    if (holds_ > 0)  // a batch being appended: take it whole
      changed_.wait_for(lock, std::chrono::duration<double>(kHoldSeconds),
                        [&] { return holds_ == 0 || stopping_; });
    if (queue_.empty()) return;
    if (queue_.front().ahead && queue_.front().ahead->cancelled) {  // its writer gave up on it
      stored_ = queue_.front().ticket;
      queue_.pop_front();
      changed_.notify_all();
      continue;
    }
    // A write ahead goes alone (refused, it is dropped by itself); appended ones together.
    size_t take = 1;
    std::vector<StoreWrite> batch = queue_.front().writes;
    if (queue_.front().ahead)
      queue_.front().ahead->started = true;
    else
      while (take < queue_.size() && !queue_[take].ahead &&
             batch.size() + queue_[take].writes.size() <= kMaxBatchWrites) {
        batch.insert(batch.end(), queue_[take].writes.begin(), queue_[take].writes.end());
        ++take;
      }
    changed_.notify_all();
    lock.unlock();
    std::string error;
    try {
      store_.write(batch);
    } catch (const std::exception& e) {
      error = e.what();
      if (error.empty()) error = "the job store refused the write";
    }
    lock.lock();
    std::string heard;  // the problem to report, once the lock is let go
    bool report = false;
    if (error.empty() && !problem_.empty()) {
      // Told before the waiters are let go: whoever sees the write stored sees the store healed.
      problem_.clear();
      if (on_problem_) {
        lock.unlock();
        on_problem_("");
        lock.lock();
      }
    }
    if (error.empty()) {
      stored_ = queue_[take - 1].ticket;
      queue_.erase(queue_.begin(), queue_.begin() + ptrdiff_t(take));
      ++batches_;
      retry = kRetryFirst;
    } else if (queue_.front().ahead) {
      queue_.front().ahead->refused = error;
      stored_ = queue_.front().ticket;  // settled: its writer is told, and goes on without it
      queue_.pop_front();
    } else {
      report = problem_ != error;
      problem_ = heard = error;
      if (stopping_) {
        spdlog::error(
            "the job store refused {} queued writes at shutdown ({}); the frame "
            "checkpoints still hold every merged result",
            queue_.size(), error);
        stored_ = next_ - 1;
        queue_.clear();
      }
    }
    changed_.notify_all();
    if (report && on_problem_) {
      lock.unlock();
      on_problem_(heard);
      lock.lock();
    }
    if (!error.empty() && !stopping_ && !queue_.empty() && !queue_.front().ahead) {
      changed_.wait_for(lock, std::chrono::duration<double>(retry), [&] { return stopping_; });
      retry = std::min(kRetryCap, retry * 2);
    }
  }
}

}  // namespace rf
