// The `ao` integrator: see ao.h.
#include "engine/integrators/ao.h"

#include <cstdio>

#include "engine/integrators/drivers.h"
#include "engine/json_reader.h"

namespace rf {

RGB AoIntegrator::radiance(const RenderContext& ctx, Ray ray, Sampler& sampler,
                          TraceCounters& counters) const {
  const AoIntegrator& s = *this;
  SurfaceHit hit;
  ++counters.rays;
  if (!ctx.accel.intersect(ray, hit)) return RGB(0.0f);
  // The hemisphere on the camera's side of the surface (the geometric side decides; the
  // shading normal orients the cosine, flipped to agree with it).
  Vec3 ng = dot(hit.ng, ray.d) < 0 ? hit.ng : -hit.ng;
  Vec3 ns = dot(hit.ns, ng) < 0 ? -hit.ns : hit.ns;
  Frame frame = Frame::from_normal(ns);
  double sum = 0;
  for (int k = 0; k < s.samples; ++k) {
    Vec2 u = sampler.get_2d();
    Vec3 local;
    float weight;
    if (s.cosine) {
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
    if (!ctx.accel.occluded(r.o, r.d, s.max_distance)) sum += weight;
  }
  return RGB(float(sum / s.samples));
}

void AoIntegrator::parse(const JsonReader& r, const Json& j, const std::string& p) {
  if (const Json* v = r.find(j, "max_distance")) {
    max_distance = r.number(*v, p + ".max_distance");
    if (!(max_distance > 0)) r.fail(p + ".max_distance", "must be > 0, got " + v->dump());
  }
  if (const Json* v = r.find(j, "sampling")) {
    std::string s = r.string(*v, p + ".sampling");
    if (s != "cosine" && s != "uniform")
      r.fail(p + ".sampling", "expected \"cosine\" or \"uniform\", got '" + s + "'");
    cosine = s == "cosine";
  }
  if (const Json* v = r.find(j, "samples")) samples = int(r.integer(*v, p + ".samples", 1, 1 << 16));
}

std::string AoIntegrator::settings_text() const {
  char buf[128];
  std::snprintf(buf, sizeof buf, ";ao=%g:%s:%d", double(max_distance),
                cosine ? "cosine" : "uniform", samples);
  return buf;
}

SampleBuffer AoIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                  bool parallel) const {
  return render_camera_paths<false>(ctx, task, parallel,
                                    [&](Ray ray, Sampler& sampler, TraceCounters& counters) {
                                      return radiance(ctx, ray, sampler, counters);
                                    });
}

}  // namespace rf
