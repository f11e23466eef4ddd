// Tests of engine/progress: the spp, relMSE and ETA every front end reports.
#include "engine/progress.h"

#include <gtest/gtest.h>

namespace rf {
namespace {

BufferHeader header(uint32_t passes) {
  BufferHeader h;
  h.scene_digest = std::string(64, 'a');
  h.integrator = "light";
  h.width = 4;
  h.height = 2;
  h.passes = PassSet::range(0, passes);
  return h;
}

TEST(Progress, SppCountsCameraSamplesPerPixel) {
  SampleBuffer b(header(1), Rect{0, 0, 4, 2}, false);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x)
      for (int s = 0; s < 3; ++s) b.add_sample(x, y, RGB(1.0f));
  EXPECT_DOUBLE_EQ(samples_per_pixel(b), 3.0);
}

// A light-tracing buffer has no camera samples: its spp is its light paths per pixel (what
// `merge` printed as 0 before).
TEST(Progress, SppOfASplatOnlyBufferIsLightPathsPerPixel) {
  SampleBuffer b(header(1), Rect{0, 0, 4, 2}, true);
  b.light_paths = 8 * 16;
  EXPECT_DOUBLE_EQ(samples_per_pixel(b), 16.0);
  EXPECT_DOUBLE_EQ(samples_per_pixel(SampleBuffer{}), 0.0);  // no pixels: no spp, no division
}

// relMSE falls as 1/passes: at relMSE 0.04 after 4 passes a target of 0.01 needs 16 passes in
// all, 12 more at 10 s each.
TEST(Progress, EtaFollowsTheOneOverPassesModel) {
  EXPECT_DOUBLE_EQ(eta_seconds(4, 64, 0.04, 0.01, 40.0), 120.0);
  // Capped by the job's passes: without a target, the rest of them.
  EXPECT_DOUBLE_EQ(eta_seconds(4, 10, 0.04, 0.0, 40.0), 60.0);
  EXPECT_DOUBLE_EQ(eta_seconds(4, 10, 0.04, 0.001, 40.0), 60.0);
  // Target already met: nothing left.
  EXPECT_DOUBLE_EQ(eta_seconds(4, 64, 0.005, 0.01, 40.0), 0.0);
  // Unknown before the first pass, or without a clock; zero once all passes are in.
  EXPECT_DOUBLE_EQ(eta_seconds(0, 64, 0.0, 0.01, 40.0), -1.0);
  EXPECT_DOUBLE_EQ(eta_seconds(2, 64, 0.1, 0.01, -1.0), -1.0);
  EXPECT_DOUBLE_EQ(eta_seconds(64, 64, 0.1, 0.01, 40.0), 0.0);
}

TEST(Progress, FrameProgressOfAMergedPrefix) {
  SampleBuffer b(header(3), Rect{0, 0, 4, 2}, false);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 4; ++x) b.add_sample(x, y, RGB(1.0f));
  FrameProgress p = frame_progress(b, 8, false, false, 0.0, 30.0);
  EXPECT_EQ(p.passes_merged, 3u);
  EXPECT_EQ(p.passes_total, 8u);
  EXPECT_DOUBLE_EQ(p.spp, 1.0);
  EXPECT_DOUBLE_EQ(p.eta_seconds, 50.0);  // 5 passes left at 10 s
  p = frame_progress(b, 8, true, true, 0.0, 30.0);
  EXPECT_TRUE(p.done && p.stopped_on_target);
  EXPECT_DOUBLE_EQ(p.eta_seconds, 0.0);
}

TEST(Progress, DurationText) {
  EXPECT_EQ(duration_text(-1), "?");
  EXPECT_EQ(duration_text(45), "45 s");
  EXPECT_EQ(duration_text(720), "12 min");
  EXPECT_EQ(duration_text(3.5 * 3600), "3.5 h");
}

}  // namespace
}  // namespace rf
