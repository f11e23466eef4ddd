// The `light` integrator: see light.h.
#include "engine/integrators/light.h"

#include "engine/integrators/drivers.h"
#include "engine/integrators/light_path.h"

namespace rf {

namespace {

// Connects every vertex of a light path to the camera and splats what arrives.
struct CameraConnector {
  const RenderContext& ctx;
  const PerspectiveCamera& camera;  // at the light path's time (camera_at)
  Sampler& sampler;
  SplatTarget& target;
  TraceCounters& counters;
  float time;  // the light path's (light_path_time)

  // Light from a path of v.depth scattering events, scattered at v towards a lens point (drawn
  // at every vertex, so a material change does not reshuffle later numbers).
  void vertex(const PathVertex& v) {
    Vec2 u_cam = sampler.get_2d();
    CameraConnection c;
    if (v.bsdf.is_delta() || !camera.connect(v.hit.p, u_cam, c)) return;
    RGB f = v.bsdf.eval(v.wo, c.wi, TransportMode::Importance);
    if (is_black(f)) return;
    ++counters.rays;
    if (!ctx.accel.visible(v.hit, c.p_lens, Vec3(0.0f), c.wi)) return;
    Vec3 ns = v.bsdf.shading_normal();
    float k = std::fabs(dot(c.wi, ns)) * shading_correction(v.wo, c.wi, ns, v.hit.ng) *
              c.importance / c.pdf_solid_angle;
    splat_to_film(target, c.raster, v.beta * f * k);
  }
  void scattered(const PathVertex&, const BsdfSample&) {}
  void escaped(Vec3, RGB) {}

  // The emission point itself seen by the camera (emitters visible in the image).
  void emitter(const EmissionSample& es) {
    Vec2 u_lens = sampler.get_2d();
    CameraConnection c;
    if (!es.is_area || !camera.connect(es.p, u_lens, c)) return;
    RGB le = emitted_radiance(ctx.accel.mesh(es.mesh), es.n, c.wi);
    if (is_black(le)) return;
    ++counters.rays;
    if (ctx.accel.visible(emission_point(es, time), c.p_lens, Vec3(0.0f), c.wi))
      splat_to_film(
          target, c.raster,
          le * (std::fabs(dot(es.n, c.wi)) * c.importance / (es.pdf_pos * c.pdf_solid_angle)));
  }
};

}  // namespace

// One pass is spp_per_pass light paths per pixel of the frame, so a pass costs about what a
// camera-path pass costs; light path i of pass p is keyed by (seed, frame, p, i).
SampleBuffer LightIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                     bool parallel) const {
  const uint64_t paths = ctx.scene.render.spp_per_pass() * uint64_t(ctx.scene.film.width) *
                         uint64_t(ctx.scene.film.height);
  const int max_depth = ctx.scene.render.integrator.max_depth;
  return render_light_paths(
      ctx, task, parallel, paths, [&](Sampler& sampler, SplatTarget& target, TraceCounters& c) {
        const float time = light_path_time(ctx, sampler);
        EmissionSample es;
        if (!sample_light_path_start(ctx, sampler, es, /*infinite_lights=*/true, time)) return;
        const PerspectiveCamera camera = camera_at(ctx, task.frame, time);
        CameraConnector connector{ctx, camera, sampler, target, c, time};
        connector.emitter(es);
        trace_subpath<TransportMode::Importance>(ctx, sampler, light_path_ray(ctx, es, time),
                                                 es.beta, max_depth, connector, c);
      });
}

}  // namespace rf
