// Instant radiosity with a clamped geometry term and its compensation (`ir`).
//
// Estimator (Keller 1997; Kollig & Keller 2004, "Illumination in the presence of weak
// singularities"). Per pass, N light paths (light by power, importance-mode BSDFs, shading
// normals corrected as in light.cpp) leave a virtual point light (VPL) at every non-delta surface
// vertex y: its BSDF, the direction the light arrived from, its throughput / N and its depth k
// (scattering events on the light path up to and including y). The camera path follows delta
// BSDFs to a non-delta vertex x; there
//   L(x) = Le(x) + direct(x) [next-event estimation, MIS with the BSDF sample, as path.cpp]
//        + sum_j f_x f_yj Phi_j V min(G, b)     G = |w.ns_x| |w.ng_y| / |x - y|^2
//        + compensation.
// The VPLs estimate the indirect light with G clamped at b = 1 / d_c^2, which removes the bright
// splotches near VPLs (the weak singularity). The clamped part, the integral of f_x (G - b)^+ V
// Ls(y), is recovered by the BSDF sample of x: it is traced to y, and y's non-delta terms (its
// direct light, its VPL gather, its own continuation) are weighted by (1 - b / G(x, y))^+, which
// is 0 for most samples, so the continuation usually ends there. Light that y scatters by a delta
// lobe, and anything seen through delta vertices, is not covered by the VPLs and is followed with
// full weight. Hence the estimator is unbiased and converges to path's image at the same max
// depth: a VPL of depth k gathered at a camera vertex with d scattering events before it makes a
// path of d + 1 + k events, and it is used only when that is at most max_depth (Russian roulette
// as path.cpp on the continuation).
// Compensation off: the (G - b)^+ part is dropped, i.e. the clamped light is lost. The image is
// then biased: darker, in concave corners and wherever surfaces see each other from closer than
// d_c. Measured on the Cornell box (box 2 wide, tests/ir_ppm_test.cpp): image means 0.6% / 0.5% /
// 0.3% (R, G, B) darker at the default d_c (0.17), 5.3% / 4.0% / 2.3% at d_c = 1.
// Parameters: max_depth, rr_min_depth, vpl_paths (N, light paths per pass; default 256),
// clamp_distance (d_c; 0 picks 0.1 x the scene's bounding radius), compensation (default true).
// Per-pass state: the VPL list of pass p, a pure function of (scene, settings, p): light path i
// is keyed by (seed, frame, p, i) and paths are traced in fixed chunks concatenated in order. It
// is shared read-only by the tiles of the pass; each pass is an independent estimate.
// Strengths: smooth, low-noise indirect light in diffuse scenes from few light paths; the cost per
// pixel is independent of the light's size or visibility from the camera.
// Limits: each camera vertex casts one shadow ray per VPL (cost O(VPLs) per pixel); VPL noise is
// correlated across the image within a pass (low-frequency blotches, not pixel noise); glossy
// receivers are poorly served by VPLs and rely on the compensation path; environment and
// directional lights cannot start light paths and such scenes are refused.
#include <algorithm>

#include "engine/integrators/light_subpaths.h"

