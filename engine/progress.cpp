#include "engine/progress.h"

#include "engine/frame_accumulator.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace rf {

double samples_per_pixel(const SampleBuffer& b) {
  double pixels = double(b.rect.area());
  if (!(pixels > 0)) return 0;
  uint64_t samples = b.total_samples();
  return double(samples ? samples : b.light_paths) / pixels;
}

double samples_per_pixel(const FrameBands& frame) {
  const SampleBuffer& info = frame.info();
  double pixels = double(info.rect.area());
  if (!(pixels > 0)) return 0;
  uint64_t samples = frame.total_samples();
  return double(samples ? samples : info.light_paths) / pixels;
}

double eta_seconds(uint32_t passes_merged, uint32_t passes_total, double rel_mse,
                   double noise_target, double seconds_so_far) {
  if (passes_merged >= passes_total) return 0;
  if (passes_merged == 0 || seconds_so_far < 0) return -1;
  double needed = passes_total;
  if (noise_target > 0 && passes_merged >= 2 && rel_mse > 0)
    needed = std::min(needed, std::ceil(passes_merged * rel_mse / noise_target));
  double per_pass = seconds_so_far / passes_merged;
  return std::max(0.0, needed - passes_merged) * per_pass;
}

FrameProgress frame_progress(const SampleBuffer& merged, uint32_t passes_total, bool done,
                             bool stopped_on_target, double noise_target,
                             double seconds_so_far) {
  FrameProgress p;
  p.passes_merged = merged.header.passes.count();
  p.passes_total = passes_total;
  p.spp = samples_per_pixel(merged);
  p.rel_mse = merged.rel_mse();
  p.done = done;
  p.stopped_on_target = stopped_on_target;
  p.eta_seconds = done ? 0
                       : eta_seconds(p.passes_merged, passes_total, p.rel_mse, noise_target,
                                     seconds_so_far);
  return p;
}

FrameProgress frame_progress(const FrameAccumulator& acc, uint32_t passes_total,
                             double noise_target, double seconds_so_far) {
  FrameProgress p;
  p.passes_merged = acc.passes_merged();
  p.passes_total = passes_total;
  p.spp = acc.samples_per_pixel();
  p.rel_mse = acc.rel_mse();
  p.done = acc.done();
  p.stopped_on_target = acc.stopped_on_target();
  p.eta_seconds =
      p.done ? 0
             : eta_seconds(p.passes_merged, passes_total, p.rel_mse, noise_target, seconds_so_far);
  return p;
}

std::string duration_text(double s) {
  if (s < 0) return "?";
  char buf[32];
  if (s < 120)
    std::snprintf(buf, sizeof buf, "%.0f s", s);
  else if (s < 7200)
    std::snprintf(buf, sizeof buf, "%.0f min", s / 60);
  else
    std::snprintf(buf, sizeof buf, "%.1f h", s / 3600);
  return buf;
}

}  // namespace rf
