// The one subpath tracer of the integrators that start paths on the lights: light tracing (a
// camera connection at every vertex), BDPT (its light subpaths, and its camera subpaths too), and
// the per-pass light paths of instant radiosity (virtual point lights) and photon mapping
// (photons). What a consumer does at a vertex is its visitor; how the path scatters, is weighted
// and ends is here, once.
//
// Random numbers, per surface vertex: whatever the visitor draws at the vertex, then the BSDF
// sample (1D + 2D) and the Russian-roulette number (1D), drawn before the BSDF is sampled so a
// vertex always uses the same dimensions.
#pragma once

#include <algorithm>
#include <cmath>
#include <vector>

#include "engine/frame.h"
#include "engine/integrators/common.h"
#include "engine/integrators/drivers.h"
#include "engine/integrators/sample_layout.h"

namespace rf {

// The adjoint BSDF with shading normals (Veach 1997, eq. 5.19): importance arriving from wo and
// leaving towards wi is weighted by |wo.ns| |wi.ng| / (|wo.ng| |wi.ns|).
inline float shading_correction(Vec3 wo, Vec3 wi, Vec3 ns, Vec3 ng) {
  float den = std::fabs(dot(wo, ng)) * std::fabs(dot(wi, ns));
  return den > 0 ? std::fabs(dot(wo, ns)) * std::fabs(dot(wi, ng)) / den : 0.0f;
}

// A surface vertex as the tracer hands it to its visitor, before the vertex scatters.
struct PathVertex {
  const SurfaceHit& hit;
  const Bsdf& bsdf;
  Vec3 wo;    // unit, towards the previous vertex
  RGB beta;   // throughput arriving at the vertex
  int depth;  // scattering events up to and including this vertex (the first hit is 1)
};

// Follows a subpath from `ray` with throughput `beta` through at most `max_depth` surface
// vertices, calling on the visitor:
//   vertex(const PathVertex&)                     at every surface vertex (delta ones included);
//   scattered(const PathVertex&, const BsdfSample&)  after the vertex's BSDF was sampled;
//   escaped(Vec3 direction, RGB beta)             when the path leaves the scene.
// Mode is the quantity carried: Importance for paths from the lights (the adjoint BSDF with its
// shading-normal correction), Radiance for camera subpaths (texture footprints grow with the ray
// cone; refraction's radiance scaling is undone for Russian roulette). Russian roulette from
// rr_min_depth on, on the throughput relative to its start (pbrt-v4's rule).
template <TransportMode Mode, class Visitor>
void trace_subpath(const RenderContext& ctx, Sampler& sampler, Ray ray, RGB beta, int max_depth,
                   Visitor& visitor, TraceCounters& counters) {
  const int rr_min_depth = ctx.scene.render.integrator.rr_min_depth;
  const float beta_start = max_component(beta);
  float eta_scale = 1, cone_width = 0;
  for (int depth = 1; depth <= max_depth; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) {
      visitor.escaped(ray.d, beta);
      return;
    }
    if constexpr (Mode == TransportMode::Radiance) cone_width += ctx.pixel_spread * hit.t;
    const Bsdf bsdf = bsdf_at(ctx, hit, cone_width);
    const PathVertex v{hit, bsdf, -ray.d, beta, depth};
    visitor.vertex(v);
    if (depth == max_depth) return;

    float uc = sampler.get_1d();
    Vec2 u = sampler.get_2d();
    float u_rr = sampler.get_1d();
    BsdfSample bs;
    if (!bsdf.sample(v.wo, uc, u, Mode, bs)) return;
    visitor.scattered(v, bs);
    const Vec3 ns = bsdf.shading_normal();
    if constexpr (Mode == TransportMode::Importance) {
      beta *= bs.f * (std::fabs(dot(bs.wi, ns)) * shading_correction(v.wo, bs.wi, ns, hit.ng) /
                      bs.pdf_solid_angle);
    } else {
      beta *= bs.f * (std::fabs(dot(bs.wi, ns)) / bs.pdf_solid_angle);
      if (bs.is_transmission) eta_scale *= sqr(bs.eta);
    }
    if (is_black(beta) || !is_finite(beta)) return;
    ray = ctx.accel.spawn(hit, bs.wi);
    if (depth >= rr_min_depth) {
      float survive = std::min(1.0f, max_component(beta * eta_scale) / beta_start);
      if (u_rr >= survive) return;
      beta = beta / survive;
    }
  }
}

// The emission that starts a light path: a light chosen by power, a point on it and a direction
// (three numbers from the sampler). False when no light can emit. With `infinite_lights`,
// directional and environment lights start paths from a disk outside the scene
// (LightSet::sample_emission); without (BDPT), a pick of one is false. `time`: the light path's
// (a moving emitter's point is taken where it is then).
inline bool sample_light_path_start(const RenderContext& ctx, Sampler& sampler, EmissionSample& es,
                                    bool infinite_lights, float time) {
  sampler.skip_1d();  // the light is picked by u_pos.x (LightSelection::select)
  Vec2 u_pos = sampler.get_2d(), u_dir = sampler.get_2d();
  return ctx.lights.sample_emission(u_pos, u_dir, es, infinite_lights, ctx.at(time));
}

// A light path's time (Ray::time): in a scene where something moves, a number from the path's
// own hashed stream (kTimeStream, as a camera sample's), else 0; its every ray and connection is
// made at that time.
inline float light_path_time(const RenderContext& ctx, Sampler& sampler) {
  return ctx.moves ? sampler.get_1d_stream(kTimeStream) : 0.0f;
}

// The emission point as a surface point at `time`, for the rays that leave it.
inline SurfaceHit emission_point(const EmissionSample& es, float time) {
  SurfaceHit at;
  at.p = es.p, at.p_error = es.p_error, at.ng = es.n, at.ns = es.n, at.time = time;
  return at;
}

// The first ray of a light path leaving its emission point at `time`.
inline Ray light_path_ray(const RenderContext& ctx, const EmissionSample& es, float time) {
  if (!es.is_area) return Ray{es.p, es.dir, kInf, time};
  return ctx.accel.spawn(emission_point(es, time), es.dir);
}

// Traces light paths 0..paths-1 of (frame, pass), trace_one(sampler, out, counters) each, in
// fixed chunks traced in parallel and concatenated in chunk order: the per-pass state of instant
// radiosity and photon mapping, bit-identical whatever the thread count.
template <class T, class TraceOne>
std::vector<T> trace_light_paths(const RenderContext& ctx, FrameNumber frame, uint32_t pass,
                                 uint64_t paths, TraceOne&& trace_one, TraceCounters& counters) {
  constexpr uint64_t kChunk = 256;
  std::vector<T> all;
  std::atomic<uint64_t> rays{0};
  for_chunks_in_order<std::vector<T>>(
      (paths + kChunk - 1) / kChunk, true,
      [&](uint64_t chunk, std::vector<T>& out) {
        out.clear();
        TraceCounters local;
        Sampler sampler(Sampler::Kind::Independent);  // light paths: independent (sampler.h)
        for (uint64_t i = chunk * kChunk; i < std::min(paths, (chunk + 1) * kChunk); ++i) {
          sampler.start_light_path(ctx.scene.render.seed, frame, pass, i);
          trace_one(sampler, out, local);
        }
        rays += local.rays;
      },
      [&](const std::vector<T>& out) { all.insert(all.end(), out.begin(), out.end()); },
      /*one_wave=*/true);
  counters.rays += rays;
  return all;
}

}  // namespace rf
