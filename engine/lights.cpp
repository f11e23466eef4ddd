#include "engine/lights.h"

#include <algorithm>

#include "engine/sampling.h"

namespace rf {

namespace {
constexpr uint32_t kNoLight = ~0u;

float triangle_area(const Mesh& m, uint32_t prim) {
  Vec3 p0 = m.positions[m.indices[3 * prim]], p1 = m.positions[m.indices[3 * prim + 1]],
       p2 = m.positions[m.indices[3 * prim + 2]];
  return 0.5f * length(cross(p1 - p0, p2 - p0));
}
}  // namespace

LightSet::LightSet(const Scene& scene) : scene_(scene) {
  mesh_first_light_.assign(scene.meshes.size(), kNoLight);
  std::vector<double> power;
  for (uint32_t mi = 0; mi < scene.meshes.size(); ++mi) {
    const Mesh& m = scene.meshes[mi];
    if (!m.emission || is_black(m.emission->radiance)) continue;
    double lum = luminance(m.emission->radiance) * (m.emission->two_sided ? 2.0 : 1.0);
    // Lights of zero luminance but non-zero colour (pure blue, say) still need a chance.
    if (lum <= 0) lum = max_component(m.emission->radiance);
    mesh_first_light_[mi] = uint32_t(tris_.size());
    for (uint32_t t = 0; t < m.triangle_count(); ++t) {
      float a = triangle_area(m, t);
      tris_.push_back({mi, t, a});
      power.push_back(kPi * double(a) * lum);
    }
  }
  double total = 0;
  for (double p : power) total += p;
  cdf_.assign(tris_.size() + 1, 0.0);
  pmf_.resize(tris_.size());
  for (size_t i = 0; i < tris_.size(); ++i) {
    pmf_[i] = total > 0 ? float(power[i] / total) : 0.0f;
    cdf_[i + 1] = cdf_[i] + (total > 0 ? power[i] / total : 0.0);
  }
  if (!tris_.empty()) cdf_.back() = 1.0;
}

float LightSet::selection_pmf(size_t light) const { return pmf_[light]; }

bool LightSet::sample(Vec3 p, float u_select, Vec2 u_point, LightSample& ls) const {
  if (tris_.empty()) return false;
  // First cdf entry > u: the light whose interval [cdf_i, cdf_i+1) holds u.
  size_t i =
      size_t(std::upper_bound(cdf_.begin() + 1, cdf_.end(), double(u_select)) - (cdf_.begin() + 1));
  i = std::min(i, tris_.size() - 1);
  while (pmf_[i] == 0 && i > 0) --i;  // a zero-width interval cannot be selected
  const Tri& tri = tris_[i];
  const Mesh& m = scene_.meshes[tri.mesh];
  Vec3 p0 = m.positions[m.indices[3 * tri.prim]], p1 = m.positions[m.indices[3 * tri.prim + 1]],
       p2 = m.positions[m.indices[3 * tri.prim + 2]];
  Vec2 b = sample_uniform_triangle(u_point);
  float b2 = 1.0f - b.x - b.y;
  ls.p = b.x * p0 + b.y * p1 + b2 * p2;
  constexpr float g7 = 7 * std::numeric_limits<float>::epsilon() * 0.5f;
  ls.p_error = g7 * (abs(b.x * p0) + abs(b.y * p1) + abs(b2 * p2));
  ls.n = normalize(cross(p1 - p0, p2 - p0));
  Vec3 d = ls.p - p;
  float dist2 = length_sq(d);
  if (dist2 <= 0) return false;
  ls.distance = std::sqrt(dist2);
  ls.wi = d / ls.distance;
  float cos_light = std::fabs(dot(ls.n, ls.wi));
  ls.radiance = emitted(m, ls.n, -ls.wi);
  if (cos_light <= 0 || is_black(ls.radiance)) return false;
  ls.pdf_solid_angle = pmf_[i] / tri.area * dist2 / cos_light;
  return std::isfinite(ls.pdf_solid_angle) && ls.pdf_solid_angle > 0;
}

float LightSet::pdf_solid_angle(Vec3 p, uint32_t mesh, uint32_t prim, Vec3 on_light,
                                Vec3 n_light) const {
  uint32_t first = mesh_first_light_[mesh];
  if (first == kNoLight) return 0.0f;
  const Tri& tri = tris_[first + prim];
  if (tri.area <= 0) return 0.0f;
  Vec3 d = on_light - p;
  float dist2 = length_sq(d);
  float cos_light = std::fabs(dot(n_light, d)) / std::sqrt(dist2);
  if (cos_light <= 0) return 0.0f;
  return pmf_[first + prim] / tri.area * dist2 / cos_light;
}

}  // namespace rf
