// Per-strategy images of bidirectional path tracing (Veach 1997, figures 10.3-10.4): what each
// (s, t) strategy contributes to one pass, with and without its MIS weight. Built on the BDPT
// integrator's strategy recorder (engine/integrators/bdpt.h).
#pragma once

#include <cstdint>
#include <vector>

#include "engine/frame.h"
#include "engine/scene.h"

namespace rf {

struct StrategyImage {
  int s = 0, t = 0;                // light and camera subpath vertices; path depth s + t - 2
  std::vector<double> weighted;    // width*height*3, RGB row-major: MIS-weighted contribution
  std::vector<double> unweighted;  // the same strategy alone (weight 1): an unbiased estimate
                                   // of the depth-(s+t-2) image where the strategy can sample
};

struct StrategyImages {
  int width = 0, height = 0;
  int max_shown_depth = 0;
  // Every strategy with s + t - 2 <= max_shown_depth except (s, t) = (1, 1), which BDPT does not
  // use (the light itself seen by the camera is (0, 2)); depth-major, s ascending.
  std::vector<StrategyImage> images;
  std::vector<double> rest;  // weighted sum of the strategies deeper than max_shown_depth
  const StrategyImage* find(int s, int t) const {
    for (const StrategyImage& i : images)
      if (i.s == s && i.t == t) return &i;
    return nullptr;
  }
};

// Renders pass `pass` of frame `frame` of the scene's BDPT (whatever its integrator type, with its
// max_depth, rr_min_depth, seed, spp_per_pass, sampler and filter) on one thread and splits every
// camera sample's estimate by strategy. Normalised as SampleBuffer::estimate(): strategies with
// t >= 2 are averaged over the pixel's camera samples, t = 1 splats are divided by the number of
// light paths (camera samples of the frame), so the weighted images plus `rest` sum to the BDPT
// image of that pass (up to float summation order, see tests/bdpt_test.cpp). Samples whose
// estimate is not finite are dropped from every image, as SampleBuffer drops them.
StrategyImages render_bdpt_strategies(const Scene& scene, uint32_t pass, int max_shown_depth,
                                      FrameNumber frame = 0);

}  // namespace rf
