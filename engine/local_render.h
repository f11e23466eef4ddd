// `rayfarm render`: the local single-node run (DESIGN.md "Local single-node runs"). The same
// splitter (tiles x passes), the same progressive merger and the same variance report as the
// farm, with TBB threads instead of workers.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>

#include "engine/frame.h"
#include "engine/frame_accumulator.h"
#include "engine/render.h"
#include "engine/sample_buffer.h"

namespace rf {

struct LocalProgress {
  uint64_t tasks_done = 0, tasks_total = 0;
  uint32_t passes_merged = 0, passes_total = 0;
  double rel_mse = 0;
  double seconds = 0;
  // The last report, after the frame's last merge (all passes, or a stop on the noise target or
  // the time budget). Before it, tasks_done may already equal tasks_total while the last pass's
  // merge is still under way.
  bool finished = false;
};

struct LocalRenderOptions {
  FrameNumber frame = 0;  // selects the seed stream (DESIGN.md determinism contract)
  uint32_t first_pass = 0;
  uint32_t pass_count = 0;   // 0: all passes of the scene from first_pass on
  double noise_target = 0;   // relMSE; 0 = none
  // Wall-clock budget in seconds (0 = none): at it, the tasks in flight are stopped (within a
  // pass: within 200 ms and one sample) and the image is the prefix of passes completed before.
  // Unlike the other stops this depends on the machine's speed, so the prefix is not a
  // reproducible one; meant for equal-time comparisons. No pass completed: passes_merged is 0.
  double time_budget_s = 0;
  int tile_size = 32;
  // Bytes of frame and waiting results held in memory (0: no bound); a larger frame is kept in
  // tiles in unlinked files in spill_dir (ProgressiveOptions::memory_budget).
  uint64_t memory_budget = 0;
  std::string spill_dir = "/tmp";
  // Called from a monitor thread about every 200 ms and once at the end.
  std::function<void(const LocalProgress&)> progress;
};

struct LocalRenderResult {
  SampleBuffer frame;  // the merged completed prefix (kept in tiles: its header and counters)
  std::unique_ptr<FrameAccumulator> tiles;  // the prefix, when kept in tiles on disk
  uint32_t passes_merged = 0;
  bool stopped_on_target = false;
  bool stopped_on_time = false;
  double seconds = 0;        // wall clock
  uint64_t rays = 0;         // traced for the merged passes
};

LocalRenderResult render_local(const Renderer& renderer, const LocalRenderOptions& options);

}  // namespace rf
