// The path estimator (path.h): a pixel's camera samples traced alone or together in packets.
#pragma once

#include "engine/integrators/camera_path.h"
#include "engine/integrators/common.h"
#include "engine/integrators/path/lane_lights.h"
#include "engine/sampler.h"

namespace rf {

class PathTracer {
 public:
  // Builds the lane light tables (once per task: they are the scene's).
  explicit PathTracer(const RenderContext& ctx) : ctx_(ctx), lane_lights_(ctx.lights) {}
  // The radiances of n <= Accel::kPacket camera samples of one pixel (rays started with their
  // samplers): traced together with Embree's packet queries when `packets` and n > 1
  // (packets.h), else one by one with single-ray queries (trace_alone); the same bits either way.
  void radiance(const Ray* rays, Sampler* samplers, int n, RGB* radiance, TraceCounters& counters,
                bool packets = true) const;

 private:
  const RenderContext& ctx_;
  LaneLights lane_lights_;
};

// The one-lane estimator: the path in state `path`, with radiance `radiance` gathered so far,
// cast ray `ray` at depth `depth` (0: the camera ray), traced to its end with Embree's
// single-ray queries and the one-vertex code; returns its radiance. A packet hands a lane over to
// it when the lane is the last one alive, so a lane's numbers and terms are those it gets traced
// alone from its camera ray.
RGB trace_alone(const RenderContext& ctx, CameraPath path, RGB radiance, Ray ray, int depth,
                Sampler& sampler, TraceCounters& counters);

}  // namespace rf
