// The progressive merger of one frame (DESIGN.md "Sample buffers and variance"), shared by the
// local renderer and the coordinator. Tasks (rect, pass) arrive in any order and are held as
// they came (a rendered buffer, or a received one still encoded); once every tile of the next
// pass is there, its tiles are added into the frame where they lie, so passes are merged strictly
// in pass order and each pixel's sums are the same as a whole-frame render's.
// The stop decision (noise target, pass budget) is taken on the completed prefix 0..k-1 only,
// so the final image is exactly that prefix, whatever order workers finished in.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <variant>

#include "engine/buffer_file.h"
#include "engine/buffer_merge.h"

namespace rf {

struct ProgressiveOptions {
  uint32_t first_pass = 0;   // passes [first_pass, first_pass + pass_count)
  uint32_t pass_count = 1;
  double noise_target = 0;   // stop once relMSE <= target (0: never)
  uint32_t min_passes = 4;   // batch-means variance from fewer passes is too noisy to stop on
  // Bytes of merged frame and of results waiting for their pass that the accumulator may hold in
  // memory (0: no bound; the frame is held whole). A frame without a splat plane, in more than
  // one tile, whose planes need more is kept in tiles in an unlinked file in spill_dir, the most
  // recently used tiles cached in half of it; results beyond the other half wait in files there.
  uint64_t memory_budget = 0;
  std::string spill_dir = "/tmp";
};

class TileSpill;  // frame_accumulator.cpp

class FrameAccumulator final : public FrameBands {
 public:
  // `base` is the header every task buffer carries (its passes field is ignored); `tiles` is how
  // a pass is split (the grid of the frame's size).
  FrameAccumulator(const BufferHeader& base, TileGrid tiles, bool splats,
                   const ProgressiveOptions& options);
  ~FrameAccumulator() override;
  FrameAccumulator(FrameAccumulator&&) noexcept;
  FrameAccumulator& operator=(FrameAccumulator&&) noexcept;

  // Whether the frame is kept in tiles on disk (options.memory_budget) rather than whole.
  bool tiled() const { return spill_ != nullptr; }
  // Bytes of planes per pixel (104, plus 8 per AOV channel).
  static uint64_t bytes_per_pixel(const AovSet& aovs) {
    return 8 * (13 + uint64_t(aovs.channels()));
  }

  enum class AddResult { Merged, Pending, Duplicate, Dropped };
  // Adds a task's one-pass buffer. Duplicate: that (rect, pass) was already added. Dropped: its
  // pass lies beyond the stop point or outside the range. Throws MergeError on a mismatch.
  AddResult add(SampleBuffer task);
  AddResult add(EncodedBuffer task);  // merged from its bytes, without a copy

  // Restores a checkpointed prefix (what frame() returned earlier, for passes [first_pass,
  // first_pass + k)) into a fresh accumulator; the stop decision is taken again on it. Throws
  // MergeError if it does not belong to this frame or is not such a prefix.
  void resume_from(SampleBuffer prefix);
  // The same from a prefix read a band at a time (a checkpoint file, BufferFileBands): a tiled
  // accumulator never holds it whole.
  void resume_from(const FrameBands& prefix);

  bool done() const { return done_; }
  bool stopped_on_target() const { return stopped_on_target_; }
  uint32_t passes_merged() const { return merged_; }   // length of the merged prefix
  // The merged prefix (empty header passes until the first pass is merged), held whole; a tiled
  // accumulator throws std::logic_error (read it with band()).
  const SampleBuffer& frame() const;
  // relMSE of the merged prefix after each pass merged, for ETA estimates. The sum runs tile by
  // tile (each tile row-major), as the tiles are merged, so it may differ from frame().rel_mse()
  // in the last bits; the stop decision uses this one, here and after a resume.
  const std::vector<double>& rel_mse_history() const { return rel_mse_history_; }
  double rel_mse() const override { return rel_mse_history_.empty() ? 0 : rel_mse_history_.back(); }
  double samples_per_pixel() const { return spp_; }  // of the merged prefix
  // Passes not yet merged that still need this tile (for schedulers).
  bool task_needed(const Rect& rect, uint32_t pass) const;
  size_t tile_index(const Rect& rect) const;  // throws MergeError if rect is not a tile

  // The merged prefix a band at a time (FrameBands): held whole, one band; kept in tiles, a row
  // of tiles per band, read from the spill file. info()'s planes are empty when tiled.
  const SampleBuffer& info() const override { return frame_; }
  int band_height() const override;
  const SampleBuffer& band(int y0) const override;
  uint64_t total_samples() const override { return samples_; }
  // What a tiled accumulator held (zeros when whole; for tests and benchmarks): peak bytes of
  // tiles cached (at most half the budget plus the tile being read) and of results waiting in
  // memory (at most half the budget), and how many results waited in spill files.
  struct SpillUse {
    uint64_t peak_tile_bytes = 0, peak_waiting_bytes = 0, parked_results = 0;
  };
  SpillUse spill_use() const;

 private:
  struct Parked {  // a waiting result in a spill file: where its .rfb bytes are
    uint64_t offset = 0, length = 0;
  };
  using Task = std::variant<SampleBuffer, EncodedBuffer, Parked>;
  AddResult add_task(Task task);
  void merge_ready_passes();
  double prefix_rel_mse() const;  // tile by tile
  void decide_after(uint32_t merged);
  void merge_pass_tiled(std::map<size_t, Task>& tiles, uint32_t pass, double* rel);
  void check_prefix(const SampleBuffer& info) const;  // resume_from's checks
  void resumed();                                     // after the prefix is in

  BufferHeader base_;
  TileGrid tiles_;
  bool splats_;
  ProgressiveOptions options_;
  SampleBuffer frame_;
  struct PendingPass {
    std::map<size_t, Task> tiles;  // by tile index: the ones arrived (a grid may have millions)
  };
  std::map<uint32_t, PendingPass> pending_;
  uint32_t merged_ = 0;
  bool done_ = false;
  bool stopped_on_target_ = false;
  std::vector<double> rel_mse_history_;
  uint64_t samples_ = 0;  // camera samples in the merged prefix
  double spp_ = 0;
  std::unique_ptr<TileSpill> spill_;  // tiled: the frame's tiles and the parked results
  uint64_t waiting_bytes_ = 0;        // tiled: bytes of results waiting in memory
  uint64_t peak_waiting_ = 0, parked_ = 0;
  mutable SampleBuffer band_;  // tiled: the last band read
};

}  // namespace rf
