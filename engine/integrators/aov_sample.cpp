#include "engine/integrators/aov_sample.h"

#include "engine/fresnel.h"

namespace rf {

namespace {

// Reflectance at normal incidence of a conductor: ((eta-1)^2 + k^2) / ((eta+1)^2 + k^2).
RGB conductor_f0(const BsdfParams& p) {
  if (p.conductor_tint) return p.specular;
  RGB f;
  for (int c = 0; c < 3; ++c)
    f[c] = (sqr(p.eta[c] - 1) + sqr(p.k[c])) / (sqr(p.eta[c] + 1) + sqr(p.k[c]));
  return f * p.specular;
}

}  // namespace

RGB aov_albedo(const BsdfParams& p) {
  switch (p.type) {
    case MaterialType::Diffuse:
    case MaterialType::Plastic:
      return p.reflectance;
    case MaterialType::Conductor:
    case MaterialType::RoughConductor:
      return conductor_f0(p);
    case MaterialType::Dielectric:
    case MaterialType::ThinDielectric:
    case MaterialType::RoughDielectric:
      return p.specular;
  }
  return RGB(0.0f);
}

AovSample aov_sample(const RenderContext& ctx, const Ray& camera_ray, TraceCounters& counters) {
  AovSample a;
  RGB tint(1.0f);
  Ray ray = camera_ray;
  for (int bounce = 0; bounce <= kMaxSpecularBounces; ++bounce) {
    SurfaceHit hit;
    ++counters.rays;
    if (!ctx.accel.intersect(ray, hit)) return a;
    if (bounce == 0) {
      a.hit = true;
      a.depth = hit.t * length(ray.d);
    }
    BsdfParams p = material_params_at(ctx, hit, 0.0f);
    Bsdf bsdf = Bsdf::make(p, hit.ns, hit.ng);
    Vec3 wo = -normalize(ray.d);
    Vec3 n = bsdf.shading_normal();
    if (!bsdf.is_delta()) {
      a.albedo = tint * aov_albedo(p);
      a.normal = dot(n, wo) < 0 ? -n : n;
      return a;
    }
    Vec3 wi;
    switch (p.type) {
      case MaterialType::ThinDielectric:
        wi = -wo;
        tint = tint * p.specular;
        break;
      case MaterialType::Dielectric:
      case MaterialType::RoughDielectric:  // smooth at this roughness
        // n faces the outside (ng's side); refract() handles rays arriving from inside.
        if (!refract(wo, n, p.ior, nullptr, &wi)) wi = 2 * dot(wo, n) * n - wo;
        tint = tint * p.specular;
        break;
      default: {  // smooth conductors
        Vec3 nf = dot(n, wo) < 0 ? -n : n;
        wi = 2 * dot(wo, nf) * nf - wo;
        tint = tint * conductor_f0(p);
        break;
      }
    }
    ray = ctx.accel.spawn(hit, wi);
  }
  a.albedo = RGB(0.0f);
  a.normal = Vec3(0.0f);
  return a;
}

}  // namespace rf
