// Bidirectional path tracing with multiple importance sampling (`bdpt`).
//
// Estimator (Veach 1997, ch. 10; Veach & Guibas 1995; pbrt-v3 section 16.3): each camera sample
// traces a camera subpath z_0 (the lens) ... z_{t-1} and a light subpath y_0 (on a light) ...
// y_{s-1}, then joins every prefix pair into a full path of s + t vertices:
//   s = 0        the camera subpath itself hit an emitter (area light, or escaped into the
//                environment);
//   s = 1        a light point is sampled afresh from z_{t-1} by LightSet::sample (next-event
//                estimation, the only way to reach directional lights and the environment);
//   t = 1        y_{s-1} is joined to a lens point (PerspectiveCamera::connect) and the result
//                is a splat at the raster point it reaches, weighted by the pixel filter and
//                carrying W_e's pixel-count factor (as light tracing);
//   s, t >= 2    a shadow ray joins y_{s-1} and z_{t-1}.
// Every strategy with s + t - 2 <= max_depth (pbrt-v4's depth, DESIGN.md) contributes, except
// (s, t) = (1, 1): a light seen directly is the (0, 2) strategy alone. The contributions of one
// path length are combined with the power heuristic (beta = 2) over every strategy that could
// have produced the path, computed by pbrt-v3's MISWeight: each vertex stores the area densities
// pdf_fwd (how its own subpath sampled it) and pdf_rev (how the other direction would), the
// connection vertices' pdf_rev are recomputed per strategy, and the weight is
// 1 / (1 + sum over other strategies of (p_other / p_this)^2), the ratios accumulated one vertex
// at a time. Delta BSDF vertices (mirror, glass, a smooth plastic coat's sampled lobe) have pdfs
// 0: strategies that would connect at them are skipped in the sum and never evaluated. Delta
// lights (point, spot, directional) cannot be hit: s = 0 does not exist for them.
// Lights at infinity (environment, directional) cannot start light subpaths here
// (LightSet::sample_emission refuses them), so their paths have only the s = 0 (environment
// only) and s = 1 strategies; the MIS sums treat s >= 2 as impossible for such paths, so the
// weights of the strategies that exist still sum to 1 (for the environment this is exactly the
// path tracer's light/BSDF MIS).
// The light subpath belongs to its camera sample: its random numbers come from the same Sampler
// after the camera subpath's (then the connections' own: light selection and point for s = 1,
// lens point for t = 1), so a pass renders the same anywhere. Shading normals are corrected in
// the light subpath's BSDFs (Veach 1997, 5.3) as in light tracing.
// Russian roulette (after rr_min_depth bounces, on throughput relative to the subpath's start;
// camera subpaths also undo refraction's radiance scaling, as path) ends subpaths early; the MIS
// weights use the sampling densities without the survival probabilities, which keeps every
// strategy unbiased (the weights still sum to 1 over the strategies of each path) at a small
// cost in variance.
// Memory: subpaths live in two per-thread vertex arrays that grow to the longest subpath the
// thread has seen (at most max_depth + 2 camera and max_depth + 1 light vertices) and are reused:
// no allocation per path once a thread has traced its longest one, and no cap on max_depth.
// Parameters: max_depth D, rr_min_depth. Per-strategy images (weighted and unweighted, Veach's
// figures): render_bdpt_strategies() in bdpt.h.
// Strengths: caustics seen directly or on diffuse surfaces (light -> specular -> diffuse ->
// camera, via t = 1 and s >= 2), light arriving through small openings or from hidden lights
// (light subpaths find the lit regions, connections do the rest), everything the path tracer
// does well it does as well (its strategies are among BDPT's).
// Cannot do: paths whose only non-delta vertex pair is missing, e.g. a caustic from a point light
// seen through a mirror (light -> specular -> diffuse -> specular -> camera: no strategy can
// connect), and reflected caustics of small lights remain noisy (that needs photon mapping or
// vertex merging). Infinite lights get only the path tracer's two strategies. A camera sample
// costs about two to three path-tracer samples (two subpaths plus O(s t) shadow rays): on the
// Cornell box (directly lit, the path tracer's home ground) BDPT reaches about half the path
// tracer's relMSE per sample but takes ~2.5x longer, so at equal time path wins by ~2x; in a
// room lit indirectly by a point light with glass and a mirror BDPT wins ~25-50x at equal time
// (tests/bdpt_test.cpp prints both).
#include "engine/integrators/bdpt.h"

