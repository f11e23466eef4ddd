// The light list: see light_set.h.
#include "engine/lights/light_set.h"

#include <algorithm>
#include <cmath>

#include "engine/accel.h"
#include "engine/check.h"

namespace rf {

namespace {
constexpr uint32_t kNoLight = ~0u;

float triangle_area(const Mesh& m, uint32_t prim) {
  Vec3 p0 = m.positions[m.indices[3 * prim]], p1 = m.positions[m.indices[3 * prim + 1]],
       p2 = m.positions[m.indices[3 * prim + 2]];
  return 0.5f * length(cross(p1 - p0, p2 - p0));
}

float cos_deg(float deg) { return std::cos(deg * kPi / 180.0f); }
}  // namespace

LightSet::LightSet(const Scene& scene) : scene_(scene) {
  // Bounding sphere of the scene's bounding box (meshes and instances).
  Vec3 lo, hi;
  scene_bounds(scene, lo, hi);
  if (lo.x <= hi.x) {
    center_ = 0.5f * (lo + hi);
    radius_ = 0.5f * length(hi - lo);
  }
  const double r2 = double(radius_) * double(radius_);

  std::vector<double> power;
  std::vector<LightSelection::Group> groups;
  mesh_first_light_.assign(scene.meshes.size(), kNoLight);
  for (uint32_t mi = 0; mi < scene.meshes.size(); ++mi) {
    const Mesh& m = scene.meshes[mi];
    if (!m.emission || is_black(m.emission->radiance)) continue;
    double w = selection_weight(m.emission->radiance) * (m.emission->two_sided ? 2.0 : 1.0);
    mesh_first_light_[mi] = uint32_t(area_.size());
    area_spheres_ |= m.sphere.has_value();
    groups.push_back({uint32_t(area_.size()), uint32_t(m.primitive_count())});
    for (uint32_t t = 0; t < m.primitive_count(); ++t) {
      float a = m.sphere ? 4 * kPi * sqr(m.sphere->radius) : triangle_area(m, t);
      AreaLight tri{mi, t, a, m.sphere ? &*m.sphere : nullptr, {}, {}, {}, {}};
      if (!m.sphere) {
        tri.p0 = m.positions[m.indices[3 * t]], tri.p1 = m.positions[m.indices[3 * t + 1]];
        tri.p2 = m.positions[m.indices[3 * t + 2]];
        tri.n = normalize(cross(tri.p1 - tri.p0, tri.p2 - tri.p0));
        tri.moves = m.deforms();
        moving_ |= tri.moves;
      }
      area_.push_back(tri);
      kinds_.push_back(LightKind::Area);
      power.push_back(double(kPi) * double(a) * w);
    }
  }
  for (const Light& l : scene.lights) {
    groups.push_back({uint32_t(kinds_.size()), 1});
    PunctualLight q{l.type, l.position, normalize(l.direction), l.intensity, 1.0f, 1.0f};
    switch (l.type) {
      case LightType::Point:
        kinds_.push_back(LightKind::Point);
        power.push_back(4.0 * double(kPi) * selection_weight(l.intensity));
        break;
      case LightType::Spot:
        q.cos_falloff_start = cos_deg(l.falloff_start_deg);
        q.cos_falloff_end = cos_deg(l.cone_angle_deg);
        kinds_.push_back(LightKind::Spot);
        power.push_back(2.0 * double(kPi) * selection_weight(l.intensity) *
                        (1.0 - 0.5 * (double(q.cos_falloff_start) + double(q.cos_falloff_end))));
        break;
      case LightType::Directional:
        q.intensity = l.irradiance;
        kinds_.push_back(LightKind::Directional);
        power.push_back(double(kPi) * r2 * selection_weight(l.irradiance));
        break;
    }
    punctual_.push_back(q);
  }
  if (scene.environment) {
    groups.push_back({uint32_t(kinds_.size()), 1});
    env_ = std::make_unique<EnvironmentMap>(*scene.environment);
    kinds_.push_back(LightKind::Environment);
    power.push_back(double(kPi) * r2 * env_->power_integral());
  }
  RF_CHECK(power.size() == kinds_.size(), std::to_string(power.size()) + " powers for " +
                                              std::to_string(kinds_.size()) + " lights");
  std::vector<bool> positioned;
  std::vector<LightBounds> b = bounds(positioned);
  selection_ = LightSelection(std::move(power), std::move(groups), std::move(b), positioned,
                              scene.render.light_selection);
}

std::vector<LightBounds> LightSet::bounds(std::vector<bool>& positioned) const {
  std::vector<LightBounds> bounds(kinds_.size());
  positioned.assign(kinds_.size(), true);
  for (size_t i = 0; i < kinds_.size(); ++i) {
    LightBounds& b = bounds[i];
    if (i < area_.size()) {
      const AreaLight& t = area_[i];
      if (t.sphere) {
        b.lo = t.sphere->center - Vec3(t.sphere->radius);
        b.hi = t.sphere->center + Vec3(t.sphere->radius);
        b.cos_theta_o = -1.0f;  // normals in every direction
      } else if (t.moves) {     // wherever its keys put it, facing anywhere
        const Mesh& m = scene_.meshes[t.mesh];
        b.lo = Vec3(kInf), b.hi = Vec3(-kInf);
        for (const VertexKey& k : m.deform)
          for (int c = 0; c < 3; ++c) {
            const Vec3 q = k.positions[m.indices[3 * size_t(t.prim) + size_t(c)]];
            b.lo = vmin(b.lo, q), b.hi = vmax(b.hi, q);
          }
        b.cos_theta_o = -1.0f;
      } else {
        b.lo = vmin(t.p0, vmin(t.p1, t.p2));
        b.hi = vmax(t.p0, vmax(t.p1, t.p2));
        b.w = t.n;
        b.cos_theta_o = 1.0f;
        b.two_sided = area_emission(i).two_sided;
      }
      b.cos_theta_e = 0.0f;  // Lambertian: a hemisphere about the normal
    } else if (i < area_.size() + punctual_.size()) {
      const PunctualLight& q = punctual_[i - area_.size()];
      if (q.type == LightType::Directional) {
        positioned[i] = false;
        continue;
      }
      b.lo = b.hi = q.position;
      if (q.type == LightType::Point) {
        b.cos_theta_o = -1.0f;
        b.cos_theta_e = 0.0f;
      } else {  // spot: normals within the full-strength cone, light up to the cone's edge
        b.w = q.direction;
        b.cos_theta_o = q.cos_falloff_start;
        b.cos_theta_e =
            std::cos(std::max(0.0f, std::acos(std::clamp(q.cos_falloff_end, -1.0f, 1.0f)) -
                                        std::acos(std::clamp(q.cos_falloff_start, -1.0f, 1.0f))));
      }
    } else {
      positioned[i] = false;  // the environment
    }
  }
  return bounds;
}

AreaLight LightSet::area_at(size_t i, const LightTime& at) const {
  AreaLight tri = area_[i];
  if (!tri.moves) return tri;
  RF_CHECK(at.accel != nullptr,
           "moving area light " + std::to_string(i) + " sampled without its time (LightTime)");
  at.accel->triangle_at(tri.mesh, tri.prim, at.time, tri.p0, tri.p1, tri.p2);
  const Vec3 c = cross(tri.p1 - tri.p0, tri.p2 - tri.p0);
  const float len = length(c);
  tri.area = 0.5f * len;
  tri.n = len > 0 ? c / len : area_[i].n;
  return tri;
}

float LightSet::pdf_solid_angle(Vec3 p, Vec3 n, uint32_t mesh, uint32_t prim, Vec3 on_light,
                                Vec3 n_light, const LightTime& at) const {
  // Surface ids past the world meshes are instanced meshes, never lights (prepare_instances).
  uint32_t first = mesh < mesh_first_light_.size() ? mesh_first_light_[mesh] : kNoLight;
  if (first == kNoLight) return 0.0f;
  const AreaLight tri = area_at(first + prim, at);
  if (!(tri.area > 0)) return 0.0f;
  float pmf = selection_pmf_at(first + prim, p, n);
  if (!(pmf > 0)) return 0.0f;
  float sin2_max, cos_max, one_minus_cos_max;
  if (tri.sphere &&
      sphere_cone(tri.sphere->center, tri.sphere->radius, p, sin2_max, cos_max, one_minus_cos_max))
    return pmf / (2 * kPi * one_minus_cos_max);
  Vec3 d = on_light - p;
  float dist2 = length_sq(d);
  float cos_light = std::fabs(dot(n_light, d)) / std::sqrt(dist2);
  if (!(cos_light > 0)) return 0.0f;
  return pmf / tri.area * dist2 / cos_light;
}

RGB LightSet::environment_radiance(Vec3 dir_world) const {
  return env_ ? env_->radiance(dir_world) : RGB(0.0f);
}

float LightSet::pdf_environment(Vec3 dir_world) const {
  if (!env_) return 0.0f;
  return selection_pmf(environment_index()) * env_->pdf(dir_world);
}

uint32_t LightSet::area_light_index(uint32_t mesh, uint32_t prim) const {
  uint32_t first = mesh < mesh_first_light_.size() ? mesh_first_light_[mesh] : kNoLight;
  return first == kNoLight ? kNoLight : first + prim;
}

}  // namespace rf
