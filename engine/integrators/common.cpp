// Pieces every integrator shares (common.h): material resolution at a hit, shadow tests,
// next-event estimation.
#include "engine/integrators/common.h"

namespace rf {

LaneKind lane_kind(const Material& m) {
  const bool constant =
      m.reflectance.texture < 0 && m.specular.texture < 0 && m.roughness.texture < 0;
  if (constant && m.type == MaterialType::Diffuse) return LaneKind::Diffuse;
  if (constant && m.type == MaterialType::RoughConductor &&
      !TrowbridgeReitz::effectively_smooth(m.roughness.value))
    return LaneKind::RoughConductor;
  return LaneKind::OneByOne;
}

// The footprint is a ray-cone estimate: the cone's width at the hit, converted to uv units by the
// triangle's uv-to-world area ratio.
BsdfParams material_params_at(const RenderContext& ctx, const SurfaceHit& hit, float cone_width) {
  const Material& m = ctx.scene.materials[ctx.accel.mesh(hit.mesh).material];
  BsdfParams p = constant_params(m);
  if (m.reflectance.texture < 0 && m.specular.texture < 0 && m.roughness.texture < 0) return p;
  const Mesh& mesh = ctx.accel.mesh(hit.mesh);
  float footprint = 0;
  if (!mesh.uvs.empty()) {
    const uint32_t* t = &mesh.indices[3 * hit.prim];
    Vec3 p0 = mesh.positions[t[0]], p1 = mesh.positions[t[1]], p2 = mesh.positions[t[2]];
    Vec2 a = mesh.uvs[t[0]], b = mesh.uvs[t[1]], c = mesh.uvs[t[2]];
    float world_area = length(cross(p1 - p0, p2 - p0));
    float uv_area = std::fabs((b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y));
    if (world_area > 0) footprint = cone_width * std::sqrt(uv_area / world_area);
  }
  p.reflectance = ctx.textures.eval(m.reflectance, hit.uv, footprint);
  p.specular = ctx.textures.eval(m.specular, hit.uv, footprint);
  p.alpha = ctx.textures.eval(m.roughness, hit.uv, footprint);
  return p;
}

Bsdf bsdf_at(const RenderContext& ctx, const SurfaceHit& hit, float cone_width) {
  return Bsdf::make(material_params_at(ctx, hit, cone_width), hit.ns, hit.ng);
}

void add_escaped(const RenderContext& ctx, Vec3 dir, bool prev_delta, float prev_bsdf_pdf, RGB beta,
                 RGB& radiance) {
  if (!ctx.lights.has_environment()) return;
  RGB le = ctx.lights.environment_radiance(dir);
  float w = prev_delta ? 1.0f : power_heuristic(prev_bsdf_pdf, ctx.lights.pdf_environment(dir));
  radiance += beta * le * w;
}

Ray light_shadow_ray(const RenderContext& ctx, const SurfaceHit& hit, const LightSample& ls) {
  if (ls.is_infinite) return ctx.accel.spawn(hit, ls.wi);
  return ctx.accel.shadow_ray(hit, ls.p, ls.p_error, ls.n);
}

bool light_visible(const RenderContext& ctx, const SurfaceHit& hit, const LightSample& ls) {
  Ray r = light_shadow_ray(ctx, hit, ls);
  return !ctx.accel.occluded(r);
}

bool light_sample_mis_unshadowed(const RenderContext& ctx, const SurfaceHit& hit, const Bsdf& bsdf,
                                 Vec3 wo, float u_light, Vec2 u_point, RGB& contribution,
                                 Ray& shadow, bool mis) {
  contribution = RGB(0.0f);
  LightSample ls;
  if (!ctx.lights.sample(hit.p, receiver_normal(bsdf, wo), u_light, u_point, ls, ctx.at(hit.time)))
    return false;
  float bsdf_pdf;
  RGB f = bsdf.eval_pdf(wo, ls.wi, bsdf_pdf);
  if (is_black(f)) return false;
  shadow = light_shadow_ray(ctx, hit, ls);
  float w = ls.is_delta || !mis ? 1.0f : power_heuristic(ls.pdf_solid_angle, bsdf_pdf);
  float cos_i = std::fabs(dot(ls.wi, bsdf.shading_normal()));
  contribution = f * ls.radiance * (cos_i * w / ls.pdf_solid_angle);
  return true;
}

RGB light_sample_mis(const RenderContext& ctx, const SurfaceHit& hit, const Bsdf& bsdf, Vec3 wo,
                     float u_light, Vec2 u_point, TraceCounters& counters) {
  RGB c;
  Ray shadow;
  if (!light_sample_mis_unshadowed(ctx, hit, bsdf, wo, u_light, u_point, c, shadow))
    return RGB(0.0f);
  ++counters.rays;
  return ctx.accel.occluded(shadow) ? RGB(0.0f) : c;
}
}  // namespace rf
