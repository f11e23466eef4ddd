// Sampling a selected light, kind by kind: see light_sampling.h. LightSet's sampling entry points
// live here too, next to the kinds they dispatch to.
#include "engine/lights/light_sampling.h"

#include <algorithm>
#include <cmath>

#include "engine/lights/light_set.h"

namespace rf {

float smooth_step(float x, float a, float b) {
  if (a == b) return x < a ? 0.0f : 1.0f;
  float t = std::clamp((x - a) / (b - a), 0.0f, 1.0f);
  return t * t * (3.0f - 2.0f * t);
}

bool sphere_cone_of(const AreaLight& light, const Emission& e, Vec3 p, SphereCone& c) {
  if (!light.sphere) return false;
  const SphereShape& s = *light.sphere;
  if (!sphere_cone(s.center, s.radius, p, c.sin2_max, c.cos_max, c.one_minus_cos_max)) return false;
  c.center = s.center, c.pole = s.axis[1], c.radius = s.radius;
  c.emission = e;
  return true;
}

bool sample_area(const AreaLight& light, const Emission& e, Vec3 p, Vec2 u, LightSample& ls) {
  SphereCone c;
  if (sphere_cone_of(light, e, p, c)) {
    float cos_alpha, sin_alpha, cos_phi, sin_phi;
    sphere_cone_angles(c.sin2_max, c.cos_max, u, cos_alpha, sin_alpha, cos_phi, sin_phi);
    return sphere_cone_point(c, p, cos_alpha, sin_alpha, cos_phi, sin_phi, ls);
  }
  if (!light.sphere)
    return sample_triangle_area(light.p0, light.p1, light.p2, light.n, light.area, e, p, u, ls);
  sample_area_surface(light, u, ls.p, ls.p_error, ls.n);  // a sphere seen from inside: uniform
  return area_point_seen_from(p, light.area, e, ls);
}

bool sample_punctual(const PunctualLight& l, float scene_radius, Vec3 p, LightSample& ls) {
  ls.is_delta = true;
  if (l.type == LightType::Directional) {
    ls.is_infinite = true;
    ls.wi = -l.direction;
    ls.distance = 2.0f * scene_radius;
    ls.p = p + ls.wi * ls.distance;
    ls.n = l.direction;
    ls.radiance = l.intensity;
    return true;
  }
  Vec3 d = l.position - p;
  float dist2 = length_sq(d);
  if (!(dist2 > 0)) return false;
  ls.p = l.position;
  ls.distance = std::sqrt(dist2);
  ls.wi = d / ls.distance;
  ls.n = -ls.wi;
  float falloff = 1.0f;
  if (l.type == LightType::Spot)  // pbrt-v4 SpotLight::I: smoothstep in cos from cone to start
    falloff = smooth_step(dot(l.direction, -ls.wi), l.cos_falloff_end, l.cos_falloff_start);
  ls.radiance = l.intensity * (falloff / dist2);
  return falloff > 0;
}

bool LightSet::sample(Vec3 p, Vec3 n, float u_select, Vec2 u_point, LightSample& ls,
                      const LightTime& at) const {
  size_t i;
  float pmf;
  return pick(p, n, u_select, u_point, i, pmf) && sample_selected(i, pmf, p, u_point, ls, at);
}

bool LightSet::sample_by_power(Vec3 p, Vec2 u_point, LightSample& ls, const LightTime& at) const {
  size_t i = selection_.select(u_point.x);
  if (i == LightSelection::kNone) return false;
  return sample_selected(i, selection_.pmf(i), p, u_point, ls, at);
}

bool LightSet::sample_selected(size_t i, float pmf, Vec3 p, Vec2 u_point, LightSample& ls,
                               const LightTime& at) const {
  ls = LightSample{};
  ls.light = uint32_t(i);
  bool ok = false;
  ls.pdf_solid_angle = 1.0f;  // delta lights: the selection probability alone
  if (i < area_.size()) {
    ok = area_[i].moves ? sample_area(area_at(i, at), area_emission(i), p, u_point, ls)
                        : sample_area(area_[i], area_emission(i), p, u_point, ls);
  } else if (i < area_.size() + punctual_.size()) {
    ok = sample_punctual(punctual_[i - area_.size()], radius_, p, ls);
  } else {
    ok = env_->sample(u_point, ls.wi, ls.radiance, ls.pdf_solid_angle);
    ls.is_infinite = true;
    ls.distance = 2.0f * radius_;
    ls.p = p + ls.wi * ls.distance;
    ls.n = -ls.wi;
  }
  return with_selection(ok, pmf, ls);
}

bool LightSet::sample_delta_light(size_t k, Vec3 p, LightSample& ls) const {
  if (k >= punctual_.size()) return false;
  ls = LightSample{};
  ls.light = uint32_t(area_.size() + k);
  if (!sample_punctual(punctual_[k], radius_, p, ls) || is_black(ls.radiance)) return false;
  ls.pdf_solid_angle = 1.0f;
  return true;
}

}  // namespace rf
