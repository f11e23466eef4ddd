// Durable per-frame results (DESIGN.md "Coordinator": atomic accumulator checkpoints that record
// their tasks). A frame's directory holds
//   prefix.rfb        the merged prefix of passes 0..k-1 (the frame accumulator's image), and
//   task-P-T.rfb      each accepted task (pass P, tile T) not yet inside the prefix.
// Every file is a checksummed sample-buffer file written atomically (temporary file, fsync,
// rename, fsync the directory), so its name is the record of which tasks it holds. A task result
// is durable before CompleteTask answers OK; a prefix is durable before the task files it absorbed
// are removed. On restart, the prefix and the task files rebuild the accumulator exactly; a file
// that fails its checksum is set aside and its tasks are rendered again.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "engine/sample_buffer.h"

namespace rf {

class FrameCheckpoint {
 public:
  explicit FrameCheckpoint(std::string dir);  // creates it

  void save_task(uint32_t pass, uint32_t tile, const SampleBuffer& buffer) const;
  // A received result's bytes as they came (already decoded and checked: a .rfb file).
  void save_task(uint32_t pass, uint32_t tile, std::string_view encoded) const;
  // Writes the prefix (passes [0, k)), then removes task files of passes < k.
  void save_prefix(const SampleBuffer& frame) const;

  struct TaskResult {
    uint32_t pass, tile;
    SampleBuffer buffer;
  };
  struct Loaded {
    std::optional<SampleBuffer> prefix;
    std::vector<TaskResult> tasks;      // in (pass, tile) order
    std::vector<std::string> problems;  // files set aside, and why
  };
  Loaded load() const;

  const std::string& dir() const { return dir_; }

 private:
  std::string dir_;
};

}  // namespace rf
