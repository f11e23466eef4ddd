// Emission for light paths (light tracing, BDPT, instant radiosity, photon mapping): the start of
// a light path and its densities. See light_set.h.
#include <cmath>

#include "engine/lights/light_set.h"

namespace rf {

namespace {
// Uniform direction in the cone of half-angle acos(cos_max) about +z; pdf 1 / (2 pi (1 - cos_max)).
Vec3 sample_uniform_cone(Vec2 u, float cos_max) {
  float cos_t = 1.0f - u.x * (1.0f - cos_max);
  float sin_t = safe_sqrt(1.0f - cos_t * cos_t);
  float phi = 2 * kPi * u.y;
  return {sin_t * std::cos(phi), sin_t * std::sin(phi), cos_t};
}
}  // namespace

bool LightSet::sample_emission(Vec2 u_pos, Vec2 u_dir, EmissionSample& es, bool infinite_lights,
                               const LightTime& at) const {
  size_t i = selection_.select(u_pos.x);
  if (i == LightSelection::kNone) return false;
  es = EmissionSample{};
  es.light = uint32_t(i);
  float pmf = selection_.pmf(i);
  if (i < area_.size()) {
    const AreaLight tri = area_at(i, at);
    const Mesh& m = scene_.meshes[tri.mesh];
    if (!(tri.area > 0)) return false;
    sample_area_surface(tri, u_pos, es.p, es.p_error, es.n);
    // Two-sided emitters pick a side with probability 1/2 (the first half of u_dir.x).
    Vec2 u = u_dir;
    float side_pdf = 1.0f;
    Vec3 side_n = es.n;
    if (m.emission->two_sided) {
      side_pdf = 0.5f;
      if (u.x < 0.5f) {
        u.x *= 2.0f;
      } else {
        u.x = 2.0f * u.x - 1.0f;
        side_n = -es.n;
      }
      u.x = std::min(u.x, 0x1.fffffep-1f);
    }
    Vec3 local = sample_cosine_hemisphere(u);
    if (!(local.z > 0)) return false;
    es.dir = Frame::from_normal(side_n).to_world(local);
    es.radiance = emitted_radiance(m, es.n, es.dir);
    es.pdf_pos = pmf / tri.area;
    float pdf_dir = side_pdf * local.z * kInvPi;
    es.pdf_dir = pdf_dir;
    es.beta = es.radiance * (local.z / (es.pdf_pos * pdf_dir));
    es.is_area = true;
    es.mesh = tri.mesh;
    es.prim = tri.prim;
  } else if (i < area_.size() + punctual_.size()) {
    const PunctualLight& l = punctual_[i - area_.size()];
    if (l.type == LightType::Directional) {
      if (!infinite_lights) return false;
      // The irradiance E crosses the disk: flux E pi R^2, a delta in direction.
      start_on_disk(l.direction, u_pos, pmf, es);
      es.pdf_dir = 1.0f;
      es.beta = l.intensity / es.pdf_pos;
      return !is_black(es.beta) && is_finite(es.beta);
    }
    es.p = l.position;
    es.n = l.direction;
    float pdf_dir;
    if (l.type == LightType::Point) {
      es.dir = sample_uniform_sphere(u_dir);
      pdf_dir = 1.0f / (4 * kPi);
    } else {
      es.dir =
          Frame::from_normal(l.direction).to_world(sample_uniform_cone(u_dir, l.cos_falloff_end));
      pdf_dir = 1.0f / (2 * kPi * (1.0f - l.cos_falloff_end));
    }
    float falloff = l.type == LightType::Spot ? smooth_step(dot(l.direction, es.dir),
                                                            l.cos_falloff_end, l.cos_falloff_start)
                                              : 1.0f;
    es.pdf_pos = pmf;  // a probability mass: the point is fixed
    es.pdf_dir = pdf_dir;
    es.beta = l.intensity * (falloff / (pmf * pdf_dir));
  } else {
    if (!infinite_lights) return false;
    Vec3 wi;  // towards the environment; the light travels along -wi
    RGB le;
    float pdf_dir;
    if (!env_->sample(u_dir, wi, le, pdf_dir) || !(pdf_dir > 0)) return false;
    start_on_disk(-wi, u_pos, pmf, es);
    es.pdf_dir = pdf_dir;
    es.radiance = le;
    es.beta = le / (es.pdf_pos * pdf_dir);  // the disk faces the beam: cos = 1
  }
  return !is_black(es.beta) && is_finite(es.beta);
}

void LightSet::start_on_disk(Vec3 dir, Vec2 u, float pmf, EmissionSample& es) const {
  Vec2 d = sample_concentric_disk(u);
  Frame f = Frame::from_normal(dir);
  es.p = center_ + radius_ * (f.to_world({d.x, d.y, 0.0f}) - dir);
  es.p_error = Vec3(0.0f);
  es.n = dir;
  es.dir = dir;
  es.pdf_pos = pmf / (kPi * radius_ * radius_);
  es.is_infinite = true;
}

void LightSet::pdf_emission(uint32_t light, Vec3 n, Vec3 dir, float& pdf_pos, float& pdf_dir,
                            const LightTime& at) const {
  pdf_pos = pdf_dir = 0;
  if (light >= size()) return;
  if (light < area_.size()) {
    const AreaLight tri = area_at(light, at);
    if (!(tri.area > 0)) return;
    pdf_pos = selection_pmf(light) / tri.area;
    float cos_t = dot(n, dir);
    if (area_emission(light).two_sided)
      pdf_dir = 0.5f * std::fabs(cos_t) * kInvPi;
    else
      pdf_dir = cos_t > 0 ? cos_t * kInvPi : 0.0f;
    return;
  }
  if (light >= area_.size() + punctual_.size()) return;  // the environment
  const PunctualLight& l = punctual_[light - area_.size()];
  if (l.type == LightType::Directional) return;
  pdf_pos = selection_pmf(light);
  if (l.type == LightType::Point)
    pdf_dir = 1.0f / (4 * kPi);
  else
    pdf_dir = dot(l.direction, dir) >= l.cos_falloff_end
                  ? 1.0f / (2 * kPi * (1.0f - l.cos_falloff_end))
                  : 0.0f;
}

}  // namespace rf
