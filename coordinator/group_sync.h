// Group commit for files (DESIGN.md "The task ledger"): results written into the state directory
// without a flush each, then made durable together by one syncfs(2) of its filesystem. Whoever
// calls sync() while no flush runs starts one for every write made before it; whoever calls while
// one runs waits for it and, when its own writes came after that flush began, for the next. So
// the flushes per result fall as results arrive together: one covers all the uploads that wait
// for it.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>

namespace rf {

class GroupSync {
 public:
  // Opens `dir` (a directory on the filesystem to flush); throws std::runtime_error naming it.
  explicit GroupSync(const std::string& dir);
  ~GroupSync();
  GroupSync(const GroupSync&) = delete;
  GroupSync& operator=(const GroupSync&) = delete;

  // Returns once every write this thread made before the call is durable; throws
  // std::runtime_error when the flush fails (the writes may be lost: the caller undoes them).
  void sync();
  uint64_t flushes() const;  // syncfs calls made so far

 private:
  std::string dir_;
  int fd_ = -1;
  mutable std::mutex mu_;
  std::condition_variable done_cv_;
  uint64_t requested_ = 0;  // tickets handed out
  uint64_t durable_ = 0;    // every ticket up to this one is durable
  bool flushing_ = false;
  uint64_t flushes_ = 0;
};

}  // namespace rf
