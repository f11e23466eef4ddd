// The camera-path vertex the camera-path estimators share (path, ir, ppm): the path's state
// between vertices and the steps every vertex takes the same way: the escape into the
// environment, the emission found at a hit (MIS-weighted against light sampling of that point from
// the previous vertex), the continuation by a BSDF sample, and Russian roulette. What an
// estimator does between arriving and scattering (next-event estimation, VPL or photon
// gathering) is its own.
#pragma once

#include <algorithm>
#include <cmath>

#include "engine/integrators/common.h"
#include "engine/lights/light_set.h"

namespace rf {

struct CameraPath {
  RGB beta{1.0f};
  float eta_scale = 1, prev_bsdf_pdf = 0;
  float cone_width = 0;       // ray-cone width at the current hit, for texture filtering
  bool prev_delta = true;     // the camera ray counts as "specular": emission taken unweighted
  Vec3 prev_p, prev_n{0.0f};  // the last vertex and its receiver normal (light selection)

  CameraPath() = default;
  explicit CameraPath(Vec3 camera) : prev_p(camera) {}

  // The ray left the scene along unit dir: the environment's radiance into `radiance`, weighted
  // against light sampling after a non-delta scattering.
  void escape(const RenderContext& ctx, Vec3 dir, RGB& radiance) const {
    add_escaped(ctx, dir, prev_delta, prev_bsdf_pdf, beta, radiance);
  }
  // The ray reached a point at distance t: the ray cone widens.
  void widen_cone(const RenderContext& ctx, float t) { cone_width += ctx.pixel_spread * t; }
  // The emission found at point p (geometric normal ng) of triangle prim of surface `mesh` (the
  // mesh m), seen from direction wo, as the path's term: beta Le, unweighted after the camera or a
  // delta scattering, else weighted by the power heuristic against the light-sampling density of
  // the point from the previous vertex. False when the point sends nothing towards wo.
  bool emission(const RenderContext& ctx, const Mesh& m, uint32_t mesh, uint32_t prim, Vec3 p,
                Vec3 ng, Vec3 wo, float time, RGB& term) const {
    const RGB le = emitted_radiance(m, ng, wo);
    if (is_black(le)) return false;
    if (prev_delta) {
      term = beta * le;
    } else {
      const float light_pdf =
          ctx.lights.pdf_solid_angle(prev_p, prev_n, mesh, prim, p, ng, ctx.at(time));
      term = beta * le * power_heuristic(prev_bsdf_pdf, light_pdf);
    }
    return true;
  }
  // Both at a hit: the cone widens and the emission goes into `radiance`.
  void arrive(const RenderContext& ctx, const SurfaceHit& hit, Vec3 wo, RGB& radiance) {
    widen_cone(ctx, hit.t);
    RGB term;
    if (emission(ctx, ctx.accel.mesh(hit.mesh), hit.mesh, hit.prim, hit.p, hit.ng, wo, hit.time,
                 term))
      radiance += term;
  }
  // The path goes on by the BSDF sample bs taken at hit (outgoing direction wo): the throughput
  // takes f |cos| / pdf, the state remembers the vertex for the next one's MIS weights; returns
  // the spawned ray.
  Ray scatter(const RenderContext& ctx, const SurfaceHit& hit, const Bsdf& bsdf, Vec3 wo,
              const BsdfSample& bs) {
    const float cos_i = std::fabs(dot(bs.wi, bsdf.shading_normal()));
    beta *= bs.f * (cos_i / bs.pdf_solid_angle);
    if (bs.is_transmission) eta_scale *= sqr(bs.eta);
    prev_bsdf_pdf = bs.pdf_solid_angle;
    prev_delta = bs.is_delta;
    prev_p = hit.p;
    prev_n = receiver_normal(bsdf, wo);
    return ctx.accel.spawn(hit, bs.wi);
  }
  // Russian roulette with the number u (pbrt-v4's rule: survival probability min(1, the largest
  // component of beta times the eta scale)): false when the path ends, else beta is divided by
  // the survival probability.
  bool survives_roulette(float u) {
    const float survive = std::min(1.0f, max_component(beta * eta_scale));
    if (u >= survive) return false;
    beta = beta / survive;
    return true;
  }
};

}  // namespace rf
