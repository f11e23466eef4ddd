// Path tracing with next-event estimation (`path`).
//
// Estimator: unidirectional paths from the camera. At every non-delta vertex one light sample
// (light chosen by power, point uniform by area) and one BSDF sample, combined by multiple
// importance sampling with the power heuristic (Veach 1997, ch. 9); emission found by the BSDF
// sample is weighted against the light-sampling pdf of the same point.
// Parameters: max_depth D (scattering events, pbrt-v4's meaning: D = 0 sees emitters only, D = 1
// is direct lighting), rr_min_depth (Russian roulette after that many bounces, with survival
// probability min(1, max component of the throughput)).
// Strengths: unbiased, simple, robust for diffuse and glossy scenes with visible light sources.
// Cannot do well: caustics from small lights seen through specular surfaces (found only by
// chance), light arriving through narrow openings; see bdpt and ppm for those.
#include "engine/bsdf.h"
#include "engine/integrator.h"

namespace rf {

RGB path_radiance(const RenderContext& ctx, Ray ray, Sampler& sampler,
                  TraceCounters& counters) {
  const IntegratorSettings& settings = ctx.scene.render.integrator;
  RGB radiance(0.0f), beta(1.0f);
  float prev_bsdf_pdf = 0;
  bool prev_delta = true;  // the camera ray counts as "specular": emission is taken unweighted
  Vec3 prev_p = ray.o;
  for (int depth = 0;; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) break;
    const Mesh& mesh = ctx.scene.meshes[hit.mesh];
    Vec3 wo = -ray.d;

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

    Bsdf bsdf = Bsdf::at(ctx.scene.materials[mesh.material], hit.ns, hit.ng, wo);

    // Next-event estimation.
    float u_light = sampler.get_1d();
    Vec2 u_point = sampler.get_2d();
    LightSample ls;
    if (ctx.lights.sample(hit.p, u_light, u_point, ls)) {
      RGB f = bsdf.eval(wo, ls.wi);
      if (!is_black(f)) {
        ++counters.rays;
        if (ctx.accel.visible(hit, ls.p, ls.p_error, ls.n)) {
          float bsdf_pdf = bsdf.pdf(wo, ls.wi);
          float w = power_heuristic(ls.pdf_solid_angle, bsdf_pdf);
          float cos_i = std::fabs(dot(ls.wi, bsdf.frame.n));
          radiance += beta * f * ls.radiance * (cos_i * w / ls.pdf_solid_angle);
        }
      }
    }

    // BSDF sampling for the next vertex.
    BsdfSample bs;
    if (!bsdf.sample(wo, sampler.get_2d(), bs)) break;
    float cos_i = std::fabs(dot(bs.wi, bsdf.frame.n));
    beta *= bs.f * (cos_i / bs.pdf_solid_angle);
    prev_bsdf_pdf = bs.pdf_solid_angle;
    prev_delta = bs.is_delta;
    prev_p = hit.p;
    ray = ctx.accel.spawn(hit, bs.wi);

    float u_rr = sampler.get_1d();
    if (depth + 1 >= settings.rr_min_depth) {
      float survive = std::min(1.0f, max_component(beta));
      if (u_rr >= survive) break;
      beta = beta / survive;
    }
  }
  return radiance;
}

}  // namespace rf
