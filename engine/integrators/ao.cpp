// Ambient occlusion (`ao`).
//
// Estimator: at the first surface a camera ray hits, AO(x) = (1/pi) * integral over the
// hemisphere about the shading normal (turned towards the camera) of V(x, w) cos(theta) dw, where
// V = 1 unless the ray x + t w hits something with t < max_distance. With cosine-weighted sampling
// each occlusion ray contributes exactly V (variance V(1-V)); with uniform hemisphere sampling it
// contributes 2 V cos(theta), unbiased but noisier. The pixel value is AO in all three channels.
// Parameters: max_distance (infinity by default), sampling ("cosine" or "uniform"), samples (rays
// per camera sample).
// Strengths: cheap, noise-friendly shape cue, needs no lights or materials.
// Cannot do: it is not light transport: no lights, no materials, no interreflection; a closed
// room is black without a max distance. A camera ray that misses everything gives 0.
#include "engine/integrator.h"

namespace rf {

RGB ao_radiance(const RenderContext& ctx, Ray ray, Sampler& sampler, TraceCounters& counters) {
  const IntegratorSettings& s = ctx.scene.render.integrator;
  SurfaceHit hit;
  ++counters.rays;
  if (!ctx.accel.intersect(ray, hit)) return RGB(0.0f);
  // The hemisphere on the camera's side of the surface (the geometric side decides; the
  // shading normal orients the cosine, flipped to agree with it).
  Vec3 ng = dot(hit.ng, ray.d) < 0 ? hit.ng : -hit.ng;
  Vec3 ns = dot(hit.ns, ng) < 0 ? -hit.ns : hit.ns;
  Frame frame = Frame::from_normal(ns);
  double sum = 0;
  for (int k = 0; k < s.ao_samples; ++k) {
    Vec2 u = sampler.get_2d();
    Vec3 local;
    float weight;
    if (s.ao_cosine) {
      local = sample_cosine_hemisphere(u);
      weight = 1.0f;
    } else {
      float z = u.x, r = safe_sqrt(1.0f - z * z), phi = 2 * kPi * u.y;
      local = {r * std::cos(phi), r * std::sin(phi), z};
      weight = 2.0f * z;  // (cos / pi) / (1 / 2 pi)
    }
    Vec3 w = frame.to_world(local);
    if (dot(w, ng) <= 0) continue;  // below the geometric surface: occluded by the surface itself
    Ray r = ctx.accel.spawn(hit, w);
    ++counters.rays;
    if (!ctx.accel.occluded(r.o, r.d, s.ao_max_distance)) sum += weight;
  }
  return RGB(float(sum / s.ao_samples));
}

}  // namespace rf
