// Whitted ray tracing (`whitted`).
//
// Estimator: from the camera, follow only delta BSDFs (mirror reflection, glass refraction and
// reflection chosen by Fresnel); at the first surface that is not purely specular, add direct
// lighting: every point, spot and directional light exactly (one shadow ray each) and the area
// lights and environment by one light sample (chosen by power, delta picks discarded, so the
// estimate is unbiased for the non-delta lights). Emitters and the environment seen through the
// specular chain are added as they are.
// Parameters: max_depth bounds the specular chain (pbrt-v4's meaning, as every integrator).
// Strengths: fast, noise-free for delta lights, sharp reflections and refractions.
// Cannot do: it is NOT a global-illumination method. No light reaches a diffuse or glossy surface
// by way of another surface (no indirect light, no colour bleeding, no caustics), and glossy
// surfaces get only their direct lighting. Its image converges to the path tracer restricted to
// camera -> specular* -> one non-specular vertex -> light.
#include "engine/integrator.h"

namespace rf {

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
    radiance += beta * LightSet::emitted(ctx.scene.meshes[hit.mesh], hit.ng, wo);
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
    if (ctx.lights.sample(hit.p, u_light, u_point, ls) && !ls.is_delta) add(ls);
    break;
  }
  return radiance;
}

}  // namespace rf