namespace rf {

struct Vpl {
  Bsdf bsdf;       // at the VPL's surface point (textures resolved)
  SurfaceHit hit;  // position, error bound and normals, for the shadow test
  Vec3 wi;         // unit, towards where the light came from
  RGB power;       // light-path throughput / N, times |wi.ns| / |wi.ng| (shading correction)
  int depth;       // scattering events on the light path, this vertex included (>= 1)
};

struct VplSet {
  std::vector<Vpl> vpls;
  float clamp_g = kInf;  // b: the bound on G
};

std::shared_ptr<const VplSet> build_vpls(const RenderContext& ctx, uint32_t pass,
                                         TraceCounters& counters) {
  light_subpaths::require_finite_lights(ctx, "ir");
  const IntegratorSettings& s = ctx.scene.render.integrator;
  auto set = std::make_shared<VplSet>();
  float dc = s.ir_clamp_distance > 0 ? s.ir_clamp_distance : 0.1f * ctx.lights.scene_radius();
  set->clamp_g = 1.0f / (dc * dc);
  const uint64_t paths = uint64_t(std::max(1, s.ir_vpl_paths));
  const float inv_paths = 1.0f / float(paths);
  // A VPL of depth k serves paths of at least k + 1 scattering events.
  const int max_vpl_depth = s.max_depth - 1;
  auto trace_one = [&](Sampler& sampler, std::vector<Vpl>& out, TraceCounters& c) {
    light_subpaths::trace(
        ctx, sampler, max_vpl_depth,
        [&](const light_subpaths::Vertex& v) {
          float cos_g = std::fabs(dot(v.wo, v.hit.ng));
          if (cos_g == 0) return;
          float corr = std::fabs(dot(v.wo, v.bsdf.shading_normal())) / cos_g;
          out.push_back(Vpl{v.bsdf, v.hit, v.wo, v.beta * (corr * inv_paths), v.depth});
        },
        c);
  };
  set->vpls = light_subpaths::trace_pass<Vpl>(ctx, pass, paths, trace_one, counters);
  return set;
}

namespace {

// The VPLs' clamped contribution at a non-delta camera vertex with `depth` scattering events
// before it: sum over VPLs of depth k <= max_depth - depth - 1 of f_x f_y Phi V min(G, b).
RGB gather_vpls(const RenderContext& ctx, const VplSet& set, const SurfaceHit& hit,
                const Bsdf& bsdf, Vec3 wo, int depth, TraceCounters& counters) {
  const int max_k = ctx.scene.render.integrator.max_depth - depth - 1;
  const Vec3 ns = bsdf.shading_normal();
  RGB sum(0.0f);
  for (const Vpl& v : set.vpls) {
    if (v.depth > max_k) continue;
    Vec3 to = v.hit.p - hit.p;
    float d2 = dot(to, to);
    if (!(d2 > 0)) continue;
    Vec3 w = to / std::sqrt(d2);
    float g = std::fabs(dot(w, ns)) * std::fabs(dot(w, v.hit.ng)) / d2;
    if (!(g > 0)) continue;
    RGB fx = bsdf.eval(wo, w);
    if (is_black(fx)) continue;
    RGB fy = v.bsdf.eval(v.wi, -w, TransportMode::Importance);
    if (is_black(fy)) continue;
    ++counters.rays;
    if (!ctx.accel.visible(hit, v.hit.p, v.hit.p_error, v.hit.ng)) continue;
    sum += fx * fy * v.power * std::min(g, set.clamp_g);
  }
  return sum;
}


}  // namespace

// The camera path: `residual` is the weight of the current vertex's non-delta terms (direct
// light, VPL gather, non-delta continuation): 1 after the camera or a delta scattering,
// (1 - b / G)^+ after a non-delta BSDF sample (0 without compensation). Emission found by a
// non-delta BSDF sample belongs to the previous vertex's direct light (MIS), not to the residual.
RGB ir_radiance(const RenderContext& ctx, const VplSet& set, Ray ray, Sampler& sampler,
                TraceCounters& counters) {
  const IntegratorSettings& s = ctx.scene.render.integrator;
  RGB radiance(0.0f), beta(1.0f);
  float eta_scale = 1, prev_bsdf_pdf = 0, cone_width = 0;
  bool prev_delta = true;
  Vec3 prev_p = ray.o, prev_ns(0.0f);
  for (int depth = 0;; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) break;  // no environment: refused by build_vpls
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
    if (depth == s.max_depth) break;

    float residual = 1;
    if (!prev_delta) {
      Vec3 d = hit.p - prev_p;
      float d2 = dot(d, d);
      float g = d2 > 0 ? std::fabs(dot(ray.d, prev_ns)) * std::fabs(dot(ray.d, hit.ng)) / d2 : 0;
      residual = s.ir_compensation && g > set.clamp_g ? 1 - set.clamp_g / g : 0;
    }

    Bsdf bsdf = bsdf_at(ctx, hit, cone_width);
    float u_light = sampler.get_1d();
    Vec2 u_point = sampler.get_2d();
    if (!bsdf.is_delta() && residual > 0) {
      RGB terms = light_sample_mis(ctx, hit, bsdf, wo, u_light, u_point, counters) +
                  gather_vpls(ctx, set, hit, bsdf, wo, depth, counters);
      radiance += beta * terms * residual;
    }

    BsdfSample bs;
    float uc = sampler.get_1d();
    Vec2 u = sampler.get_2d();
    if (!bsdf.sample(wo, uc, u, TransportMode::Radiance, bs)) break;
    if (!bs.is_delta) {
      if (residual == 0) break;
      beta *= residual;
    }
    float cos_i = std::fabs(dot(bs.wi, bsdf.shading_normal()));
    beta *= bs.f * (cos_i / bs.pdf_solid_angle);
    if (bs.is_transmission) eta_scale *= sqr(bs.eta);
    prev_bsdf_pdf = bs.pdf_solid_angle;
    prev_delta = bs.is_delta;
    prev_p = hit.p;
    prev_ns = bsdf.shading_normal();
    ray = ctx.accel.spawn(hit, bs.wi);

    float u_rr = sampler.get_1d();
    if (depth + 1 >= s.rr_min_depth) {
      float survive = std::min(1.0f, max_component(beta * eta_scale));
      if (u_rr >= survive) break;
      beta = beta / survive;
    }
  }
  return radiance;
}

}  // namespace rf