#include <vector>

#include "engine/filter.h"
#include "engine/integrator.h"
#include "engine/render.h"

namespace rf {

namespace {

constexpr uint32_t kNoLight = ~0u;

enum class VertexKind : uint8_t { Camera, Light, Surface };

struct Vertex {
  VertexKind kind = VertexKind::Surface;
  bool on_surface = false;    // p has a normal (area densities get its cosine)
  bool delta = false;         // surface: scattered by a delta lobe
  bool delta_light = false;   // light: a delta position or direction (cannot be hit)
  bool infinite = false;      // light at infinity: `dir` matters, not hit.p
  uint32_t light = kNoLight;  // light: its index; surface: its area light index or kNoLight
  SurfaceHit hit;             // p, p_error, ng, ns (the BSDF's shading normal), mesh, prim
  Vec3 wo{0.0f};              // surface: unit direction towards the previous vertex
  Vec3 dir{0.0f};             // infinite light: unit direction from the scene to the light
  Bsdf bsdf;
  RGB beta{0.0f};
  float pdf_fwd = 0, pdf_rev = 0;  // area densities (solid angle towards an infinite light)
};

// The adjoint BSDF with shading normals (Veach 1997, eq. 5.19), as light.cpp.
float shading_correction(Vec3 wo, Vec3 wi, Vec3 ns, Vec3 ng) {
  float den = std::fabs(dot(wo, ng)) * std::fabs(dot(wi, ns));
  return den > 0 ? std::fabs(dot(wo, ns)) * std::fabs(dot(wi, ng)) / den : 0.0f;
}

// As light.cpp's splat(): W_e's pixel-count factor, then the filter weight per covered pixel.
void splat(SplatTarget& t, Vec2 raster, RGB value) {
  if (!is_finite(value) || is_black(value)) return;
  const FilterSettings& f = *t.filter;
  value *= float(t.width) * float(t.height);
  int x0 = std::max(0, int(std::floor(raster.x - f.radius - 0.5f)));
  int x1 = std::min(t.width - 1, int(std::floor(raster.x + f.radius - 0.5f)) + 1);
  int y0 = std::max(0, int(std::floor(raster.y - f.radius - 0.5f)));
  int y1 = std::min(t.height - 1, int(std::floor(raster.y + f.radius - 0.5f)) + 1);
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      Vec2 d{raster.x - (float(x) + 0.5f), raster.y - (float(y) + 0.5f)};
      if (f.type == FilterType::Box &&
          (d.x < -f.radius || d.x >= f.radius || d.y < -f.radius || d.y >= f.radius))
        continue;
      float w = filter_weight(f, d);
      if (w == 0) continue;
      t.out->push_back({uint32_t(y) * uint32_t(t.width) + uint32_t(x), value * w});
    }
}

struct Tracer {
  const RenderContext& ctx;
  const PerspectiveCamera& camera;
  Sampler& sampler;
  TraceCounters& counters;

  // Unit direction from v to `to`.
  static Vec3 direction(const Vertex& v, const Vertex& to) {
    return to.infinite ? to.dir : normalize(to.hit.p - v.hit.p);
  }

  // A solid-angle density at v towards next, as an area density at next.
  static float to_area(const Vertex& v, float pdf, const Vertex& next) {
    if (next.infinite) return pdf;
    Vec3 w = next.hit.p - v.hit.p;
    float d2 = length_sq(w);
    if (!(d2 > 0)) return 0.0f;
    if (next.on_surface) pdf *= std::fabs(dot(next.hit.ng, w)) / std::sqrt(d2);
    return pdf / d2;
  }

  // Area density at next of a light path leaving light vertex v (v.light) towards next.
  float pdf_light(const Vertex& v, const Vertex& next) const {
    if (v.infinite || next.infinite) return 0.0f;  // no light subpaths from infinity
    Vec3 w = next.hit.p - v.hit.p;
    float d2 = length_sq(w);
    if (!(d2 > 0)) return 0.0f;
    w = w / std::sqrt(d2);
    float pdf_pos, pdf_dir;
    ctx.lights.pdf_emission(v.light, v.hit.ng, w, pdf_pos, pdf_dir);
    float pdf = pdf_dir / d2;
    if (next.on_surface) pdf *= std::fabs(dot(next.hit.ng, w));
    return pdf;
  }

