// Path tracing with next-event estimation (`path`).
//
// Estimator: unidirectional paths from the camera. At every vertex with a non-delta BSDF, one
// light sample (light chosen by power) and one BSDF sample, combined by multiple importance
// sampling with the power heuristic (Veach 1997, ch. 9); emission found by the BSDF sample (area
// lights, the environment) is weighted against the light-sampling pdf of the same point. Delta
// lights (point, spot, directional) are reached by light sampling only, delta BSDFs (mirror,
// glass) by BSDF sampling only, each with weight 1.
// Parameters: max_depth D (scattering events, pbrt-v4's meaning: D = 0 sees emitters only, D = 1
// is direct lighting), rr_min_depth (Russian roulette after that many bounces, survival
// probability min(1, max component of throughput x eta scale), pbrt-v4's rule).
// Strengths: unbiased, simple, robust for diffuse and glossy scenes with visible light sources.
// Cannot do well: caustics from small lights seen through specular surfaces (found only by
// chance; from point lights never), light arriving through narrow openings; see bdpt and ppm.
#include "engine/integrator.h"

namespace rf {

RGB path_radiance(const RenderContext& ctx, Ray ray, Sampler& sampler, TraceCounters& counters) {
  const IntegratorSettings& settings = ctx.scene.render.integrator;
  RGB radiance(0.0f), beta(1.0f);
  float eta_scale = 1;
  float prev_bsdf_pdf = 0;
  bool prev_delta = true;  // the camera ray counts as "specular": emission is taken unweighted
  Vec3 prev_p = ray.o;
  float cone_width = 0;  // ray-cone width at the current hit, for texture filtering
  for (int depth = 0;; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) {
      if (ctx.lights.has_environment()) {
        RGB le = ctx.lights.environment_radiance(ray.d);
        float w = prev_delta ? 1.0f : power_heuristic(prev_bsdf_pdf, ctx.lights.pdf_environment(ray.d));
        radiance += beta * le * w;
      }
      break;
    }
    const Mesh& mesh = ctx.scene.meshes[hit.mesh];
    Vec3 wo = -ray.d;
    cone_width += ctx.pixel_spread * hit.t;

    RGB le = LightSet::emitted(mesh, hit.ng, wo);
    if (!is_black(le)) {
      if (prev_delta) {
        radiance += beta * le;
      } else {
        float light_pdf = ctx.lights.pdf_solid_angle(prev_p, hit.mesh, hit.prim, hit.p, hit.ng);
        radiance += beta * le * power_heuristic(prev_bsdf_pdf, light_pdf);
      }
    }
    if (depth == settings.max_depth) break;

    Bsdf bsdf = bsdf_at(ctx, hit, cone_width);

    // Next-event estimation (the dimensions are drawn either way, so a material change does
    // not reshuffle the random numbers of later bounces).
    float u_light = sampler.get_1d();
    Vec2 u_point = sampler.get_2d();
    if (!bsdf.is_delta())
      radiance += beta * light_sample_mis(ctx, hit, bsdf, wo, u_light, u_point, counters);

    // BSDF sampling for the next vertex.
    BsdfSample bs;
    float uc = sampler.get_1d();
    Vec2 u = sampler.get_2d();
    if (!bsdf.sample(wo, uc, u, TransportMode::Radiance, bs)) break;
    float cos_i = std::fabs(dot(bs.wi, bsdf.shading_normal()));
    beta *= bs.f * (cos_i / bs.pdf_solid_angle);
    if (bs.is_transmission) eta_scale *= sqr(bs.eta);
    prev_bsdf_pdf = bs.pdf_solid_angle;
    prev_delta = bs.is_delta;
    prev_p = hit.p;
    ray = ctx.accel.spawn(hit, bs.wi);

    float u_rr = sampler.get_1d();
    if (depth + 1 >= settings.rr_min_depth) {
      float survive = std::min(1.0f, max_component(beta * eta_scale));
      if (u_rr >= survive) break;
      beta = beta / survive;
    }
  }
  return radiance;
}

}  // namespace rf
