// The `ao` integrator: see ao.h.
#include "engine/integrators/ao.h"

#include <cstdio>

#include "engine/integrators/drivers.h"
#include "engine/json_reader.h"

namespace rf {

RGB AoIntegrator::radiance(const RenderContext& ctx, Ray ray, Sampler& sampler,
                          TraceCounters& counters) const {
  const AoIntegrator& s = *this;
  SurfaceHit hit;
  ++counters.rays;
  if (!ctx.accel.intersect(ray, hit)) return RGB(0.0f);
  // The hemisphere on the camera's side of the surface (the geometric side decides; the
  // shading normal orients the cosine, flipped to agree with it).
  Vec3 ng = dot(hit.ng, ray.d) < 0 ? hit.ng : -hit.ng;
  Vec3 ns = dot(hit.ns, ng) < 0 ? -hit.ns : hit.ns;
  Frame frame = Frame::from_normal(ns);
  double sum = 0;
  for (int k = 0; k < s.samples; ++k) {
    Vec2 u = sampler.get_2d();
    Vec3 local;
    float weight;
    if (s.cosine) {
      local = sample_cosine_hemisphere(u);
      weight = 1.0f;
    } else {
      float z = u.x, r = safe_sqrt(1.0f - z * z), phi = 2 * kPi * u.y;
      local = {r * std::cos(phi), r * std::sin(phi), z};
      weight = 2.0f * z;  // (cos / pi) / (1 / 2 pi)
    }
    Vec3 w = frame.to_world(local);
    if (dot(w, ng) <= 0) continue;  // below the geometric surface: occluded by the surface itself
    Ray r = ctx.accel.spawn(hit, w);
    r.tmax = s.max_distance;
    ++counters.rays;
    if (!ctx.accel.occluded(r)) sum += weight;
  }
  return RGB(float(sum / s.samples));
}

SampleBuffer AoIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                  bool parallel) const {
  return render_camera_paths<false>(ctx, task, parallel,
                                    [&](Ray ray, Sampler& sampler, TraceCounters& counters) {
                                      return radiance(ctx, ray, sampler, counters);
                                    });
}

}  // namespace rf