  // Density of light vertex v as s = 1 or a light subpath would choose it: area density with
  // selection (point/spot: the selection probability); for the environment the solid-angle
  // density of its direction (the s = 1 strategy's).
  float pdf_light_origin(const Vertex& v) const {
    if (v.infinite) return v.delta_light ? 0.0f : ctx.lights.pdf_environment(v.dir);
    float pdf_pos, pdf_dir;
    ctx.lights.pdf_emission(v.light, v.hit.ng, v.hit.ng, pdf_pos, pdf_dir);
    return pdf_pos;
  }

  // Area density at next of sampling it from v, having arrived from prev (the BSDF's
  // direction density, or the camera's).
  float pdf(const Vertex& v, const Vertex* prev, const Vertex& next, TransportMode mode) const {
    if (v.kind == VertexKind::Light) return pdf_light(v, next);
    Vec3 wn = direction(v, next);
    float p;
    if (v.kind == VertexKind::Camera) {
      float pdf_pos;
      camera.pdf_ray(wn, pdf_pos, p);
    } else {
      p = v.bsdf.pdf(direction(v, *prev), wn, mode);
    }
    return to_area(v, p, next);
  }

  static bool connectible(const Vertex& v) {
    switch (v.kind) {
      case VertexKind::Camera:
        return true;
      case VertexKind::Light:
        return !v.infinite;
      case VertexKind::Surface:
        return !v.bsdf.is_delta();
    }
    return false;
  }

  // f(v.wo -> wi), with the shading-normal correction for importance.
  static RGB f(const Vertex& v, Vec3 wi, TransportMode mode) {
    RGB r = v.bsdf.eval(v.wo, wi, mode);
    if (mode == TransportMode::Importance) r *= shading_correction(v.wo, wi, v.hit.ns, v.hit.ng);
    return r;
  }

  // Extends path[0..n) (path[n-1] set, ray leaving it with direction density pdf_fwd) by
  // scattering until max_vertices, a miss, an absorption or Russian roulette; returns the
  // vertex count. The camera subpath records an escape into the environment as a light vertex.
  size_t walk(std::vector<Vertex>& path, Ray ray, RGB beta, float pdf_fwd, TransportMode mode,
              int64_t max_vertices) {
    const IntegratorSettings& is = ctx.scene.render.integrator;
    const float beta_start = max_component(beta);
    float eta_scale = 1, cone_width = 0;
    size_t n = 1;
    while (int64_t(n) < max_vertices) {
      if (path.size() == n) path.emplace_back();  // only while a thread's longest path grows
      Vertex& prev = path[n - 1];
      Vertex& v = path[n];
      v = Vertex{};
      ++counters.rays;
      if (!ctx.accel.intersect(ray, v.hit)) {
        if (mode == TransportMode::Radiance && ctx.lights.has_environment()) {
          v.kind = VertexKind::Light;
          v.infinite = true;
          v.light = uint32_t(ctx.lights.environment_index());
          v.dir = ray.d;
          v.beta = beta;
          v.pdf_fwd = pdf_fwd;
          ++n;
        }
        break;
      }
      if (mode == TransportMode::Radiance) cone_width += ctx.pixel_spread * v.hit.t;
      v.bsdf = bsdf_at(ctx, v.hit, cone_width);
      v.hit.ns = v.bsdf.shading_normal();
      v.on_surface = true;
      v.wo = -ray.d;
      v.beta = beta;
      v.pdf_fwd = to_area(prev, pdf_fwd, v);
      if (ctx.scene.meshes[v.hit.mesh].emission)
        v.light = ctx.lights.area_light_index(v.hit.mesh, v.hit.prim);
      ++n;
      if (int64_t(n) >= max_vertices) break;

      float uc = sampler.get_1d();
      Vec2 u = sampler.get_2d();
      float u_rr = sampler.get_1d();
      BsdfSample bs;
      if (!v.bsdf.sample(v.wo, uc, u, mode, bs)) break;
      float pdf_rev = v.bsdf.pdf(
          bs.wi, v.wo,
          mode == TransportMode::Radiance ? TransportMode::Importance : TransportMode::Radiance);
      beta *= bs.f * (std::fabs(dot(bs.wi, v.hit.ns)) / bs.pdf_solid_angle);
      if (mode == TransportMode::Importance)
        beta *= shading_correction(v.wo, bs.wi, v.hit.ns, v.hit.ng);
      else if (bs.is_transmission)
        eta_scale *= sqr(bs.eta);
      pdf_fwd = bs.pdf_solid_angle;
      if (bs.is_delta) {
        v.delta = true;
        pdf_fwd = pdf_rev = 0;
      }
      prev.pdf_rev = to_area(v, pdf_rev, prev);
      if (is_black(beta) || !is_finite(beta)) break;
      ray = ctx.accel.spawn(v.hit, bs.wi);
      if (int64_t(n - 1) >= is.rr_min_depth) {  // n - 1 bounces so far
        float survive = std::min(1.0f, max_component(beta * eta_scale) / beta_start);
        if (u_rr >= survive) break;
        beta = beta / survive;
      }
    }
    return n;
  }

