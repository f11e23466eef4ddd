// The `ir` integrator: see ir.h.
#include "engine/integrators/ir.h"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "engine/integrators/camera_path.h"
#include "engine/integrators/drivers.h"
#include "engine/integrators/light_path.h"
#include "engine/json_reader.h"
#include "engine/scene_error.h"

namespace rf {

namespace {

constexpr int kMaxVplSamples = IrIntegrator::kMaxVplSamples;
constexpr int kMaxVplCandidates = IrIntegrator::kMaxVplCandidates;

// Reflection-only materials scatter light only to the side of the surface it came from: a VPL on
// one lights only its own side, a receiver on one is lit only from wo's side.
bool reflects_only(MaterialType t) {
  return t == MaterialType::Diffuse || t == MaterialType::Conductor ||
         t == MaterialType::RoughConductor || t == MaterialType::Plastic;
}

struct Vpl {
  Bsdf bsdf;       // at the VPL's surface point (textures resolved)
  SurfaceHit hit;  // position, error bound and normals, for the shadow test
  Vec3 wi;         // unit, towards where the light came from
  RGB power;       // light-path throughput / N, times |wi.ns| / |wi.ng| (shading correction)
  int depth;       // scattering events on the light path, this vertex included (>= 1)
  Vec3 emit_n;     // ng turned to wi's side: a one-sided VPL lights only that side
  bool one_sided;  // reflection-only material
  float weight;    // mean over RGB of power x albedo: what the VPL can send (0: nothing)
};

// What the candidate loop reads of a VPL with weight, packed.
struct VplPoint {
  Vec3 p;
  float weight;
  Vec3 emit_n;
  uint32_t vpl : 31;
  uint32_t one_sided : 1;
};

// A slot of Walker's alias table with both of its points inline, so a candidate costs one
// memory access: the slot's own point with probability prob, else its alias.
struct AliasSlot {
  VplPoint own, alias;
  float prob;
};

struct VplSet {
  std::vector<Vpl> vpls;
  std::vector<AliasSlot> alias;  // over the VPLs with weight: each by weight / total_weight
  double total_weight = 0;
  float clamp_g = kInf;  // b: the bound on G
};

// Deposits a VPL at every non-delta vertex of a light path.
struct VplDeposit {
  const RenderContext& ctx;
  std::vector<Vpl>& out;
  float inv_paths;
  void vertex(const PathVertex& v) {
    if (v.bsdf.is_delta()) return;
    float cos_g = std::fabs(dot(v.wo, v.hit.ng));
    if (cos_g == 0) return;
    float corr = std::fabs(dot(v.wo, v.bsdf.shading_normal())) / cos_g;
    RGB power = v.beta * (corr * inv_paths);
    BsdfParams params = material_params_at(ctx, v.hit, 0);
    bool one_sided = reflects_only(params.type);
    // The albedo guess: exact for a diffuse VPL (a black one, e.g. a lamp's housing, is never
    // picked: it lights nothing); other kinds count as white.
    RGB albedo = params.type == MaterialType::Diffuse ? params.reflectance : RGB(1.0f);
    RGB pa = power * albedo;
    float weight = (pa.x + pa.y + pa.z) / 3;
    if (!(weight >= 0) || !std::isfinite(weight)) weight = 0;
    Vec3 emit_n = dot(v.wo, v.hit.ng) > 0 ? v.hit.ng : -v.hit.ng;
    out.push_back(Vpl{v.bsdf, v.hit, v.wo, power, v.depth, emit_n, one_sided, weight});
  }
  void scattered(const PathVertex&, const BsdfSample&) {}
  void escaped(Vec3, RGB) {}
};

// Walker's alias table over the points' weights (Vose's construction, deterministic).
void build_alias(VplSet& set, const std::vector<VplPoint>& points) {
  const size_t n = points.size();
  double total = 0;
  for (const VplPoint& q : points) total += double(q.weight);
  set.total_weight = total;
  std::vector<double> scaled(n);
  std::vector<uint32_t> alias(n), small, large;
  std::vector<float> prob(n, 1.0f);
  for (size_t i = 0; i < n; ++i) {
    alias[i] = uint32_t(i);
    scaled[i] = double(points[i].weight) * double(n) / total;
    (scaled[i] < 1 ? small : large).push_back(uint32_t(i));
  }
  while (!small.empty() && !large.empty()) {
    uint32_t s = small.back(), l = large.back();
    small.pop_back();
    prob[s] = float(scaled[s]), alias[s] = l;
    scaled[l] += scaled[s] - 1;
    if (scaled[l] < 1) large.pop_back(), small.push_back(l);
  }
  // Slots left in either list keep probability 1 (rounding leftovers).
  set.alias.resize(n);
  for (size_t i = 0; i < n; ++i) set.alias[i] = AliasSlot{points[i], points[alias[i]], prob[i]};
}

// The VPLs of one pass: vpl_paths light paths keyed by (seed, frame, pass, path index), and the
// alias table over those that have weight.
std::shared_ptr<const VplSet> build_vpls(const IrIntegrator& s, const RenderContext& ctx,
                                         FrameNumber frame, uint32_t pass,
                                         TraceCounters& counters) {
  auto set = std::make_shared<VplSet>();
  float dc = s.clamp_distance > 0 ? s.clamp_distance : 0.1f * ctx.lights.scene_radius();
  set->clamp_g = 1.0f / (dc * dc);
  const uint64_t paths = uint64_t(std::max(1, s.vpl_paths));
  const float inv_paths = 1.0f / float(paths);
  // A VPL of depth k serves paths of at least k + 1 scattering events.
  const int max_vpl_depth = ctx.scene.render.integrator.max_depth - 1;
  auto trace_one = [&](Sampler& sampler, std::vector<Vpl>& out, TraceCounters& c) {
    EmissionSample es;
    if (!sample_light_path_start(ctx, sampler, es, /*infinite_lights=*/true, /*time=*/0.0f)) return;
    VplDeposit deposit{ctx, out, inv_paths};
    trace_subpath<TransportMode::Importance>(ctx, sampler, light_path_ray(ctx, es, 0.0f),
                                             es.beta,  // still geometry: kMovingGeometry
                                             max_vpl_depth, deposit, c);
  };
  set->vpls = trace_light_paths<Vpl>(ctx, frame, pass, paths, trace_one, counters);
  std::vector<VplPoint> points;
  for (uint32_t i = 0; i < uint32_t(set->vpls.size()); ++i) {
    const Vpl& v = set->vpls[i];
    if (v.weight > 0) points.push_back(VplPoint{v.hit.p, v.weight, v.emit_n, i, v.one_sided});
  }
  if (!points.empty()) build_alias(*set, points);
  return set;
}

// One VPL's clamped contribution at a non-delta camera vertex: f_x f_y Phi V min(G, b), 0 when
// the VPL is too deep for max_depth (max_k) or occluded.
RGB vpl_contribution(const RenderContext& ctx, const VplSet& set, const Vpl& v,
                     const SurfaceHit& hit, const Bsdf& bsdf, Vec3 wo, int max_k,
                     TraceCounters& counters) {
  if (v.depth > max_k) return RGB(0.0f);
  Vec3 to = v.hit.p - hit.p;
  float d2 = dot(to, to);
  if (!(d2 > 0)) return RGB(0.0f);
  Vec3 w = to / std::sqrt(d2);
  float g = std::fabs(dot(w, bsdf.shading_normal())) * std::fabs(dot(w, v.hit.ng)) / d2;
  if (!(g > 0)) return RGB(0.0f);
  RGB fx = bsdf.eval(wo, w);
  if (is_black(fx)) return RGB(0.0f);
  RGB fy = v.bsdf.eval(v.wi, -w, TransportMode::Importance);
  if (is_black(fy)) return RGB(0.0f);
  ++counters.rays;
  if (!ctx.accel.visible(hit, v.hit.p, v.hit.p_error, v.hit.ng)) return RGB(0.0f);
  return fx * fy * v.power * std::min(g, set.clamp_g);
}

// The receiver of a VPL gather: a shading point, its shading normal turned to wo's side, and
// whether its BSDF reflects only (then nothing behind that normal lights it).
struct Receiver {
  Vec3 p, n;
  bool one_sided;
};

// The resampling target per unit weight: min(b, G) with both cosines, 0 where the VPL cannot
// light the receiver (the receiver behind the VPL's reflecting side, or the VPL behind the
// receiver's). It sees the shading point; only visibility and the BSDFs' lobes are left out.
inline float target_g(const VplPoint& q, const Receiver& r, float clamp_g) {
  Vec3 to = q.p - r.p;
  float d2 = dot(to, to), de = -dot(to, q.emit_n), dr = dot(to, r.n);
  if (!(d2 > 0) || (q.one_sided && de <= 0) || (r.one_sided && dr <= 0)) return 0;
  return std::min(clamp_g, std::fabs(de * dr) / (d2 * d2));
}

// One VPL picked by resampled importance sampling (Talbot et al. 2005, "Importance resampling for
// global illumination"): K candidates drawn by weight from the alias table, one of them kept with
// probability proportional to its target g, its term weighted by
//   W x (sum_k g_k) / (K x weight_y x g_y)      (W: the total weight).
// Given the candidates the expectation is the mean of c(x_k) / p(x_k) (p = weight / W), so the
// estimate is unbiased given the VPLs when the candidates' slots are uniform on [0, 1) over all
// picks together (see gather_vpls) and g > 0 wherever a VPL can contribute. Candidate k takes its
// slot from u_slot + k / K (mod 1) and its alias coin from u_coin + k x golden ratio (mod 1), so
// the coin is independent of the slot. Cost: K table reads and one shadow ray, whatever the
// number of VPLs.
RGB resample_vpl(const RenderContext& ctx, const VplSet& set, const SurfaceHit& hit,
                 const Bsdf& bsdf, Vec3 wo, const Receiver& r, int max_k, int k_count,
                 double u_slot, double u_coin, float u_pick, TraceCounters& counters) {
  const VplPoint* cand[kMaxVplCandidates];
  float g[kMaxVplCandidates];
  const double n = double(set.alias.size()), step = 1.0 / k_count;
  float g_sum = 0;
  for (int k = 0; k < k_count; ++k) {
    double u = u_slot + k * step, coin = u_coin + k * 0.6180339887498949;
    size_t slot = std::min(set.alias.size() - 1, size_t((u - std::floor(u)) * n));
    const AliasSlot& a = set.alias[slot];
    cand[k] = coin - std::floor(coin) < a.prob ? &a.own : &a.alias;
    g[k] = target_g(*cand[k], r, set.clamp_g);
    g_sum += g[k];
  }
  if (!(g_sum > 0)) return RGB(0.0f);
  float t = u_pick * g_sum;
  int k = 0, last = -1;
  for (; k < k_count; ++k) {
    if (g[k] > 0) last = k;
    if (t < g[k]) break;
    t -= g[k];
  }
  if (k == k_count) k = last;  // rounding: the last candidate with g > 0
  const VplPoint& q = *cand[k];
  double scale = set.total_weight * double(g_sum) / (double(k_count) * q.weight * g[k]);
  return vpl_contribution(ctx, set, set.vpls[q.vpl], hit, bsdf, wo, max_k, counters) * float(scale);
}

// The VPLs' clamped contribution at a non-delta camera vertex with `depth` scattering events
// before it: sum over VPLs of depth k <= max_depth - depth - 1 of f_x f_y Phi V min(G, b),
// estimated as the mean of vpl_samples resampled picks (u: 3 numbers each), or summed over every
// VPL when vpl_samples is 0. The M picks' K candidates stratify the slots together: pick i's
// slots start in [i, i + 1) / (M K), so over the M picks each stratum of width 1 / (M K) holds
// one candidate and the mean of the picks is unbiased.
RGB gather_vpls(const IrIntegrator& ir, const RenderContext& ctx, const VplSet& set,
                const SurfaceHit& hit, const Bsdf& bsdf, Vec3 wo, int depth, const float* u,
                TraceCounters& counters) {
  const int max_k = ctx.scene.render.integrator.max_depth - depth - 1;
  RGB sum(0.0f);
  if (max_k < 1) return sum;
  const int picks = ir.vpl_samples;
  if (picks == 0) {
    for (const Vpl& v : set.vpls)
      sum += vpl_contribution(ctx, set, v, hit, bsdf, wo, max_k, counters);
    return sum;
  }
  if (set.alias.empty()) return sum;
  Vec3 n = bsdf.shading_normal();
  if (dot(wo, n) < 0) n = -n;
  const Receiver r{hit.p, n,
                   reflects_only(ctx.scene.materials[ctx.accel.mesh(hit.mesh).material].type)};
  const int k_count = ir.vpl_candidates;
  for (int i = 0; i < picks; ++i) {
    double u_slot = (i + double(u[3 * i])) / (double(picks) * k_count);
    sum += resample_vpl(ctx, set, hit, bsdf, wo, r, max_k, k_count, u_slot, u[3 * i + 1],
                        u[3 * i + 2], counters);
  }
  return sum / float(picks);
}

// The camera path: `residual` is the weight of the current vertex's non-delta terms (direct
// light, VPL gather, non-delta continuation): 1 after the camera or a delta scattering,
// (1 - b / G)^+ after a non-delta BSDF sample (0 without compensation). Emission found by a
// non-delta BSDF sample belongs to the previous vertex's direct light (MIS), not to the residual.
RGB ir_radiance(const IrIntegrator& ir, const RenderContext& ctx, const VplSet& set, Ray ray,
                Sampler& sampler, TraceCounters& counters) {
  const IntegratorSettings& s = ctx.scene.render.integrator;
  const int n_u = 3 * ir.vpl_samples;  // the VPL picks' numbers, drawn at every vertex
  float u_vpl[3 * kMaxVplSamples];
  RGB radiance(0.0f);
  CameraPath path(ray.o);
  Vec3 prev_ns(0.0f);  // the previous vertex's shading normal (the residual's geometry term)
  for (int depth = 0;; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) {
      // The environment, as emission found by the previous vertex's BSDF sample (its direct
      // light, MIS-weighted; the VPLs stand only for light that scattered on a surface).
      path.escape(ctx, ray.d, radiance);
      break;
    }
    Vec3 wo = -ray.d;
    path.arrive(ctx, hit, wo, radiance);
    if (depth == s.max_depth) break;

    float residual = 1;
    if (!path.prev_delta) {
      Vec3 d = hit.p - path.prev_p;
      float d2 = dot(d, d);
      float g = d2 > 0 ? std::fabs(dot(ray.d, prev_ns)) * std::fabs(dot(ray.d, hit.ng)) / d2 : 0;
      residual = ir.compensation && g > set.clamp_g ? 1 - set.clamp_g / g : 0;
    }

    Bsdf bsdf = bsdf_at(ctx, hit, path.cone_width);
    float u_light = sampler.get_1d();
    Vec2 u_point = sampler.get_2d();
    for (int i = 0; i < n_u; ++i) u_vpl[i] = sampler.get_1d();
    if (!bsdf.is_delta() && residual > 0) {
      RGB terms = light_sample_mis(ctx, hit, bsdf, wo, u_light, u_point, counters) +
                  gather_vpls(ir, ctx, set, hit, bsdf, wo, depth, u_vpl, counters);
      radiance += path.beta * terms * residual;
    }

    BsdfSample bs;
    float uc = sampler.get_1d();
    Vec2 u = sampler.get_2d();
    if (!bsdf.sample(wo, uc, u, TransportMode::Radiance, bs)) break;
    if (!bs.is_delta) {
      if (residual == 0) break;
      path.beta *= residual;
    }
    ray = path.scatter(ctx, hit, bsdf, wo, bs);
    prev_ns = bsdf.shading_normal();

    float u_rr = sampler.get_1d();
    if (depth + 1 >= s.rr_min_depth && !path.survives_roulette(u_rr)) break;
  }
  return radiance;
}

}  // namespace

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
