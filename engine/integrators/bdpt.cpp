// The `bdpt` integrator: see bdpt.h.
#include "engine/integrators/bdpt.h"

#include <vector>

#include "engine/integrators/drivers.h"
#include "engine/integrators/light_path.h"

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

struct Tracer {
  const RenderContext& ctx;
  Sampler& sampler;
  TraceCounters& counters;
  const PerspectiveCamera& camera;  // at the camera sample's time (camera_at)

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
    ctx.lights.pdf_emission(v.light, v.hit.ng, w, pdf_pos, pdf_dir, ctx.at(v.hit.time));
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
    ctx.lights.pdf_emission(v.light, v.hit.ng, v.hit.ng, pdf_pos, pdf_dir, ctx.at(v.hit.time));
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

  // Records a subpath as trace_subpath (light_path.h) follows it: each surface vertex with its
  // area densities, pdf_fwd as this direction sampled it and pdf_rev as the other would; the
  // camera subpath records an escape into the environment as a light vertex.
  struct Recorder {
    const Tracer& tracer;
    std::vector<Vertex>& path;
    TransportMode mode;
    float pdf_fwd;  // solid-angle density of the ray leaving path[n - 1]
    size_t n = 1;   // vertices recorded; path[0] is the lens or light endpoint

    Vertex& next() {
      if (path.size() == n) path.emplace_back();  // only while a thread's longest path grows
      Vertex& v = path[n];
      v = Vertex{};
      return v;
    }
    void vertex(const PathVertex& pv) {
      Vertex& v = next();
      v.hit = pv.hit;
      v.bsdf = pv.bsdf;
      v.hit.ns = v.bsdf.shading_normal();
      v.on_surface = true;
      v.wo = pv.wo;
      v.beta = pv.beta;
      v.pdf_fwd = to_area(path[n - 1], pdf_fwd, v);
      if (tracer.ctx.accel.mesh(v.hit.mesh).emission)
        v.light = tracer.ctx.lights.area_light_index(v.hit.mesh, v.hit.prim);
      ++n;
    }
    void scattered(const PathVertex&, const BsdfSample& bs) {
      Vertex& v = path[n - 1];
      float pdf_rev = v.bsdf.pdf(
          bs.wi, v.wo,
          mode == TransportMode::Radiance ? TransportMode::Importance : TransportMode::Radiance);
      pdf_fwd = bs.pdf_solid_angle;
      if (bs.is_delta) {
        v.delta = true;
        pdf_fwd = pdf_rev = 0;
      }
      path[n - 2].pdf_rev = to_area(v, pdf_rev, path[n - 2]);
    }
    void escaped(Vec3 dir, RGB beta) {
      if (mode != TransportMode::Radiance || !tracer.ctx.lights.has_environment()) return;
      Vertex& v = next();
      v.kind = VertexKind::Light;
      v.infinite = true;
      v.light = uint32_t(tracer.ctx.lights.environment_index());
      v.dir = dir;
      v.beta = beta;
      v.pdf_fwd = pdf_fwd;
      ++n;
    }
  };

  // Extends path[0] (set; the ray leaves it with solid-angle density pdf_fwd) to at most
  // max_vertices vertices; returns the vertex count.
  template <TransportMode Mode>
  size_t walk(std::vector<Vertex>& path, Ray ray, RGB beta, float pdf_fwd, int64_t max_vertices) {
    Recorder rec{*this, path, Mode, pdf_fwd};
    trace_subpath<Mode>(ctx, sampler, ray, beta, int(max_vertices - 1), rec, counters);
    return rec.n;
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
        c = pt.beta * emitted_radiance(ctx.accel.mesh(pt.hit.mesh), pt.hit.ng, pt.wo);
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
      sampler.skip_1d();  // the light is picked by u_point.x (LightSelection::select)
      Vec2 u_point = sampler.get_2d();
      LightSample ls;
      if (!connectible(pt) ||
          !ctx.lights.sample_by_power(pt.hit.p, u_point, ls, ctx.at(pt.hit.time)))
        return RGB(0.0f);
      sampled.kind = VertexKind::Light;
      sampled.light = ls.light;
      sampled.infinite = ls.is_infinite;
      sampled.delta_light = ls.is_delta;
      sampled.on_surface = ctx.lights.kind(ls.light) == LightKind::Area;
      sampled.dir = ls.wi;
      sampled.hit.p = ls.p;
      sampled.hit.p_error = ls.p_error;
      sampled.hit.ng = sampled.hit.ns = ls.n;
      sampled.hit.time = pt.hit.time;
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

}  // namespace

RGB bdpt_camera_sample(const RenderContext& ctx, Ray ray, Sampler& sampler, SplatTarget& splats,
                       TraceCounters& counters, FrameNumber frame, BdptStrategyRecorder* rec) {
  // The camera at the sample's time: its camera ray's, its light subpath's and every t = 1
  // connection's.
  const PerspectiveCamera camera = camera_at(ctx, frame, ray.time);
  const int64_t max_depth = ctx.scene.render.integrator.max_depth;
  Tracer tr{ctx, sampler, counters, camera};
  std::vector<Vertex>& cam = t_camera_path;
  std::vector<Vertex>& light = t_light_path;
  if (cam.empty()) cam.emplace_back();
  if (light.empty()) light.emplace_back();

  // Camera subpath: the lens point, then up to max_depth + 1 surface vertices.
  cam[0] = Vertex{};
  cam[0].kind = VertexKind::Camera;
  cam[0].hit.p = ray.o;
  cam[0].hit.time = ray.time;  // the light subpath and every connection are made at this time
  cam[0].beta = RGB(1.0f);
  float pdf_pos, pdf_dir;
  camera.pdf_ray(ray.d, pdf_pos, pdf_dir);
  cam[0].pdf_fwd = pdf_pos;
  size_t n_cam = tr.walk<TransportMode::Radiance>(cam, ray, RGB(1.0f), pdf_dir, max_depth + 2);

  // Light subpath: a point on a light, then up to max_depth surface vertices.
  size_t n_light = 0;
  EmissionSample es;
  if (sample_light_path_start(ctx, sampler, es, /*infinite_lights=*/false, ray.time)) {
    Vertex& y0 = light[0];
    y0 = Vertex{};
    y0.kind = VertexKind::Light;
    y0.light = es.light;
    y0.on_surface = es.is_area;
    y0.delta_light = !es.is_area;
    y0.hit.p = es.p;
    y0.hit.p_error = es.p_error;
    y0.hit.ng = y0.hit.ns = es.n;
    y0.hit.time = ray.time;
    y0.beta = es.radiance;
    y0.pdf_fwd = es.pdf_pos;
    n_light = tr.walk<TransportMode::Importance>(light, light_path_ray(ctx, es, ray.time), es.beta,
                                                 es.pdf_dir, max_depth + 1);
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
        splat_to_film(splats, raster, c * w);
        if (rec) rec->splat(int(s), int(t), raster, c * w, c);
      } else {
        pixel += c * w;
        if (rec) rec->camera(int(s), int(t), c * w, c);
      }
    }
  return pixel;
}

// One pass: camera samples as for the path tracer, each with its own light subpath, so the
// splat plane is normalised by the camera sample count (render_camera_paths with splats).
SampleBuffer BdptIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                    bool parallel) const {
  return render_camera_paths<true>(
      ctx, task, parallel,
      [&](Ray ray, Sampler& sampler, SplatTarget& splats, TraceCounters& counters) {
        return bdpt_camera_sample(ctx, ray, sampler, splats, counters, task.frame);
      });
}

}  // namespace rf
