// The `ppm` integrator: see ppm.h.
#include "engine/integrators/ppm.h"

#include <algorithm>
#include <cstdio>

#include "engine/integrators/camera_path.h"
#include "engine/integrators/drivers.h"
#include "engine/integrators/light_path.h"
#include "engine/integrators/photon_grid.h"
#include "engine/json_reader.h"

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

struct PhotonMap {
  PointHashGrid<Photon> grid;
  float inv_area = 0;  // 1 / (pi r^2)
};

// Stores a photon at every non-delta vertex after the first (direct light is not taken from
// photons).
struct PhotonDeposit {
  std::vector<Photon>& out;
  float inv_paths;
  void vertex(const PathVertex& v) {
    if (!v.bsdf.is_delta() && v.depth >= 2)
      out.push_back(Photon{v.hit.p, v.wo, v.beta * inv_paths, v.depth});
  }
  void scattered(const PathVertex&, const BsdfSample&) {}
  void escaped(Vec3, RGB) {}
};

// The photons of one pass: `photons` paths keyed by (seed, frame, pass, path index), in a grid of
// the pass's radius.
std::shared_ptr<const PhotonMap> build_photon_map(const PpmIntegrator& s, const RenderContext& ctx,
                                                  FrameNumber frame, uint32_t pass,
                                                  TraceCounters& counters) {
  const uint64_t paths = uint64_t(std::max(1, s.photons));
  const float inv_paths = 1.0f / float(paths);
  const int max_depth = ctx.scene.render.integrator.max_depth;
  auto trace_one = [&](Sampler& sampler, std::vector<Photon>& out, TraceCounters& c) {
    EmissionSample es;
    if (!sample_light_path_start(ctx, sampler, es, /*infinite_lights=*/true, /*time=*/0.0f)) return;
    PhotonDeposit deposit{out, inv_paths};
    trace_subpath<TransportMode::Importance>(ctx, sampler, light_path_ray(ctx, es, 0.0f),
                                             es.beta,  // still geometry: kMovingGeometry
                                             max_depth, deposit, c);
  };
  std::vector<Photon> photons =
      trace_light_paths<Photon>(ctx, frame, pass, paths, trace_one, counters);
  float r1 = s.radius > 0 ? s.radius : 0.02f * ctx.lights.scene_radius();
  float r = float(double(r1) * radius_scale(pass + 1, double(s.alpha)));
  auto map = std::make_shared<PhotonMap>();
  map->grid.build(std::move(photons), r);
  map->inv_area = 1.0f / (kPi * r * r);
  return map;
}

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

RGB ppm_radiance(const RenderContext& ctx, const PhotonMap& map, Ray ray, Sampler& sampler,
                 TraceCounters& counters) {
  const IntegratorSettings& s = ctx.scene.render.integrator;
  RGB radiance(0.0f);
  CameraPath path(ray.o);
  for (int depth = 0;; ++depth) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) {
      path.escape(ctx, ray.d, radiance);
      break;
    }
    Vec3 wo = -ray.d;
    path.arrive(ctx, hit, wo, radiance);
    // A non-delta BSDF sample only looks for emission: the photons stand for the rest.
    if (!path.prev_delta || depth == s.max_depth) break;

    Bsdf bsdf = bsdf_at(ctx, hit, path.cone_width);
    float u_light = sampler.get_1d();
    Vec2 u_point = sampler.get_2d();
    if (!bsdf.is_delta())
      radiance += path.beta * (light_sample_mis(ctx, hit, bsdf, wo, u_light, u_point, counters) +
                               gather_photons(ctx, map, hit, bsdf, wo, depth));

    BsdfSample bs;
    float uc = sampler.get_1d();
    Vec2 u = sampler.get_2d();
    if (!bsdf.sample(wo, uc, u, TransportMode::Radiance, bs)) break;
    ray = path.scatter(ctx, hit, bsdf, wo, bs);

    float u_rr = sampler.get_1d();
    if (bs.is_delta && depth + 1 >= s.rr_min_depth && !path.survives_roulette(u_rr)) break;
  }
  return radiance;
}

}  // namespace

SampleBuffer PpmIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                   bool parallel) const {
  return render_camera_paths_with_pass_state<PhotonMap>(
      ctx, task, parallel,
      [&](TraceCounters& c) { return build_photon_map(*this, ctx, task.frame, task.pass, c); },
      [&](const PhotonMap& photons, Ray ray, Sampler& sampler, TraceCounters& c) {
        return ppm_radiance(ctx, photons, ray, sampler, c);
      });
}

}  // namespace rf
