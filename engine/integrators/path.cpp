// The `path` integrator: see path.h.
#include "engine/integrators/path.h"

#include "engine/integrators/drivers.h"

namespace rf {

namespace {

// The one-lane stand-in for Accel::RayPacket: Embree's single-ray queries, for groups of one
// sample (a pass of one sample per pixel), where a 16-wide packet would carry one live lane.
struct SingleRay {
  Ray r;
  bool on = false;
  void set(int, const Ray& ray) { r = ray, on = true; }
  void clear(int) { on = false; }
  bool active(int) const { return on; }
  Ray ray(int) const { return r; }
};
void intersect(const Accel& accel, Accel::RayPacket& p, int n, SurfaceHit* hits, bool* found) {
  accel.intersect_packet(p, n, hits, found);
}
void intersect(const Accel& accel, SingleRay& p, int, SurfaceHit* hits, bool* found) {
  found[0] = accel.intersect(p.r, hits[0]);
}
void occluded(const Accel& accel, Accel::RayPacket& p, int n, bool* blocked) {
  accel.occluded_packet(p, n, blocked);
}
void occluded(const Accel& accel, SingleRay& p, int, bool* blocked) {
  blocked[0] = accel.occluded(p.r.o, p.r.d, p.r.tmax);
}

// The path estimator for n <= K camera samples of one pixel, traced in lockstep: at every depth
// the live lanes' rays are cast together (one packet query), each lane is shaded, then the lanes'
// shadow rays are cast together. A lane's numbers are drawn in the same order whatever the other
// lanes do (light sample, BSDF sample, roulette; its shadow test is known only after all three),
// and its NEE term is added after the test and before its next vertex, so each lane's radiance is
// the one it would get traced alone: bit-identical with K = 1 (tests/integrators_test.cpp).
// Every vertex consumes the same dimensions whether or not it reads them (skipped ones cost
// nothing), so a material change does not reshuffle the random numbers of later bounces.
template <int K, class Packet>
void trace_paths(const RenderContext& ctx, const Ray* camera_rays, Sampler* samplers, int n,
                 RGB* radiance, TraceCounters& counters) {
  const IntegratorSettings& settings = ctx.scene.render.integrator;
  struct Lane {
    RGB beta{1.0f};
    float eta_scale = 1, prev_bsdf_pdf = 0;
    float cone_width = 0;       // ray-cone width at the current hit, for texture filtering
    bool prev_delta = true;     // the camera ray counts as "specular": emission taken unweighted
    Vec3 prev_p, prev_n{0.0f};  // the last vertex and its receiver normal (light selection)
    RGB nee_beta{0.0f}, nee{0.0f};  // the pending NEE term: beta at the vertex, f Le cos w / pdf
  };
  Lane lanes[K];
  Packet rays, shadow;
  SurfaceHit hits[K];
  bool found[K], nee_done[K], blocked[K] = {};
  // With a Sobol sampler the lanes that shade a vertex draw its numbers together, in the order one
  // lane draws them (Sampler::get_lanes): all of them, read or not, where one lane alone skips
  // the unread ones; a skip and a draw consume the same dimension, so the values are the same.
  static_assert(K <= Sampler::kMaxLanes);
  const bool lockstep_draws = K > 1 && samplers[0].kind() != Sampler::Kind::Independent;
  // A vertex's draws: light choice, light point, lobe choice, direction, roulette (or its skip).
  enum { kULight, kUPoint, kUChoice, kUDir, kURoulette, kVertexDraws };
  int shading[K];
  Sampler::LaneDraws u[kVertexDraws];
  int live = n;
  for (int i = 0; i < n; ++i) {
    rays.set(i, camera_rays[i]);
    lanes[i].prev_p = camera_rays[i].o;
    radiance[i] = RGB(0.0f);
  }
  for (int depth = 0; live > 0; ++depth) {
    counters.rays += uint64_t(live);
    intersect(ctx.accel, rays, n, hits, found);
    const bool roulette = depth + 1 >= settings.rr_min_depth;
    if (lockstep_draws && depth < settings.max_depth) {
      int m = 0;
      for (int i = 0; i < n; ++i)
        if (rays.active(i) && found[i]) shading[m++] = i;
      const uint8_t draws[kVertexDraws] = {1, 2, 1, 2, uint8_t(roulette ? 1 : 0)};
      Sampler::get_lanes(samplers, shading, m, draws, kVertexDraws, u);
    }
    bool any_shadow = false;
    for (int i = 0; i < n; ++i) {
      nee_done[i] = false;
      shadow.clear(i);
      if (!rays.active(i)) continue;
      Lane& a = lanes[i];
      const SurfaceHit& hit = hits[i];
      Sampler& sampler = samplers[i];
      const Vec3 wo = -rays.ray(i).d;
      auto end = [&] { rays.clear(i), --live; };
      if (!found[i]) {
        add_escaped(ctx, -wo, a.prev_delta, a.prev_bsdf_pdf, a.beta, radiance[i]);
        end();
        continue;
      }
      const Mesh& mesh = ctx.accel.mesh(hit.mesh);
      a.cone_width += ctx.pixel_spread * hit.t;
      RGB le = LightSet::emitted(mesh, hit.ng, wo);
      if (!is_black(le)) {
        if (a.prev_delta) {
          radiance[i] += a.beta * le;
        } else {
          float light_pdf =
              ctx.lights.pdf_solid_angle(a.prev_p, a.prev_n, hit.mesh, hit.prim, hit.p, hit.ng);
          radiance[i] += a.beta * le * power_heuristic(a.prev_bsdf_pdf, light_pdf);
        }
      }
      if (depth == settings.max_depth) {
        end();
        continue;
      }
      Bsdf bsdf = bsdf_at(ctx, hit, a.cone_width);
      const bool nee = !bsdf.is_delta();
      float u_light = lockstep_draws ? u[kULight][0][i] : sampler.get_1d_if(nee);
      Vec2 u_point =
          lockstep_draws ? Vec2{u[kUPoint][0][i], u[kUPoint][1][i]} : sampler.get_2d_if(nee);
      if (nee) {
        nee_done[i] = true;
        a.nee_beta = a.beta;
        Ray r;
        if (light_sample_mis_unshadowed(ctx, hit, bsdf, wo, u_light, u_point, a.nee, r)) {
          shadow.set(i, r);
          any_shadow = true;
          ++counters.rays;
        }
      }
      BsdfSample bs;
      float uc = lockstep_draws ? u[kUChoice][0][i] : sampler.get_1d_if(bsdf.sample_uses_choice());
      Vec2 u_dir = lockstep_draws ? Vec2{u[kUDir][0][i], u[kUDir][1][i]}
                                  : sampler.get_2d_if(bsdf.sample_uses_direction());
      if (!bsdf.sample(wo, uc, u_dir, TransportMode::Radiance, bs)) {
        end();
        continue;
      }
      float cos_i = std::fabs(dot(bs.wi, bsdf.shading_normal()));
      a.beta *= bs.f * (cos_i / bs.pdf_solid_angle);
      if (bs.is_transmission) a.eta_scale *= sqr(bs.eta);
      a.prev_bsdf_pdf = bs.pdf_solid_angle;
      a.prev_delta = bs.is_delta;
      a.prev_p = hit.p;
      a.prev_n = receiver_normal(bsdf, wo);
      rays.set(i, ctx.accel.spawn(hit, bs.wi));
      float u_rr = lockstep_draws ? u[kURoulette][0][i] : sampler.get_1d_if(roulette);
      if (roulette) {
        float survive = std::min(1.0f, max_component(a.beta * a.eta_scale));
        if (u_rr >= survive) {
          end();
          continue;
        }
        a.beta = a.beta / survive;
      }
    }
    if (any_shadow) occluded(ctx.accel, shadow, n, blocked);
    for (int i = 0; i < n; ++i)
      if (nee_done[i])  // beta * (term or 0) at every NEE vertex, occluded or not, as K = 1 adds
        radiance[i] +=
            lanes[i].nee_beta * (shadow.active(i) && !blocked[i] ? lanes[i].nee : RGB(0.0f));
  }
}

}  // namespace

void path_radiance(const RenderContext& ctx, const Ray* rays, Sampler* samplers, int n,
                   RGB* radiance, TraceCounters& counters, bool packets) {
  if (packets && n > 1)
    trace_paths<Accel::kPacket, Accel::RayPacket>(ctx, rays, samplers, n, radiance, counters);
  else
    for (int i = 0; i < n; ++i)
      trace_paths<1, SingleRay>(ctx, rays + i, samplers + i, 1, radiance + i, counters);
}

SampleBuffer PathIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                    bool parallel) const {
  return render_camera_paths<false>(
      ctx, task, parallel,
      [&](const Ray* rays, Sampler* samplers, int n, RGB* radiance, TraceCounters& counters) {
        path_radiance(ctx, rays, samplers, n, radiance, counters);
      });
}

}  // namespace rf
