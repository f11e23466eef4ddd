// The `direct` integrator: see direct.h.
#include "engine/integrators/direct.h"

#include <cstdio>

#include "engine/integrators/drivers.h"
#include "engine/json_reader.h"

namespace rf {

namespace {
float mis_weight(float n_a, float pdf_a, float n_b, float pdf_b, bool power) {
  float a = n_a * pdf_a, b = n_b * pdf_b;
  if (power) a *= a, b *= b;
  if (std::isinf(a)) return 1.0f;
  return a + b > 0 ? a / (a + b) : 0.0f;
}

RGB direct_radiance(const DirectIntegrator& s, const RenderContext& ctx, Ray ray, Sampler& sampler,
                    TraceCounters& counters) {
  using Strategy = DirectIntegrator::Strategy;
  // Sample counts of each strategy (0 when unused), as the MIS weights need them.
  float n_light = s.strategy == Strategy::Bsdf ? 0.0f : float(s.light_samples);
  float n_bsdf = s.strategy == Strategy::Light ? 0.0f : float(s.bsdf_samples);
  SurfaceHit hit;
  ++counters.rays;
  if (!ctx.accel.intersect(ray, hit)) return ctx.lights.environment_radiance(ray.d);
  Vec3 wo = -ray.d;
  RGB radiance = emitted_radiance(ctx.accel.mesh(hit.mesh), hit.ng, wo);
  Bsdf bsdf = bsdf_at(ctx, hit, ctx.pixel_spread * hit.t);
  Vec3 ns = bsdf.shading_normal();
  const Vec3 n_receiver = receiver_normal(bsdf, wo);  // light selection (LightSet::sample)

  // Light sampling: area lights and the environment MIS-weighted, delta lights always.
  // With the "bsdf" strategy one light sample still serves the delta lights, if any.
  int light_rounds = bsdf.is_delta()  ? 0
                     : n_light > 0    ? s.light_samples
                     : ctx.lights.delta_light_count() > 0 ? 1
                                                          : 0;
  for (int k = 0; k < light_rounds; ++k) {
    float u = sampler.get_1d();
    // The first round of each strategy is stratified jointly with the filter offset, as the path
    // tracer's first vertex (Sampler::get_2d_joint).
    Vec2 up = k == 0 ? sampler.get_2d_joint(0) : sampler.get_2d();
    LightSample ls;
    if (!ctx.lights.sample(hit.p, n_receiver, u, up, ls, ctx.at(hit.time))) continue;
    if (n_light == 0 && !ls.is_delta) continue;  // "bsdf" strategy: only delta lights here
    RGB f = bsdf.eval(wo, ls.wi);
    if (is_black(f)) continue;
    ++counters.rays;
    if (!light_visible(ctx, hit, ls)) continue;
    float w = ls.is_delta ? 1.0f
                          : mis_weight(n_light, ls.pdf_solid_angle, n_bsdf, bsdf.pdf(wo, ls.wi),
                                       s.power_heuristic);
    // Delta lights are sampled in every round but estimated by the light strategy alone.
    float count = ls.is_delta ? float(light_rounds) : n_light;
    radiance += f * ls.radiance * (std::fabs(dot(ls.wi, ns)) * w / (ls.pdf_solid_angle * count));
  }

  // BSDF sampling: emitters and the environment along sampled directions.
  int bsdf_rounds = bsdf.is_delta() ? std::max(1, s.bsdf_samples) : int(n_bsdf);
  for (int k = 0; k < bsdf_rounds; ++k) {
    float uc = sampler.get_1d();
    Vec2 u = k == 0 ? sampler.get_2d_joint(1) : sampler.get_2d();
    BsdfSample bs;
    if (!bsdf.sample(wo, uc, u, TransportMode::Radiance, bs)) continue;
    RGB weight = bs.f * (std::fabs(dot(bs.wi, ns)) / (bs.pdf_solid_angle * float(bsdf_rounds)));
    Ray r = ctx.accel.spawn(hit, bs.wi);
    SurfaceHit light_hit;
    ++counters.rays;
    RGB le;
    float light_pdf;
    if (ctx.accel.intersect(r, light_hit)) {
      le = emitted_radiance(ctx.accel.mesh(light_hit.mesh), light_hit.ng, -bs.wi);
      if (is_black(le)) continue;
      light_pdf = ctx.lights.pdf_solid_angle(hit.p, n_receiver, light_hit.mesh, light_hit.prim,
                                             light_hit.p, light_hit.ng, ctx.at(hit.time));
    } else {
      le = ctx.lights.environment_radiance(bs.wi);
      if (is_black(le)) continue;
      light_pdf = ctx.lights.pdf_environment(bs.wi);
    }
    float w = bs.is_delta ? 1.0f
                          : mis_weight(n_bsdf, bs.pdf_solid_angle, n_light, light_pdf,
                                       s.power_heuristic);
    radiance += weight * le * w;
  }
  return radiance;
}

}  // namespace

SampleBuffer DirectIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                      bool parallel) const {
  return render_camera_paths<false>(ctx, task, parallel,
                                    [&](Ray ray, Sampler& sampler, TraceCounters& counters) {
                                      return direct_radiance(*this, ctx, ray, sampler, counters);
                                    });
}

}  // namespace rf
