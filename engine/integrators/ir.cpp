// The `ir` integrator: see ir.h.
#include "engine/integrators/ir.h"

#include <algorithm>
#include <cstdio>

#include "engine/integrators/drivers.h"
#include "engine/integrators/light_path.h"
#include "engine/json_reader.h"

namespace rf {

namespace {

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

// Deposits a VPL at every non-delta vertex of a light path.
struct VplDeposit {
  std::vector<Vpl>& out;
  float inv_paths;
  void vertex(const PathVertex& v) {
    if (v.bsdf.is_delta()) return;
    float cos_g = std::fabs(dot(v.wo, v.hit.ng));
    if (cos_g == 0) return;
    float corr = std::fabs(dot(v.wo, v.bsdf.shading_normal())) / cos_g;
    out.push_back(Vpl{v.bsdf, v.hit, v.wo, v.beta * (corr * inv_paths), v.depth});
  }
  void scattered(const PathVertex&, const BsdfSample&) {}
  void escaped(Vec3, RGB) {}
};

// The VPLs of one pass: vpl_paths light paths keyed by (seed, frame, pass, path index).
std::shared_ptr<const VplSet> build_vpls(const IrIntegrator& s, const RenderContext& ctx,
                                         uint32_t frame, uint32_t pass, TraceCounters& counters) {
  auto set = std::make_shared<VplSet>();
  float dc = s.clamp_distance > 0 ? s.clamp_distance : 0.1f * ctx.lights.scene_radius();
  set->clamp_g = 1.0f / (dc * dc);
  const uint64_t paths = uint64_t(std::max(1, s.vpl_paths));
  const float inv_paths = 1.0f / float(paths);
  // A VPL of depth k serves paths of at least k + 1 scattering events.
  const int max_vpl_depth = ctx.scene.render.integrator.max_depth - 1;
  auto trace_one = [&](Sampler& sampler, std::vector<Vpl>& out, TraceCounters& c) {
    EmissionSample es;
    if (!sample_light_path_start(ctx, sampler, es)) return;
    VplDeposit deposit{out, inv_paths};
    trace_subpath<TransportMode::Importance>(ctx, sampler, light_path_ray(ctx, es), es.beta,
                                             max_vpl_depth, deposit, c);
  };
  set->vpls = trace_light_paths<Vpl>(ctx, frame, pass, paths, trace_one, counters);
  return set;
}

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

// The camera path: `residual` is the weight of the current vertex's non-delta terms (direct
// light, VPL gather, non-delta continuation): 1 after the camera or a delta scattering,
// (1 - b / G)^+ after a non-delta BSDF sample (0 without compensation). Emission found by a
// non-delta BSDF sample belongs to the previous vertex's direct light (MIS), not to the residual.
RGB ir_radiance(const IrIntegrator& ir, const RenderContext& ctx, const VplSet& set, Ray ray,
                Sampler& sampler, TraceCounters& counters) {
  const IntegratorSettings& s = ctx.scene.render.integrator;
  RGB radiance(0.0f), beta(1.0f);
  float eta_scale = 1, prev_bsdf_pdf = 0, cone_width = 0;
  bool prev_delta = true;
  Vec3 prev_p = ray.o, prev_ns(0.0f);
  for (int depth = 0;; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) break;  // no environment: refused by build_vpls
    const Mesh& mesh = ctx.accel.mesh(hit.mesh);
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
      residual = ir.compensation && g > set.clamp_g ? 1 - set.clamp_g / g : 0;
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

}  // namespace

void IrIntegrator::parse(const JsonReader& r, const Json& j, const std::string& p) {
  if (const Json* v = r.find(j, "vpl_paths")) vpl_paths = int(r.integer(*v, p + ".vpl_paths", 1, 1 << 24));
  if (const Json* v = r.find(j, "clamp_distance")) {
    clamp_distance = r.number(*v, p + ".clamp_distance");
    if (clamp_distance < 0)
      r.fail(p + ".clamp_distance", "must be >= 0 (0: automatic), got " + v->dump());
  }
  if (const Json* v = r.find(j, "compensation")) compensation = r.boolean(*v, p + ".compensation");
}

std::string IrIntegrator::settings_text() const {
  char buf[128];
  std::snprintf(buf, sizeof buf, ";ir=%d:%.9g:%s", vpl_paths, double(clamp_distance),
                compensation ? "comp" : "nocomp");
  return buf;
}

void IrIntegrator::check(const Scene& scene) const { require_finite_emitters(scene, kName); }

SampleBuffer IrIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                  bool parallel) const {
  return render_camera_paths_with_pass_state<VplSet>(
      ctx, task, parallel,
      [&](TraceCounters& c) { return build_vpls(*this, ctx, task.frame, task.pass, c); },
      [&](const VplSet& vpls, Ray ray, Sampler& sampler, TraceCounters& c) {
        return ir_radiance(*this, ctx, vpls, ray, sampler, c);
      });
}

}  // namespace rf
