// Durable per-frame results (DESIGN.md "Coordinator": atomic accumulator checkpoints that record
// their tasks). A frame's directory holds
//   prefix.rfb        the merged prefix of passes 0..k-1 (the frame accumulator's image), and
//   tasks.log         each accepted task (pass P, tile T) not yet inside the prefix, appended as
//                     it came: records of a 32-byte head (magic "RFTL", pass, tile, 0, the length,
//                     an XXH3-64 of the head's first 24 bytes) and the task's .rfb bytes;
//   task-P-T.rfb      the same, one file per task, as builds before the log wrote them (read, and
//                     removed once inside the prefix).
// Every .rfb carries its checksum. The prefix is written atomically (temporary file, fsync,
// rename, fsync of the directory); a task's record is appended unflushed, and the coordinator
// makes it durable before CompleteTask answers OK (GroupSync: one flush for the results that
// arrive together); a prefix is durable before the records it absorbed are dropped. On restart,
// the prefix and the task records rebuild the accumulator exactly: a torn record at the log's end
// (a crash in the middle of an append) is cut off, and a record that fails its checksum is
// skipped (its task is rendered again), both reported. Appending to one file per frame costs no
// inode: creating and removing a file per task was a tenth of the coordinator's CPU per task
// (ext4's inode allocation), docs/performance.md.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "engine/buffer_file.h"
#include "engine/sample_buffer.h"

namespace rf {

class FrameCheckpoint {
 public:
  explicit FrameCheckpoint(std::string dir);  // creates it

  // Appends a task's result (encoded, or the bytes as received, already decoded and checked) to
  // the log, unflushed: the caller makes it durable (GroupSync) before it counts
  // on it. Throws std::runtime_error naming the file (and leaves no partial record behind).
  void save_task(uint32_t pass, uint32_t tile, const SampleBuffer& buffer) const;
  void save_task(uint32_t pass, uint32_t tile, std::string_view encoded) const;
  // Writes the prefix (passes [0, k)), then drops the results of passes < k: the log is emptied
  // when none of its records is of a later pass, rewritten with those only (flushed) when they
  // are less than half of it; task files of passes < k are removed.
  void save_prefix(const FrameBands& frame) const;  // written a band at a time
  void save_prefix(const SampleBuffer& frame) const { save_prefix(WholeFrame(frame)); }

  struct TaskResult {
    uint32_t pass, tile;
    SampleBuffer buffer;
  };
  struct Loaded {
    std::unique_ptr<BufferFileBands> prefix;  // prefix.rfb, checked, read a band at a time
    std::vector<TaskResult> tasks;      // in (pass, tile) order
    std::vector<std::string> problems;  // files set aside, and why
  };
  Loaded load(uint64_t band_bytes = uint64_t(64) << 20) const;
  // The same in two steps, so that a restart never holds a pass of results at once: the prefix
  // and the task files of builds before the log (tasks unsorted), then the log's records of
  // passes >= k not among `have`, each handed to `each` as it is read (its problems appended).
  Loaded load_prefix(uint64_t band_bytes = uint64_t(64) << 20) const;
  void load_log(uint32_t k, std::set<std::pair<uint32_t, uint32_t>> have,
                const std::function<void(TaskResult&&)>& each,
                std::vector<std::string>& problems) const;

  const std::string& dir() const { return dir_; }

 private:
  struct Record {
    uint32_t pass = 0, tile = 0;
    uint64_t offset = 0, length = 0;  // of the .rfb bytes in the log
  };
  // The log's records, read from its heads; `end` is where the last whole record ends (a torn
  // tail, or a bad head, begins there).
  std::vector<Record> scan_log(uint64_t* end, uint64_t* size) const;
  std::string log_path() const { return dir_ + "/tasks.log"; }

  std::string dir_;
  mutable bool log_checked_ = false;  // a torn tail of an earlier process was cut off
};

}  // namespace rf
