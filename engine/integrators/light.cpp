// Light tracing, or particle tracing (`light`).
//
// Estimator: paths start on the lights (a light chosen by power, a point on it, a direction by
// its emission distribution) and scatter through the scene with importance-mode BSDFs; every
// vertex, the one on the light included, connects to the camera through the camera's importance
// W_e and splats its contribution beta * f * |cos| * W_e / pdf_lens at the raster point it reaches,
// weighted by the pixel filter (DESIGN.md "Pixels, filters and splats"). With W_e normalised over
// the whole film, a pixel's importance is W_e times the pixel count, so every splat carries that
// factor; the image is the splat plane divided by the number of light paths. A light path's
// random numbers are keyed by (seed, frame, pass, light-path index): any pass range renders
// anywhere. Non-symmetric shading normals are corrected (Veach 1997, 5.3).
// Parameters: max_depth (a vertex after k scatterings connects through one more: paths with up
// to max_depth scattering events), rr_min_depth (roulette on throughput relative to its start).
// Strengths: caustics seen on diffuse surfaces (light -> specular -> diffuse -> camera), which the
// path tracer finds only by chance.
// Cannot do: anything seen through a specular surface (a connection through a delta BSDF is
// impossible), the environment and directional lights (no finite emission position: such
// scenes are refused), and it is noisy wherever the camera sees little of what lights reach.
#include "engine/filter.h"
#include "engine/integrator.h"

namespace rf {

namespace {

// The adjoint BSDF with shading normals: f* = f * |wo.ns| |wi.ng| / (|wo.ng| |wi.ns|) for
// importance arriving from wo and leaving towards wi (Veach 1997, eq. 5.19).
float shading_correction(Vec3 wo, Vec3 wi, Vec3 ns, Vec3 ng) {
  float den = std::fabs(dot(wo, ng)) * std::fabs(dot(wi, ns));
  return den > 0 ? std::fabs(dot(wo, ns)) * std::fabs(dot(wi, ng)) / den : 0.0f;
}

void splat(SplatTarget& t, Vec2 raster, RGB value) {
  if (!is_finite(value) || is_black(value)) return;
  const FilterSettings& f = *t.filter;
  value *= float(t.width) * float(t.height);  // a pixel's importance: W_e times the pixel count
  int x0 = std::max(0, int(std::floor(raster.x - f.radius - 0.5f)));
  int x1 = std::min(t.width - 1, int(std::floor(raster.x + f.radius - 0.5f)) + 1);
  int y0 = std::max(0, int(std::floor(raster.y - f.radius - 0.5f)));
  int y1 = std::min(t.height - 1, int(std::floor(raster.y + f.radius - 0.5f)) + 1);
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      Vec2 d{raster.x - (float(x) + 0.5f), raster.y - (float(y) + 0.5f)};
      // The box is half-open so a splat on a pixel border lands in exactly one pixel.
      if (f.type == FilterType::Box &&
          (d.x < -f.radius || d.x >= f.radius || d.y < -f.radius || d.y >= f.radius))
        continue;
      float w = filter_weight(f, d);
      if (w == 0) continue;
      t.out->push_back({uint32_t(y) * uint32_t(t.width) + uint32_t(x), value * w});
    }
}

}  // namespace

void trace_light_path(const RenderContext& ctx, const PerspectiveCamera& camera, Sampler& sampler,
                      SplatTarget& target, TraceCounters& counters) {
  const IntegratorSettings& s = ctx.scene.render.integrator;
  float u_select = sampler.get_1d();
  Vec2 u_pos = sampler.get_2d(), u_dir = sampler.get_2d();
  EmissionSample es;
  if (!ctx.lights.sample_emission(u_select, u_pos, u_dir, es)) return;

  // The light vertex itself, seen by the camera (emitters visible in the image).
  Vec2 u_lens = sampler.get_2d();
  SurfaceHit light_vertex;
  light_vertex.p = es.p, light_vertex.p_error = es.p_error, light_vertex.ng = es.n;
  light_vertex.ns = es.n;
  if (es.is_area) {
    CameraConnection c;
    if (camera.connect(es.p, u_lens, c)) {
      RGB le = LightSet::emitted(ctx.scene.meshes[es.mesh], es.n, c.wi);
      if (!is_black(le)) {
        ++counters.rays;
        if (ctx.accel.visible(light_vertex, c.p_lens, Vec3(0.0f), c.wi))
          splat(target, c.raster,
                le * (std::fabs(dot(es.n, c.wi)) * c.importance / (es.pdf_pos * c.pdf_solid_angle)));
      }
    }
  }

  RGB beta = es.beta;
  const float beta_start = max_component(es.beta);
  Ray ray = es.is_area ? ctx.accel.spawn(light_vertex, es.dir) : Ray{es.p, es.dir, kInf};
  for (int depth = 1; depth <= s.max_depth; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) break;
    Vec3 wo = -ray.d;
    Bsdf bsdf = bsdf_at(ctx, hit, 0.0f);
    Vec3 ns = bsdf.shading_normal();

    // Connect this vertex to the camera: a path of `depth` scattering events.
    Vec2 u_cam = sampler.get_2d();
    CameraConnection c;
    if (!bsdf.is_delta() && camera.connect(hit.p, u_cam, c)) {
      RGB f = bsdf.eval(wo, c.wi, TransportMode::Importance);
      if (!is_black(f)) {
        ++counters.rays;
        if (ctx.accel.visible(hit, c.p_lens, Vec3(0.0f), c.wi)) {
          float k = std::fabs(dot(c.wi, ns)) * shading_correction(wo, c.wi, ns, hit.ng) *
                    c.importance / c.pdf_solid_angle;
          splat(target, c.raster, beta * f * k);
        }
      }
    }
    if (depth == s.max_depth) break;

    float uc = sampler.get_1d();
    Vec2 u = sampler.get_2d();
    BsdfSample bs;
    if (!bsdf.sample(wo, uc, u, TransportMode::Importance, bs)) break;
    beta *= bs.f * (std::fabs(dot(bs.wi, ns)) * shading_correction(wo, bs.wi, ns, hit.ng) /
                    bs.pdf_solid_angle);
    ray = ctx.accel.spawn(hit, bs.wi);
    float u_rr = sampler.get_1d();
    if (depth >= s.rr_min_depth) {
      float survive = std::min(1.0f, max_component(beta) / beta_start);
      if (u_rr >= survive) break;
      beta = beta / survive;
    }
  }
}

}  // namespace rf
