// The `whitted` integrator: see whitted.h.
#include "engine/integrators/whitted.h"

#include "engine/integrators/drivers.h"

namespace rf {

namespace {

RGB whitted_radiance(const RenderContext& ctx, Ray ray, Sampler& sampler, TraceCounters& counters) {
  const int max_depth = ctx.scene.render.integrator.max_depth;
  RGB radiance(0.0f), beta(1.0f);
  float cone_width = 0;
  for (int depth = 0;; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) {
      radiance += beta * ctx.lights.environment_radiance(ray.d);
      break;
    }
    Vec3 wo = -ray.d;
    cone_width += ctx.pixel_spread * hit.t;
    radiance += beta * emitted_radiance(ctx.accel.mesh(hit.mesh), hit.ng, wo);
    if (depth == max_depth) break;
    Bsdf bsdf = bsdf_at(ctx, hit, cone_width);
    float u_light = sampler.get_1d();
    Vec2 u_point = sampler.get_2d();
    float uc = sampler.get_1d();
    Vec2 u_bsdf = sampler.get_2d();
    if (bsdf.is_delta()) {
      BsdfSample bs;
      if (!bsdf.sample(wo, uc, u_bsdf, TransportMode::Radiance, bs)) break;
      beta *= bs.f * (std::fabs(dot(bs.wi, bsdf.shading_normal())) / bs.pdf_solid_angle);
      ray = ctx.accel.spawn(hit, bs.wi);
      continue;
    }
    auto add = [&](const LightSample& ls) {
      RGB f = bsdf.eval(wo, ls.wi);
      if (is_black(f)) return;
      ++counters.rays;
      if (!light_visible(ctx, hit, ls)) return;
      radiance += beta * f * ls.radiance *
                  (std::fabs(dot(ls.wi, bsdf.shading_normal())) / ls.pdf_solid_angle);
    };
    for (size_t k = 0; k < ctx.lights.delta_light_count(); ++k) {
      LightSample ls;
      if (ctx.lights.sample_delta_light(k, hit.p, ls)) add(ls);
    }
    LightSample ls;
    if (ctx.lights.sample(hit.p, receiver_normal(bsdf, wo), u_light, u_point, ls,
                          ctx.at(hit.time)) &&
        !ls.is_delta)
      add(ls);
    break;
  }
  return radiance;
}

}  // namespace

SampleBuffer WhittedIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                       bool parallel) const {
  return render_camera_paths<false>(ctx, task, parallel,
                                    [&](Ray ray, Sampler& sampler, TraceCounters& counters) {
                                      return whitted_radiance(ctx, ray, sampler, counters);
                                    });
}

}  // namespace rf
