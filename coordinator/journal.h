// The job store's writes, in order and off the lock that leases take (DESIGN.md "The task
// ledger"). The ledger appends a transition's writes under the coordinator's lock without waiting
// for the disk; one writer thread stores what is queued in batches, each one transaction and one
// flush for every write queued meanwhile (group commit); a call acknowledges its transition only
// once wait(ticket) says its writes are stored, after it has let go of the lock.
//
// Two kinds of writes:
// - appended: the transition is already applied in memory. The journal retries a batch the store
//   refuses (a full disk) until it is stored; problem() says why meanwhile, and a wait() that runs
//   out of time lets the caller answer UNAVAILABLE. Nothing acknowledged depends on them before
//   they are stored.
// - written ahead (write_ahead): nothing in memory refers to them yet (a submitted job, a worker's
//   registration, a tenant's blob): the caller waits for them and applies its change after; when
//   the store refuses them they are dropped and the caller refuses its request.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "coordinator/job_store.h"

namespace rf {

class Journal {
 public:
  using Ticket = uint64_t;

  // `on_problem` hears every change of problem() ("" when writes work again), from the writer
  // thread.
  explicit Journal(JobStore& store, std::function<void(const std::string&)> on_problem = {});
  ~Journal();  // stores what is queued (giving up on a store that keeps refusing), then stops
  Journal(const Journal&) = delete;
  Journal& operator=(const Journal&) = delete;

  // Queues writes after every earlier one; never waits for the disk. An empty list gets the
  // ticket of the last write queued.
  Ticket append(std::vector<StoreWrite> writes);
  // Stores these after everything queued before, and returns once they are; throws StoreError
  // (and drops them) when the store refuses them, or when they have not been started within
  // timeout_seconds (a refused batch ahead of them is being retried: problem() says why).
  void write_ahead(std::vector<StoreWrite> writes, double timeout_seconds = 10);
  // Waits until every write up to `ticket` is stored: false if it is not within timeout_seconds.
  bool wait(Ticket ticket, double timeout_seconds) const;
  // Why the store refuses the journal's writes now; "" when it takes them.
  std::string problem() const;
  // Batches stored so far (each one transaction), for tests of the grouping.
  uint64_t batches() const;

  // Held while one call appends many transitions (a batch of leases or results): the writer
  // thread waits for it to end, up to kHoldSeconds, so that they go in one transaction instead
  // of the first in one and the rest in the next.
  class Hold {
   public:
    explicit Hold(Journal& j);
    ~Hold();
    Hold(const Hold&) = delete;
    Hold& operator=(const Hold&) = delete;

   private:
    Journal& j_;
  };
  static constexpr double kHoldSeconds = 0.005;

 private:
  // A write ahead's fate, shared by its writer and the journal's thread.
  struct Ahead {
    bool started = false;    // taken by the writer thread: it will be stored or refused
    bool cancelled = false;  // given up on before it was started: dropped unwritten
    std::string refused;     // why the store refused it
  };
  struct Entry {
    Ticket ticket = 0;
    std::vector<StoreWrite> writes;
    std::shared_ptr<Ahead> ahead;  // write_ahead's; empty for appended writes
  };
  void run();

  JobStore& store_;
  std::function<void(const std::string&)> on_problem_;
  mutable std::mutex mu_;
  mutable std::condition_variable changed_;
  std::deque<Entry> queue_;
  Ticket next_ = 1, stored_ = 0;
  std::string problem_;
  uint64_t batches_ = 0;
  int holds_ = 0;
  bool stopping_ = false;
  std::thread writer_;
};

}  // namespace rf
