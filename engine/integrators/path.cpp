// The `path` integrator: see path.h.
#include "engine/integrators/path.h"

#include "engine/integrators/drivers.h"

namespace rf {

namespace {

RGB path_radiance(const RenderContext& ctx, Ray ray, Sampler& sampler, TraceCounters& counters) {
  const IntegratorSettings& settings = ctx.scene.render.integrator;
  RGB radiance(0.0f), beta(1.0f);
  float eta_scale = 1;
  float prev_bsdf_pdf = 0;
  bool prev_delta = true;  // the camera ray counts as "specular": emission is taken unweighted
  Vec3 prev_p = ray.o, prev_n(0.0f);  // the last vertex and its receiver normal (light selection)
  float cone_width = 0;               // ray-cone width at the current hit, for texture filtering
  for (int depth = 0;; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) {
      add_escaped(ctx, ray.d, prev_delta, prev_bsdf_pdf, beta, radiance);
      break;
    }
    const Mesh& mesh = ctx.accel.mesh(hit.mesh);
    Vec3 wo = -ray.d;
    cone_width += ctx.pixel_spread * hit.t;

    RGB le = LightSet::emitted(mesh, hit.ng, wo);
    if (!is_black(le)) {
      if (prev_delta) {
        radiance += beta * le;
      } else {
        float light_pdf =
            ctx.lights.pdf_solid_angle(prev_p, prev_n, hit.mesh, hit.prim, hit.p, hit.ng);
        radiance += beta * le * power_heuristic(prev_bsdf_pdf, light_pdf);
      }
    }
    if (depth == settings.max_depth) break;

    Bsdf bsdf = bsdf_at(ctx, hit, cone_width);

    // Next-event estimation. Every vertex consumes the same dimensions whether or not it reads
    // them (skipped ones cost nothing), so a material change does not reshuffle the random
    // numbers of later bounces.
    const bool nee = !bsdf.is_delta();
    float u_light = sampler.get_1d_if(nee);
    Vec2 u_point = sampler.get_2d_if(nee);
    if (nee) radiance += beta * light_sample_mis(ctx, hit, bsdf, wo, u_light, u_point, counters);

    // BSDF sampling for the next vertex.
    BsdfSample bs;
    float uc = sampler.get_1d_if(bsdf.sample_uses_choice());
    Vec2 u = sampler.get_2d_if(bsdf.sample_uses_direction());
    if (!bsdf.sample(wo, uc, u, TransportMode::Radiance, bs)) break;
    float cos_i = std::fabs(dot(bs.wi, bsdf.shading_normal()));
    beta *= bs.f * (cos_i / bs.pdf_solid_angle);
    if (bs.is_transmission) eta_scale *= sqr(bs.eta);
    prev_bsdf_pdf = bs.pdf_solid_angle;
    prev_delta = bs.is_delta;
    prev_p = hit.p;
    prev_n = receiver_normal(bsdf, wo);
    ray = ctx.accel.spawn(hit, bs.wi);

    const bool roulette = depth + 1 >= settings.rr_min_depth;
    float u_rr = sampler.get_1d_if(roulette);
    if (roulette) {
      float survive = std::min(1.0f, max_component(beta * eta_scale));
      if (u_rr >= survive) break;
      beta = beta / survive;
    }
  }
  return radiance;
}

}  // namespace

SampleBuffer PathIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                    bool parallel) const {
  return render_camera_paths<false>(ctx, task, parallel,
                                    [&](Ray ray, Sampler& sampler, TraceCounters& counters) {
                                      return path_radiance(ctx, ray, sampler, counters);
                                    });
}

}  // namespace rf
