// Group commit for files (DESIGN.md "The task ledger"): results written into the state directory
// without a flush each, then made durable together by one syncfs(2) of its filesystem. Whoever
// calls sync() while no flush runs starts one for every write made before it; whoever calls while
// one runs waits for it and, when its own writes came after that flush began, for the next. A
// writer announces itself before it writes (Writer), and a flush about to start waits for the
// writers announced, up to `gather_seconds`, so that it covers them too. So the flushes per
// result fall as results arrive together: one covers all the uploads in flight.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>

namespace rf {

class GroupSync {
 public:
  // Opens `dir` (a directory on the filesystem to flush); throws std::runtime_error naming it.
  explicit GroupSync(const std::string& dir, double gather_seconds = 0.002);
  ~GroupSync();
  GroupSync(const GroupSync&) = delete;
  GroupSync& operator=(const GroupSync&) = delete;

  // Held from before a write until its sync() returns (or the write failed).
  class Writer {
   public:
    explicit Writer(GroupSync& g);
    ~Writer();
    Writer(const Writer&) = delete;
    Writer& operator=(const Writer&) = delete;
    // Returns once every write this thread made before the call is durable; throws
    // std::runtime_error when the flush fails (the writes may be lost).
    void sync();

   private:
    GroupSync& g_;
    bool synced_ = false;
  };
  void sync();               // the same, for a writer that did not announce itself
  uint64_t flushes() const;  // syncfs calls made so far

 private:
  void wait_durable(std::unique_lock<std::mutex>& lock, uint64_t ticket);

  std::string dir_;
  int fd_ = -1;
  mutable std::mutex mu_;
  std::condition_variable done_cv_;
  double gather_seconds_;
  int writing_ = 0;         // writers announced that have not called sync() yet
  uint64_t requested_ = 0;  // tickets handed out
  uint64_t durable_ = 0;    // every ticket up to this one is durable
  bool flushing_ = false;
  uint64_t flushes_ = 0;
};

}  // namespace rf
