// The progress of one frame, as every front end reports it (DESIGN.md "Sample buffers and
// variance"): `render`'s summary, `merge`, the coordinator's job status, `watch` and `fetch` all
// take their spp, relMSE and ETA from here, so the figures mean the same everywhere.
#pragma once

#include <cstdint>
#include <string>

#include "engine/sample_buffer.h"

namespace rf {

class FrameAccumulator;

// Samples per pixel of a buffer: its camera samples per pixel of its rect, or, for light
// tracing (no camera samples), its light paths per pixel, the work a camera sample stands for.
double samples_per_pixel(const SampleBuffer& buffer);
double samples_per_pixel(const FrameBands& frame);  // the same, from its counts

struct FrameProgress {
  uint32_t passes_merged = 0;  // length of the merged prefix
  uint32_t passes_total = 0;   // the job's passes (the stop may come earlier)
  double spp = 0;
  double rel_mse = 0;          // of the merged prefix; 0 before two passes (DESIGN.md)
  bool done = false;
  bool stopped_on_target = false;
  double eta_seconds = -1;     // until the frame is done: -1 unknown, 0 done
};

// The ETA model. The batch-means relMSE falls as 1/passes, so a noise target needs about
// passes * relMSE / target passes in all (never more than passes_total); every pass still needed
// takes the time per pass seen so far. Unknown (-1) before the first pass is merged.
double eta_seconds(uint32_t passes_merged, uint32_t passes_total, double rel_mse,
                   double noise_target, double seconds_so_far);

// The progress of a merged prefix of passes (FrameAccumulator::frame(), or a merged .rfb).
// `seconds_so_far` is the time since the frame's first task started (< 0: unknown).
FrameProgress frame_progress(const SampleBuffer& merged, uint32_t passes_total, bool done,
                             bool stopped_on_target, double noise_target, double seconds_so_far);

// The same from an accumulator's figures, kept as passes merge: nothing reads the frame's planes
// (the coordinator takes this under its lock at every result).
FrameProgress frame_progress(const FrameAccumulator& acc, uint32_t passes_total,
                             double noise_target, double seconds_so_far);

// "45 s", "12 min", "3.5 h"; "?" for a negative (unknown) duration.
std::string duration_text(double seconds);

}  // namespace rf
