// The `path` integrator: see path.h. The module's render, the tracer's entry and the one-lane
// estimator.
#include "engine/integrators/path/path.h"

#include <algorithm>
#include <cmath>

#include "engine/integrators/drivers.h"
#include "engine/integrators/path/packets.h"
#include "engine/integrators/path/path_tracer.h"
#include "engine/integrators/sample_layout.h"

namespace rf {

// Every vertex consumes the same dimensions whether or not it reads them (skipped ones cost
// nothing; sample_layout.h), so a material change does not reshuffle the random numbers of later
// bounces.
RGB trace_alone(const RenderContext& ctx, CameraPath path, RGB radiance, Ray ray, int depth,
                Sampler& sampler, TraceCounters& counters) {
  const IntegratorSettings& settings = ctx.scene.render.integrator;
  for (;; ++depth) {
    ++counters.rays;
    SurfaceHit hit;
    if (!ctx.accel.intersect(ray, hit)) {
      path.escape(ctx, ray.d, radiance);
      break;
    }
    const Vec3 wo = -ray.d;
    path.arrive(ctx, hit, wo, radiance);
    if (depth == settings.max_depth) break;
    const bool roulette = depth + 1 >= settings.rr_min_depth;
    // A diffuse vertex at the last depth ends its path after its light sample, which takes the
    // full weight: its BSDF ray would be cast only for the emission it hits at depth max_depth,
    // weighted by MIS against that light sample, and a Lambertian lobe's share of that is small
    // (veach-mis: at most 2e-4 in a pixel at 256 spp) for a closest-hit query. The same expected
    // value (light sampling alone is unbiased: every light it can miss emits nothing towards the
    // vertex); other lobes keep both strategies (a glossy lobe's light samples alone are noisy).
    const bool last = depth + 1 == settings.max_depth;
    const Bsdf bsdf = bsdf_at(ctx, hit, path.cone_width);
    const bool nee = !bsdf.is_delta();
    const bool ends = last && bsdf.is_diffuse();
    const float u_light = sampler.get_1d_if(nee);
    const Vec2 u_point = vertex_2d(sampler, nee, depth, kPointPair);
    if (nee) {
      Ray r;
      RGB l;
      if (light_sample_mis_unshadowed(ctx, hit, bsdf, wo, u_light, u_point, l, r, !ends)) {
        ++counters.rays;
        if (!ctx.accel.occluded(r)) radiance += path.beta * l;
      }
    }
    if (ends) break;
    BsdfSample bs;
    const float uc = sampler.get_1d_if(bsdf.sample_uses_choice());
    const Vec2 u_dir = vertex_2d(sampler, bsdf.sample_uses_direction(), depth, kDirPair);
    if (!bsdf.sample(wo, uc, u_dir, TransportMode::Radiance, bs)) break;
    ray = path.scatter(ctx, hit, bsdf, wo, bs);
    const float u_rr = sampler.get_1d_if(roulette);
    if (roulette && !path.survives_roulette(u_rr)) break;
  }
  return radiance;
}

void PathTracer::radiance(const Ray* rays, Sampler* samplers, int n, RGB* radiance,
                          TraceCounters& counters, bool packets) const {
  if (packets && n > 1) {
    PacketPaths(ctx_, lane_lights_, samplers, n, counters).trace(rays, radiance);
    return;
  }
  for (int i = 0; i < n; ++i)
    radiance[i] =
        trace_alone(ctx_, CameraPath(rays[i].o), RGB(0.0f), rays[i], 0, samplers[i], counters);
}

SampleBuffer PathIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                    bool parallel) const {
  const PathTracer tracer(ctx);
  return render_camera_paths<false>(
      ctx, task, parallel,
      [&](const Ray* rays, Sampler* samplers, int n, RGB* radiance, TraceCounters& counters) {
        tracer.radiance(rays, samplers, n, radiance, counters);
      });
}

}  // namespace rf