  // pbrt-v3's MISWeight with the power heuristic; `sampled` replaces light[0] (s = 1) or
  // camera[0] (t = 1) for this strategy. The vertices are restored before returning.
  float mis_weight(std::vector<Vertex>& light, std::vector<Vertex>& cam, const Vertex& sampled,
                   size_t s, size_t t) const {
    if (s + t == 2) return 1.0f;
    Vertex* swapped = s == 1 ? &light[0] : t == 1 ? &cam[0] : nullptr;
    Vertex saved_endpoint;
    if (swapped) {
      saved_endpoint = *swapped;
      *swapped = sampled;
    }
    Vertex* qs = s > 0 ? &light[s - 1] : nullptr;
    Vertex* pt = &cam[t - 1];
    Vertex* qs_minus = s > 1 ? &light[s - 2] : nullptr;
    Vertex* pt_minus = t > 1 ? &cam[t - 2] : nullptr;
    struct Saved {
      float pt_rev, pt_minus_rev, qs_rev, qs_minus_rev;
      bool pt_delta, qs_delta;
    } saved{pt->pdf_rev,
            pt_minus ? pt_minus->pdf_rev : 0,
            qs ? qs->pdf_rev : 0,
            qs_minus ? qs_minus->pdf_rev : 0,
            pt->delta,
            qs ? qs->delta : false};

    // The connection's endpoints are not degenerate; the densities the other direction would
    // have sampled them (and their predecessors) with.
    float pt_rev =
        s > 0 ? pdf(*qs, qs_minus, *pt, TransportMode::Importance) : pdf_light_origin(*pt);
    float pt_minus_rev = 0, qs_rev = 0, qs_minus_rev = 0;
    if (pt_minus)
      pt_minus_rev =
          s > 0 ? pdf(*pt, qs, *pt_minus, TransportMode::Importance) : pdf_light(*pt, *pt_minus);
    if (qs) qs_rev = pdf(*pt, pt_minus, *qs, TransportMode::Radiance);
    if (qs_minus) qs_minus_rev = pdf(*qs, pt, *qs_minus, TransportMode::Radiance);
    pt->delta = false;
    pt->pdf_rev = pt_rev;
    if (pt_minus) pt_minus->pdf_rev = pt_minus_rev;
    if (qs) {
      qs->delta = false;
      qs->pdf_rev = qs_rev;
    }
    if (qs_minus) qs_minus->pdf_rev = qs_minus_rev;

    // A light at infinity has only the s = 0 and s = 1 strategies.
    const bool at_infinity = s == 0 ? pt->infinite : s == 1 && qs->infinite;
    auto remap = [](float p) { return p != 0 ? p : 1.0f; };
    double sum = 0, r = 1;
    for (size_t i = t - 1; i > 0; --i) {  // strategy (s + t - i, i)
      r *= sqr(remap(cam[i].pdf_rev) / remap(cam[i].pdf_fwd));
      if (at_infinity && s + t - i >= 2) break;
      if (!cam[i].delta && !cam[i - 1].delta) sum += r;
    }
    r = 1;
    for (size_t i = s; i-- > 0;) {  // strategy (i, s + t - i)
      r *= sqr(remap(light[i].pdf_rev) / remap(light[i].pdf_fwd));
      bool delta_before = i > 0 ? light[i - 1].delta : light[0].delta_light;
      if (!light[i].delta && !delta_before) sum += r;
    }

    pt->pdf_rev = saved.pt_rev;
    pt->delta = saved.pt_delta;
    if (pt_minus) pt_minus->pdf_rev = saved.pt_minus_rev;
    if (qs) {
      qs->pdf_rev = saved.qs_rev;
      qs->delta = saved.qs_delta;
    }
    if (qs_minus) qs_minus->pdf_rev = saved.qs_minus_rev;
    if (swapped) *swapped = saved_endpoint;
    return float(1.0 / (1.0 + sum));
  }

