// Light sub-paths for the integrators that precompute per pass (ir's virtual point lights,
// ppm's photons): one light path traced with importance-mode BSDFs, and the deterministic,
// chunked parallel loop that traces a pass's paths.
//
// Path index i of pass p draws its numbers from Sampler::start_light_path(seed, frame, p, i), and
// paths are traced in fixed chunks whose outputs are concatenated in chunk order, so the result is
// bit-identical whatever the thread count (DESIGN.md, the determinism contract).
#pragma once

#include <tbb/parallel_for.h>

#include <algorithm>
#include <vector>

#include "engine/integrator.h"

namespace rf::light_subpaths {

// The adjoint BSDF with shading normals, as in light.cpp (Veach 1997, eq. 5.19): importance
// arriving from wo and leaving towards wi is weighted by |wo.ns| |wi.ng| / (|wo.ng| |wi.ns|).
inline float shading_correction(Vec3 wo, Vec3 wi, Vec3 ns, Vec3 ng) {
  float den = std::fabs(dot(wo, ng)) * std::fabs(dot(wi, ns));
  return den > 0 ? std::fabs(dot(wo, ns)) * std::fabs(dot(wi, ng)) / den : 0.0f;
}

// What a light path hands to its consumer at a surface vertex with a non-delta BSDF.
struct Vertex {
  const SurfaceHit& hit;
  const Bsdf& bsdf;
  Vec3 wo;    // unit, towards the previous light-path vertex (where the light comes from)
  RGB beta;   // throughput arriving at the vertex (area measure at the vertex), before it scatters
  int depth;  // scattering events up to and including this vertex (the first hit is 1)
};

// Traces one light path (light chosen by power, a point, a direction) with `sampler` already
// started for it, and calls deposit(const Vertex&) at every non-delta surface vertex of depth
// 1..max_vertex_depth. Russian roulette as light.cpp: after rr_min_depth, on the throughput
// relative to its start.
template <class Deposit>
void trace(const RenderContext& ctx, Sampler& sampler, int max_vertex_depth, Deposit&& deposit,
           TraceCounters& counters) {
  const IntegratorSettings& s = ctx.scene.render.integrator;
  float u_select = sampler.get_1d();
  Vec2 u_pos = sampler.get_2d(), u_dir = sampler.get_2d();
  EmissionSample es;
  if (max_vertex_depth < 1 || !ctx.lights.sample_emission(u_select, u_pos, u_dir, es)) return;
  SurfaceHit light_vertex;
  light_vertex.p = es.p, light_vertex.p_error = es.p_error, light_vertex.ng = es.n;
  light_vertex.ns = es.n;
  RGB beta = es.beta;
  const float beta_start = max_component(es.beta);
  if (!(beta_start > 0)) return;
  Ray ray = es.is_area ? ctx.accel.spawn(light_vertex, es.dir) : Ray{es.p, es.dir, kInf};
  for (int depth = 1;; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) return;
    Vec3 wo = -ray.d;
    Bsdf bsdf = bsdf_at(ctx, hit, 0.0f);
    if (!bsdf.is_delta()) deposit(Vertex{hit, bsdf, wo, beta, depth});
    if (depth >= max_vertex_depth) return;

    float uc = sampler.get_1d();
    Vec2 u = sampler.get_2d();
    BsdfSample bs;
    if (!bsdf.sample(wo, uc, u, TransportMode::Importance, bs)) return;
    Vec3 ns = bsdf.shading_normal();
    beta *= bs.f * (std::fabs(dot(bs.wi, ns)) * shading_correction(wo, bs.wi, ns, hit.ng) /
                    bs.pdf_solid_angle);
    ray = ctx.accel.spawn(hit, bs.wi);
    float u_rr = sampler.get_1d();
    if (depth >= s.rr_min_depth) {
      float survive = std::min(1.0f, max_component(beta) / beta_start);
      if (u_rr >= survive) return;
      beta = beta / survive;
    }
  }
}

// Traces light paths 0..paths-1 of `pass`, trace_one(sampler, out, counters) each, in chunks of
// kChunk paths traced in parallel; returns every chunk's output in chunk order.
template <class T, class TraceOne>
std::vector<T> trace_pass(const RenderContext& ctx, uint32_t pass, uint64_t paths,
                          TraceOne&& trace_one, TraceCounters& counters) {
  constexpr uint64_t kChunk = 256;
  const RenderSettings& rs = ctx.scene.render;
  const size_t chunks = size_t((paths + kChunk - 1) / kChunk);
  std::vector<std::vector<T>> outs(chunks);
  std::vector<uint64_t> rays(chunks, 0);
  tbb::parallel_for(size_t(0), chunks, [&](size_t c) {
    TraceCounters local;
    Sampler sampler(Sampler::Kind::Independent);  // light paths: independent (sampler.h)
    for (uint64_t i = c * kChunk; i < std::min(paths, (c + 1) * kChunk); ++i) {
      sampler.start_light_path(rs.seed, ctx.frame, pass, i);
      trace_one(sampler, outs[c], local);
    }
    rays[c] = local.rays;
  });
  size_t total = 0;
  for (const auto& o : outs) total += o.size();
  std::vector<T> all;
  all.reserve(total);
  for (size_t c = 0; c < chunks; ++c) {
    all.insert(all.end(), outs[c].begin(), outs[c].end());
    counters.rays += rays[c];
  }
  return all;
}

// Instant radiosity and photon mapping start every path on a light with a finite position; they
// refuse environment and directional lights (whose indirect light they would silently drop).
inline void require_finite_lights(const RenderContext& ctx, const char* integrator) {
  bool directional = false;
  for (const Light& l : ctx.scene.lights) directional |= l.type == LightType::Directional;
  if (ctx.scene.environment || directional)
    throw SceneError(ctx.scene.path + ": the " + integrator +
                     " integrator cannot start light paths on " +
                     std::string(ctx.scene.environment ? "an environment" : "a directional light") +
                     " (no finite emission position); use path or bdpt for this scene");
}

}  // namespace rf::light_subpaths
