// One coordinator per state directory (DESIGN.md "Coordinator").
#pragma once

#include <string>

namespace rf {

// One coordinator per state directory: an exclusive lock (flock) on STATE_DIR/lock, held for
// the object's life, with the holder's pid written in the file. A second holder is refused
// with a StoreError naming the first one's pid.
class StateDirLock {
 public:
  explicit StateDirLock(const std::string& state_dir);  // creates the directory if needed
  ~StateDirLock();
  StateDirLock(const StateDirLock&) = delete;
  StateDirLock& operator=(const StateDirLock&) = delete;

 private:
  int fd_ = -1;
};

// Renames `from` to `to` (same directory) and flushes the directory, so that the rename
// survives a power cut before anything that relies on it is written. Throws StoreError.
void rename_durably(const std::string& from, const std::string& to);

}  // namespace rf