  // The unweighted contribution of strategy (s, t) and its MIS weight; for t = 1 also the
  // raster point it lands on.
  RGB connect(std::vector<Vertex>& light, std::vector<Vertex>& cam, size_t s, size_t t,
              Vec2& raster, float& weight) {
    weight = 0;
    const Vertex& pt = cam[t - 1];
    if (t > 1 && s != 0 && pt.kind == VertexKind::Light) return RGB(0.0f);  // escaped
    Vertex sampled;
    RGB c(0.0f);
    if (s == 0) {
      if (pt.kind == VertexKind::Light)
        c = pt.beta * ctx.lights.environment_radiance(pt.dir);
      else if (pt.light != kNoLight)
        c = pt.beta * LightSet::emitted(ctx.scene.meshes[pt.hit.mesh], pt.hit.ng, pt.wo);
    } else if (t == 1) {
      const Vertex& qs = light[s - 1];
      Vec2 u_lens = sampler.get_2d();
      CameraConnection cc;
      if (!connectible(qs) || !camera.connect(qs.hit.p, u_lens, cc)) return RGB(0.0f);
      sampled.kind = VertexKind::Camera;
      sampled.hit.p = cc.p_lens;
      sampled.beta = RGB(cc.importance / cc.pdf_solid_angle);
      c = qs.beta * f(qs, cc.wi, TransportMode::Importance) * sampled.beta *
          std::fabs(dot(cc.wi, qs.hit.ns));
      if (is_black(c)) return c;
      ++counters.rays;
      if (!ctx.accel.visible(qs.hit, cc.p_lens, Vec3(0.0f), cc.wi)) return RGB(0.0f);
      raster = cc.raster;
    } else if (s == 1) {
      float u_select = sampler.get_1d();
      Vec2 u_point = sampler.get_2d();
      LightSample ls;
      if (!connectible(pt) || !ctx.lights.sample(pt.hit.p, u_select, u_point, ls)) return RGB(0.0f);
      sampled.kind = VertexKind::Light;
      sampled.light = ls.light;
      sampled.infinite = ls.is_infinite;
      sampled.delta_light = ls.is_delta;
      sampled.on_surface = ctx.lights.kind(ls.light) == LightKind::Area;
      sampled.dir = ls.wi;
      sampled.hit.p = ls.p;
      sampled.hit.p_error = ls.p_error;
      sampled.hit.ng = sampled.hit.ns = ls.n;
      sampled.beta = ls.radiance / ls.pdf_solid_angle;
      sampled.pdf_fwd = pdf_light_origin(sampled);
      c = pt.beta * f(pt, ls.wi, TransportMode::Radiance) * sampled.beta *
          std::fabs(dot(ls.wi, pt.hit.ns));
      if (is_black(c)) return c;
      ++counters.rays;
      if (!light_visible(ctx, pt.hit, ls)) return RGB(0.0f);
    } else {
      const Vertex& qs = light[s - 1];
      if (!connectible(qs) || !connectible(pt)) return RGB(0.0f);
      Vec3 d = qs.hit.p - pt.hit.p;
      float d2 = length_sq(d);
      if (!(d2 > 0)) return RGB(0.0f);
      Vec3 w = d / std::sqrt(d2);  // pt -> qs
      c = qs.beta * f(qs, -w, TransportMode::Importance) * f(pt, w, TransportMode::Radiance) *
          pt.beta;
      if (is_black(c)) return c;
      c *= std::fabs(dot(w, pt.hit.ns)) * std::fabs(dot(w, qs.hit.ns)) / d2;
      if (is_black(c)) return c;
      ++counters.rays;
      if (!ctx.accel.visible(pt.hit, qs.hit.p, qs.hit.p_error, qs.hit.ng)) return RGB(0.0f);
    }
    if (is_black(c)) return c;
    weight = mis_weight(light, cam, sampled, s, t);
    return c;
  }
};

thread_local std::vector<Vertex> t_camera_path, t_light_path;

struct NoRecorder {
  void camera(size_t, size_t, RGB, RGB) {}
  void splat(size_t, size_t, Vec2, RGB, RGB) {}
};

template <class Recorder>
RGB bdpt_trace(const RenderContext& ctx, const PerspectiveCamera& camera, Ray ray, Sampler& sampler,
               SplatTarget& splats, TraceCounters& counters, Recorder& rec) {
  const int64_t max_depth = ctx.scene.render.integrator.max_depth;
  Tracer tr{ctx, camera, sampler, counters};
  std::vector<Vertex>& cam = t_camera_path;
  std::vector<Vertex>& light = t_light_path;
  if (cam.empty()) cam.emplace_back();
  if (light.empty()) light.emplace_back();

  // Camera subpath: the lens point, then up to max_depth + 1 surface vertices.
  cam[0] = Vertex{};
  cam[0].kind = VertexKind::Camera;
  cam[0].hit.p = ray.o;
  cam[0].beta = RGB(1.0f);
  float pdf_pos, pdf_dir;
  camera.pdf_ray(ray.d, pdf_pos, pdf_dir);
  cam[0].pdf_fwd = pdf_pos;
  size_t n_cam = tr.walk(cam, ray, RGB(1.0f), pdf_dir, TransportMode::Radiance, max_depth + 2);

  // Light subpath: a point on a light, then up to max_depth surface vertices.
  size_t n_light = 0;
  float u_select = sampler.get_1d();
  Vec2 u_pos = sampler.get_2d(), u_dir = sampler.get_2d();
  EmissionSample es;
  if (max_depth >= 0 && ctx.lights.sample_emission(u_select, u_pos, u_dir, es)) {
    Vertex& y0 = light[0];
    y0 = Vertex{};
    y0.kind = VertexKind::Light;
    y0.light = es.light;
    y0.on_surface = es.is_area;
    y0.delta_light = !es.is_area;
    y0.hit.p = es.p;
    y0.hit.p_error = es.p_error;
    y0.hit.ng = y0.hit.ns = es.n;
    y0.beta = es.radiance;
    y0.pdf_fwd = es.pdf_pos;
    Ray r = es.is_area ? ctx.accel.spawn(y0.hit, es.dir) : Ray{es.p, es.dir, kInf};
    n_light = tr.walk(light, r, es.beta, es.pdf_dir, TransportMode::Importance, max_depth + 1);
  }

  // s = 1 samples its light afresh, so it runs even when no light subpath could start (the
  // environment or a directional light was picked): the MIS weights count it as available.
  RGB pixel(0.0f);
  const size_t s_end = std::max<size_t>(n_light, 1);
  for (size_t t = 1; t <= n_cam; ++t)
    for (size_t s = 0; s <= s_end; ++s) {
      int64_t depth = int64_t(s + t) - 2;
      if ((s == 1 && t == 1) || depth < 0 || depth > max_depth) continue;
      Vec2 raster;
      float w;
      RGB c = tr.connect(light, cam, s, t, raster, w);
      if (is_black(c)) continue;
      if (t == 1) {
        splat(splats, raster, c * w);
        rec.splat(s, t, raster, c * w, c);
      } else {
        pixel += c * w;
        rec.camera(s, t, c * w, c);
      }
    }
  return pixel;
}

// Collects one pass's strategy images (render_bdpt_strategies).
struct ImageRecorder {
  StrategyImages& out;
  const FilterSettings& filter;
  std::vector<int> index;  // strategy slot by depth-major (s, t) key, -1 when not shown
  // Per camera sample: its t >= 2 records, committed once its total is known to be finite.
  struct Pending {
    int slot;
    RGB weighted, unweighted;
  };
  std::vector<Pending> pending;
  std::vector<Splat> scratch;

