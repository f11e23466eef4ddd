// Progressive photon mapping, probabilistic form (`ppm`; Knaus & Zwicker 2011).
//
// Estimator. Pass i (i = pass + 1) is an independent photon-mapping image with its own photons
// and its own radius r_i, which depends only on i:
//   r_i^2 = r_1^2 prod_{k=1}^{i-1} (k + alpha) / (k + 1)     (KZ 2011, eq. 15; ~ i^(alpha - 1)),
// so the image, the average of passes, is consistent: the kernel's bias falls with r_i^2 and the
// variance of pass i grows only as 1 / r_i^2 ~ i^(1 - alpha), so the average's error -> 0.
// Per pass, M photon paths leave the lights (light by power, importance-mode BSDFs, shading
// normals corrected as in light.cpp, Russian roulette) and store a photon (position, incoming
// direction, throughput / M, depth k = scattering events including its own vertex) at every
// non-delta surface hit except the first (k >= 2): direct light is not taken from photons.
// The camera path follows delta BSDFs to the first non-delta vertex x (d scattering events before
// it) and there estimates
//   L(x) = Le(x) + direct(x) [next-event estimation, MIS with the BSDF sample, as path.cpp]
//        + sum over photons within r_i with k + d <= max_depth of
//          f_x(wo, wi_j) Phi_j |wi_j.ns| / |wi_j.ng| / (pi r_i^2)      (constant kernel).
// A photon of depth k stands for a path of k + d scattering events (the photon's vertex is x), so
// the max-depth rule is path's. The BSDF sample of x is traced only to find emission for MIS, and,
// when x's BSDF sampled a delta lobe (a plastic's smooth coat), to continue the camera path,
// which then gathers again at its next non-delta vertex.
// Bias (consistent, not unbiased): the density estimate blurs indirect light over r_i (corners
// and contact shadows are filled in, edges of indirect light softened, light on a thin wall's one
// side can reach the other side's points within r_i where the BSDF allows). The bias of pass i is
// O(r_i^2); it vanishes as passes grow, but any finite number of passes keeps some.
// Parameters: max_depth, rr_min_depth, photons (M per pass; default 100000), radius (r_1; 0 picks
// 0.02 x the scene's bounding radius, LightSet::scene_radius()), alpha (default 2/3, in (0, 1)).
// Per-pass state: the photons of pass p in a hash grid of cell 2 r_p (photon_grid.h), a pure
// function of (scene, settings, p): photon path i is keyed by (seed, frame, p, i) and paths are
// traced in fixed chunks concatenated in order. Shared read-only by the pass's tiles.
// Strengths: caustics (light -> specular -> diffuse -> camera) and caustics seen through
// specular surfaces (specular -> diffuse -> specular), which neither path nor light tracing
// nor BDPT samples well.
// Limits: biased for any finite pass count; memory per pass grows with M; environment and
// directional lights cannot emit photons and such scenes are refused; glossy receivers blur.
#include <algorithm>

#include "engine/integrators/light_subpaths.h"
#include "engine/integrators/photon_grid.h"

namespace rf {

namespace {
struct Photon {
  Vec3 p;
  Vec3 wi;    // unit, towards where the photon came from
  RGB power;  // photon path throughput / M
  int depth;  // scattering events, this vertex included (>= 2)
};

// r_i / r_1 for pass index i >= 1: sqrt(prod_{k=1}^{i-1} (k + alpha) / (k + 1)).
double radius_scale(uint32_t i, double alpha) {
  double r2 = 1;
  for (uint32_t k = 1; k < i; ++k) r2 *= (double(k) + alpha) / (double(k) + 1);
  return std::sqrt(r2);
}
}  // namespace

struct PhotonMap {
  PointHashGrid<Photon> grid;
  float inv_area = 0;  // 1 / (pi r^2)
};

std::shared_ptr<const PhotonMap> build_photon_map(const RenderContext& ctx, uint32_t pass,
                                                  TraceCounters& counters) {
  light_subpaths::require_finite_lights(ctx, "ppm");
  const IntegratorSettings& s = ctx.scene.render.integrator;
  const uint64_t paths = uint64_t(std::max(1, s.ppm_photons));
  const float inv_paths = 1.0f / float(paths);
  auto trace_one = [&](Sampler& sampler, std::vector<Photon>& out, TraceCounters& c) {
    light_subpaths::trace(
        ctx, sampler, s.max_depth,
        [&](const light_subpaths::Vertex& v) {
          if (v.depth >= 2) out.push_back(Photon{v.hit.p, v.wo, v.beta * inv_paths, v.depth});
        },
        c);
  };
  std::vector<Photon> photons =
      light_subpaths::trace_pass<Photon>(ctx, pass, paths, trace_one, counters);
  float r1 = s.ppm_radius > 0 ? s.ppm_radius : 0.02f * ctx.lights.scene_radius();
  float r = float(double(r1) * radius_scale(pass + 1, double(s.ppm_alpha)));
  auto map = std::make_shared<PhotonMap>();
  map->grid.build(std::move(photons), r);
  map->inv_area = 1.0f / (kPi * r * r);
  return map;
}

namespace {

// Density estimate of the photons' scattered radiance at a non-delta vertex with `depth`
// scattering events before it.
RGB gather_photons(const RenderContext& ctx, const PhotonMap& map, const SurfaceHit& hit,
                   const Bsdf& bsdf, Vec3 wo, int depth) {
  const int max_k = ctx.scene.render.integrator.max_depth - depth;
  const Vec3 ns = bsdf.shading_normal();
  RGB sum(0.0f);
  map.grid.for_each_near(hit.p, [&](const Photon& ph) {
    if (ph.depth > max_k) return;
    float cos_g = std::fabs(dot(ph.wi, hit.ng));
    if (cos_g == 0) return;
    RGB f = bsdf.eval(wo, ph.wi);
    if (!is_black(f)) sum += f * ph.power * (std::fabs(dot(ph.wi, ns)) / cos_g);
  });
  return sum * map.inv_area;
}


}  // namespace

RGB ppm_radiance(const RenderContext& ctx, const PhotonMap& map, Ray ray, Sampler& sampler,
                 TraceCounters& counters) {
  const IntegratorSettings& s = ctx.scene.render.integrator;
  RGB radiance(0.0f), beta(1.0f);
  float eta_scale = 1, prev_bsdf_pdf = 0, cone_width = 0;
  bool prev_delta = true;
  Vec3 prev_p = ray.o;
  for (int depth = 0;; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) break;  // no environment: refused by build_photon_map
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
    // A non-delta BSDF sample only looks for emission: the photons stand for the rest.
    if (!prev_delta || depth == s.max_depth) break;

    Bsdf bsdf = bsdf_at(ctx, hit, cone_width);
    float u_light = sampler.get_1d();
    Vec2 u_point = sampler.get_2d();
    if (!bsdf.is_delta())
      radiance += beta * (light_sample_mis(ctx, hit, bsdf, wo, u_light, u_point, counters) +
                          gather_photons(ctx, map, hit, bsdf, wo, depth));

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
    if (bs.is_delta && depth + 1 >= s.rr_min_depth) {
      float survive = std::min(1.0f, max_component(beta * eta_scale));
      if (u_rr >= survive) break;
      beta = beta / survive;
    }
  }
  return radiance;
}

}  // namespace rf