  int slot(size_t s, size_t t) const {
    int64_t d = int64_t(s + t) - 2;
    if (d > out.max_shown_depth) return -1;
    return index[size_t(d) * size_t(out.max_shown_depth + 3) + s];
  }
  void camera(size_t s, size_t t, RGB weighted, RGB unweighted) {
    pending.push_back({slot(s, t), weighted, unweighted});
  }
  void splat(size_t s, size_t t, Vec2 raster, RGB weighted, RGB unweighted) {
    int k = slot(s, t);
    add_splat(raster, weighted, k >= 0 ? out.images[size_t(k)].weighted : out.rest);
    if (k >= 0) add_splat(raster, unweighted, out.images[size_t(k)].unweighted);
  }
  void add_splat(Vec2 raster, RGB value, std::vector<double>& img) {
    scratch.clear();
    SplatTarget target{&scratch, out.width, out.height, &filter};
    rf::splat(target, raster, value);
    for (const Splat& sp : scratch)
      for (int c = 0; c < 3; ++c) img[3 * size_t(sp.pixel) + size_t(c)] += double(sp.value[c]);
  }
};

}  // namespace

RGB bdpt_sample(const RenderContext& ctx, const PerspectiveCamera& camera, Ray ray,
                Sampler& sampler, SplatTarget& splats, TraceCounters& counters) {
  NoRecorder none;
  return bdpt_trace(ctx, camera, ray, sampler, splats, counters, none);
}

StrategyImages render_bdpt_strategies(const Scene& scene, uint32_t pass, int max_shown_depth) {
  Renderer renderer(scene);
  RenderContext ctx = renderer.context();
  const int w = scene.film.width, h = scene.film.height;
  const size_t pixels = size_t(w) * size_t(h);
  const RenderSettings& rs = scene.render;
  PerspectiveCamera camera(scene.camera, w, h);

  StrategyImages out;
  out.width = w;
  out.height = h;
  out.max_shown_depth = std::max(0, max_shown_depth);
  out.rest.assign(3 * pixels, 0.0);
  ImageRecorder rec{out, scene.film.filter, {}, {}, {}};
  const size_t stride = size_t(out.max_shown_depth + 3);
  rec.index.assign(size_t(out.max_shown_depth + 1) * stride, -1);
  for (int d = 0; d <= out.max_shown_depth; ++d)
    for (int s = 0; s <= d + 1; ++s) {
      if (s == 1 && d == 0) continue;
      rec.index[size_t(d) * stride + size_t(s)] = int(out.images.size());
      out.images.push_back({s, d + 2 - s, std::vector<double>(3 * pixels, 0.0),
                            std::vector<double>(3 * pixels, 0.0)});
    }
  // Camera strategies are summed per pixel first and divided by the pixel's sample count at the
  // end; splats are divided by the light path count (camera samples of the frame).
  const uint64_t spp = rs.spp_per_pass();
  std::vector<double> rest_camera(3 * pixels, 0.0);
  std::vector<std::vector<double>> cam_w(out.images.size(), std::vector<double>(3 * pixels, 0.0));
  std::vector<std::vector<double>> cam_u = cam_w;

  TraceCounters counters;
  Sampler sampler(kind_from_name(rs.sampler));
  std::vector<Splat> ignored;
  SplatTarget target{&ignored, w, h, &scene.film.filter};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (uint64_t k = 0; k < spp; ++k) {
        sampler.start_camera_sample(rs.seed, rs.frame, pass, x, y, k);
        FilterSample fs = sample_filter(scene.film.filter, sampler.get_2d());
        Vec2 u_lens = sampler.get_2d();
        Ray ray = camera.generate_ray(float(x) + 0.5f + fs.offset.x, float(y) + 0.5f + fs.offset.y,
                                      u_lens);
        rec.pending.clear();
        RGB l = bdpt_trace(ctx, camera, ray, sampler, target, counters, rec);
        ignored.clear();
        if (!is_finite(l * fs.weight)) continue;  // SampleBuffer drops the whole sample
        size_t p = 3 * (size_t(y) * size_t(w) + size_t(x));
        for (const ImageRecorder::Pending& r : rec.pending)
          for (int c = 0; c < 3; ++c) {
            double wv = double(r.weighted[c] * fs.weight), uv = double(r.unweighted[c] * fs.weight);
            if (r.slot < 0) {
              rest_camera[p + size_t(c)] += wv;
            } else {
              cam_w[size_t(r.slot)][p + size_t(c)] += wv;
              cam_u[size_t(r.slot)][p + size_t(c)] += uv;
            }
          }
      }
  const double inv_spp = spp > 0 ? 1.0 / double(spp) : 0.0;
  const double inv_paths = spp > 0 ? 1.0 / double(spp * pixels) : 0.0;
  for (size_t i = 0; i < 3 * pixels; ++i) {
    out.rest[i] = out.rest[i] * inv_paths + rest_camera[i] * inv_spp;
    for (size_t k = 0; k < out.images.size(); ++k) {
      StrategyImage& img = out.images[k];
      img.weighted[i] = img.weighted[i] * inv_paths + cam_w[k][i] * inv_spp;
      img.unweighted[i] = img.unweighted[i] * inv_paths + cam_u[k][i] * inv_spp;
    }
  }
  return out;
}

}  // namespace rf
