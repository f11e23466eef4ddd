#include "engine/lights.h"

#include <algorithm>
#include <cmath>

#include "engine/check.h"
#include "engine/sampling.h"
#include "engine/shapes.h"
#include "engine/simd.h"

namespace rf {

namespace {
constexpr uint32_t kNoLight = ~0u;

float triangle_area(const Mesh& m, uint32_t prim) {
  Vec3 p0 = m.positions[m.indices[3 * prim]], p1 = m.positions[m.indices[3 * prim + 1]],
       p2 = m.positions[m.indices[3 * prim + 2]];
  return 0.5f * length(cross(p1 - p0, p2 - p0));
}

// pbrt-v4's SmoothStep: 0 at x <= a, 1 at x >= b, 3t^2 - 2t^3 between; a step when a == b.
float smooth_step(float x, float a, float b) {
  if (a == b) return x < a ? 0.0f : 1.0f;
  float t = std::clamp((x - a) / (b - a), 0.0f, 1.0f);
  return t * t * (3.0f - 2.0f * t);
}

float cos_deg(float deg) { return std::cos(deg * kPi / 180.0f); }

// Directional and environment lights: no position, so not in the light BVH.
bool is_infinite(LightKind k) { return k == LightKind::Directional || k == LightKind::Environment; }
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

  mesh_first_light_.assign(scene.meshes.size(), kNoLight);
  for (uint32_t mi = 0; mi < scene.meshes.size(); ++mi) {
    const Mesh& m = scene.meshes[mi];
    if (!m.emission || is_black(m.emission->radiance)) continue;
    double w = selection_weight(m.emission->radiance) * (m.emission->two_sided ? 2.0 : 1.0);
    mesh_first_light_[mi] = uint32_t(tris_.size());
    groups_.push_back({uint32_t(tris_.size()), uint32_t(m.primitive_count())});
    for (uint32_t t = 0; t < m.primitive_count(); ++t) {
      float a = m.sphere ? 4 * kPi * sqr(m.sphere->radius) : triangle_area(m, t);
      Tri tri{mi, t, a, m.sphere ? &*m.sphere : nullptr, {}, {}, {}, {}};
      if (!m.sphere) {
        tri.p0 = m.positions[m.indices[3 * t]], tri.p1 = m.positions[m.indices[3 * t + 1]];
        tri.p2 = m.positions[m.indices[3 * t + 2]];
        tri.n = normalize(cross(tri.p1 - tri.p0, tri.p2 - tri.p0));
      }
      tris_.push_back(tri);
      kinds_.push_back(LightKind::Area);
      power_.push_back(double(kPi) * double(a) * w);
    }
  }
  for (const Light& l : scene.lights) {
    groups_.push_back({uint32_t(kinds_.size()), 1});
    Punctual q{l.type, l.position, normalize(l.direction), l.intensity, 1.0f, 1.0f};
    switch (l.type) {
      case LightType::Point:
        kinds_.push_back(LightKind::Point);
        power_.push_back(4.0 * double(kPi) * selection_weight(l.intensity));
        break;
      case LightType::Spot:
        q.cos_falloff_start = cos_deg(l.falloff_start_deg);
        q.cos_falloff_end = cos_deg(l.cone_angle_deg);
        kinds_.push_back(LightKind::Spot);
        power_.push_back(2.0 * double(kPi) * selection_weight(l.intensity) *
                         (1.0 - 0.5 * (double(q.cos_falloff_start) + double(q.cos_falloff_end))));
        break;
      case LightType::Directional:
        q.intensity = l.irradiance;
        kinds_.push_back(LightKind::Directional);
        power_.push_back(double(kPi) * r2 * selection_weight(l.irradiance));
        break;
    }
    punctual_.push_back(q);
  }
  if (scene.environment) {
    groups_.push_back({uint32_t(kinds_.size()), 1});
    env_ = std::make_unique<EnvironmentMap>(*scene.environment);
    kinds_.push_back(LightKind::Environment);
    power_.push_back(double(kPi) * r2 * env_->power_integral());
  }

  // Selection in two steps with the same per-light probability as one power-proportional pick:
  // a group (a light, or all primitives of an emissive mesh) by its power, then a primitive of
  // the group by its power within the group.
  const size_t n = kinds_.size();
  RF_CHECK(power_.size() == n,
           std::to_string(power_.size()) + " powers for " + std::to_string(n) + " lights");
  double total = 0;
  for (double p : power_) total += p;
  pmf_.resize(n);
  for (size_t i = 0; i < n; ++i) pmf_[i] = float(total > 0 ? power_[i] / total : 1.0 / double(n));
  if constexpr (kDchecks) {
    double sum = 0;  // each pmf is rounded to float: the sum is 1 within n x 2^-24 relative
    for (float p : pmf_) sum += double(p);
    RF_DCHECK(n == 0 || std::fabs(sum - 1.0) < 1e-5, "light pmfs sum to " + std::to_string(sum));
  }
  cdf_.assign(groups_.size() + 1, 0.0);
  within_cdf_.assign(n, 1.0);
  for (size_t g = 0; g < groups_.size(); ++g) {
    const Group& gr = groups_[g];
    double gp = 0;
    for (uint32_t k = 0; k < gr.count; ++k) gp += power_[gr.first + k];
    cdf_[g + 1] = cdf_[g] + (total > 0 ? gp / total : double(gr.count) / double(n));
    double acc = 0;
    for (uint32_t k = 0; k < gr.count; ++k) {
      acc += gp > 0 ? power_[gr.first + k] / gp : 1.0 / double(gr.count);
      within_cdf_[gr.first + k] = acc;
    }
    within_cdf_[gr.first + gr.count - 1] = 1.0;
  }
  RF_DCHECK(groups_.empty() || std::fabs(cdf_.back() - 1.0) < 1e-9,
            "the light groups' cdf ends at " + std::to_string(cdf_.back()));
  if (!groups_.empty()) cdf_.back() = 1.0;
  build_bvh(scene.render.light_selection);
  triangles_by_power_ =
      !tris_.empty() && punctual_.empty() && !env_ && !uses_bvh() &&
      std::none_of(tris_.begin(), tris_.end(), [](const Tri& t) { return t.sphere; });
  pick_in_lanes_ = groups_.size() == 1 && groups_[0].count >= 2 &&
                   groups_[0].count <= uint32_t(kPickLanes) &&
                   std::all_of(pmf_.begin() + groups_[0].first,
                               pmf_.begin() + groups_[0].first + groups_[0].count,
                               [](float p) { return p > 0; });
  const bool spheres =
      !uses_bvh() && !groups_.empty() && groups_.size() <= size_t(kPickLanes) &&
      std::all_of(groups_.begin(), groups_.end(), [&](const Group& g) {
        return g.count == 1 && g.first < tris_.size() && tris_[g.first].sphere && pmf_[g.first] > 0;
      });
  for (size_t g = 0; spheres && g < groups_.size(); ++g) {
    SphereTable& st = sphere_table_;
    const uint32_t i = groups_[g].first;
    const Tri& t = tris_[i];
    const Emission& e = *scene_.meshes[t.mesh].emission;
    const int k = int(g);
    st.put(st.center, k, t.sphere->center), st.put(st.pole, k, t.sphere->axis[1]);
    st.put(st.radiance, k, e.radiance);
    st.radius[k] = t.sphere->radius, st.pmf[k] = pmf_[i], st.two_sided[k] = e.two_sided;
    st.light[k] = i;
    st.count = int(g) + 1;
  }
  if (pick_in_lanes_) {
    PickTable& pt = pick_table_;
    pt.count = int(groups_[0].count);
    for (int k = 0; k < pt.count; ++k) {
      const TriangleLight t = triangle_light(groups_[0].first + uint32_t(k));
      pt.put(pt.p0, k, t.p0), pt.put(pt.p1, k, t.p1), pt.put(pt.p2, k, t.p2), pt.put(pt.n, k, t.n);
      pt.put(pt.radiance, k, t.emission.radiance);
      pt.area[k] = t.area, pt.pmf[k] = t.pmf, pt.two_sided[k] = t.emission.two_sided;
    }
  }
}

void LightSet::build_bvh(const std::string& mode) {
  std::vector<LightBounds> bounds(kinds_.size());
  size_t positioned = 0;
  double positioned_share = 0;
  for (size_t i = 0; i < kinds_.size(); ++i) {
    LightBounds& b = bounds[i];
    float phi = float(power_[i]);
    if (i < tris_.size()) {
      const Tri& t = tris_[i];
      const Mesh& m = scene_.meshes[t.mesh];
      if (t.sphere) {
        b.lo = t.sphere->center - Vec3(t.sphere->radius);
        b.hi = t.sphere->center + Vec3(t.sphere->radius);
        b.cos_theta_o = -1.0f;  // normals in every direction
      } else {
        b.lo = vmin(t.p0, vmin(t.p1, t.p2));
        b.hi = vmax(t.p0, vmax(t.p1, t.p2));
        b.w = t.n;
        b.cos_theta_o = 1.0f;
        b.two_sided = m.emission->two_sided;
      }
      b.cos_theta_e = 0.0f;  // Lambertian: a hemisphere about the normal
    } else if (i < tris_.size() + punctual_.size()) {
      const Punctual& q = punctual_[i - tris_.size()];
      if (q.type == LightType::Directional) continue;
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
      continue;  // the environment
    }
    if (!(phi > 0) || !std::isfinite(phi)) continue;
    b.phi = phi;
    ++positioned;
    positioned_share += pmf_[i];
  }
  bool use = mode == "bvh" || (mode == "auto" && positioned > kAutoBvhLights);
  if (!use || positioned == 0) return;
  bvh_ = LightBvh(bounds);
  bvh_share_ = float(std::min(1.0, positioned_share));
  // Every positioned light with power is in the tree; the rest of the unit is the infinite ones'.
  infinite_cdf_.assign(1, 0.0);
  double acc = 0, inf_total = 0;
  for (size_t i = 0; i < kinds_.size(); ++i)
    if (is_infinite(kinds_[i])) infinite_.push_back(uint32_t(i)), inf_total += pmf_[i];
  for (uint32_t i : infinite_) {
    acc += inf_total > 0 ? pmf_[i] / inf_total : 0.0;
    infinite_cdf_.push_back(acc);
  }
  if (!infinite_.empty()) infinite_cdf_.back() = 1.0;
  if (infinite_.empty()) bvh_share_ = 1.0f;
}

// The light u.x picks (see the constructor): its group, then the primitive within the group, u.x
// rescaled to [0, 1) within each picked interval so that (u.x, u.y) stays a stratified 2D sample
// over the light's surface. Each rescale costs x resolution: about 2^-24 / (group pmf x
// primitive pmf within the group) is left. ~0 when nothing can be picked.
size_t LightSet::select(float& ux) const {
  const size_t ng = groups_.size();
  if (ng == 0) return kNoLight;
  // First cdf entry > ux: the group whose interval [cdf_g, cdf_g+1) holds ux (one group: it),
  // and ux rescaled to [0, 1) within it (as the step within the group below, whose lane version
  // pick_in_group_lanes also does this step for pick_sphere_entries).
  size_t g = 0;
  if (ng > 1) {
    g = size_t(std::upper_bound(cdf_.begin() + 1, cdf_.end(), double(ux)) - (cdf_.begin() + 1));
    g = std::min(g, ng - 1);
    while (cdf_[g + 1] == cdf_[g] && g > 0) --g;  // a zero-width interval cannot be selected
    double lo = g > 0 ? cdf_[g] : 0.0, hi = cdf_[g + 1];
    ux = hi > lo ? float(std::clamp((double(ux) - lo) / (hi - lo), 0.0, 1.0)) : 0.5f;
    ux = std::min(ux, 0x1.fffffep-1f);
  }
  const Group& gr = groups_[g];
  size_t i = gr.first;
  if (gr.count > 1) {
    auto begin = within_cdf_.begin() + gr.first, end = begin + gr.count;
    const double x = double(ux);
    if (gr.count <= 16) {
      // upper_bound's position in a sorted range is the number of entries it does not pass
      // (!(x < c)); counted without branches: a search's branches mispredict on random u.
      size_t k = 0;
      for (auto c = begin; c != end; ++c) k += !(x < *c);
      i = gr.first + k;
    } else {
      i = size_t(std::upper_bound(begin, end, x) - within_cdf_.begin());
    }
    i = std::min(i, size_t(gr.first + gr.count - 1));
    while (pmf_[i] == 0 && i > gr.first) --i;
    double lo = i > gr.first ? within_cdf_[i - 1] : 0.0, hi = within_cdf_[i];
    ux = hi > lo ? float(std::clamp((double(ux) - lo) / (hi - lo), 0.0, 1.0)) : 0.5f;
    ux = std::min(ux, 0x1.fffffep-1f);
  }
  return pmf_[i] > 0 ? i : kNoLight;
}

bool LightSet::sample_by_power(Vec3 p, Vec2 u_point, LightSample& ls) const {
  size_t i = select(u_point.x);
  if (i == kNoLight) return false;
  return sample_selected(i, pmf_[i], p, u_point, ls);
}

bool LightSet::sample(Vec3 p, Vec3 n, float u_select, Vec2 u_point, LightSample& ls) const {
  size_t i;
  float pmf;
  return pick(p, n, u_select, u_point, i, pmf) && sample_selected(i, pmf, p, u_point, ls);
}

bool LightSet::pick(Vec3 p, Vec3 n, float u_select, Vec2& u_point, size_t& light,
                    float& pmf) const {
  if (!uses_bvh()) {
    light = select(u_point.x);
    pmf = light == kNoLight ? 0.0f : pmf_[light];
    return light != kNoLight;
  }
  if (u_select < bvh_share_) {
    uint32_t i;
    float u = std::min(u_select / bvh_share_, 0x1.fffffep-1f);
    if (!bvh_.sample(p, n, u, i, pmf)) return false;
    light = i, pmf *= bvh_share_;
    return true;
  }
  if (infinite_.empty()) return false;
  double u = (double(u_select) - bvh_share_) / (1.0 - bvh_share_);
  size_t k = size_t(std::upper_bound(infinite_cdf_.begin() + 1, infinite_cdf_.end(), u) -
                    (infinite_cdf_.begin() + 1));
  k = std::min(k, infinite_.size() - 1);
  light = infinite_[k], pmf = pmf_[light];
  return pmf > 0;
}

float LightSet::selection_pmf_at(size_t light, Vec3 p, Vec3 n) const {
  if (light >= size()) return 0.0f;
  if (!uses_bvh()) return pmf_[light];
  if (is_infinite(kinds_[light])) return pmf_[light];
  return bvh_share_ * bvh_.pmf(p, n, uint32_t(light));
}

bool LightSet::sample_selected(size_t i, float pmf, Vec3 p, Vec2 u_point, LightSample& ls) const {
  ls = LightSample{};
  ls.light = uint32_t(i);
  bool ok = false;
  ls.pdf_solid_angle = 1.0f;  // delta lights: the selection probability alone
  if (i < tris_.size()) {
    ok = sample_area(tris_[i], p, u_point, ls);
  } else if (i < tris_.size() + punctual_.size()) {
    ok = sample_punctual(punctual_[i - tris_.size()], p, ls);
  } else {
    ok = env_->sample(u_point, ls.wi, ls.radiance, ls.pdf_solid_angle);
    ls.is_infinite = true;
    ls.distance = 2.0f * radius_;
    ls.p = p + ls.wi * ls.distance;
    ls.n = -ls.wi;
  }
  return with_selection(ok, pmf, ls);
}

bool LightSet::pick_triangle(float& ux, TriangleLight& light) const {
  size_t i = select(ux);
  if (i == kNoLight) return false;
  light = triangle_light(uint32_t(i));
  return true;
}

namespace {
// select()'s second step for kPickLanes lanes in one group of 1 <= count <= kPickLanes entries
// (or its first step over groups, pick_sphere_entries)
// of cumulative probability cdf[0..count) (last 1), none of zero probability (equal entries, from
// probabilities that vanish in the sum, are met as select() meets them): k[j] the entry (upper
// bound of x = ux[j], clamped to the last) and ux[j] rescaled to it. The same operations as
// select() in the same order, so the same bits: the upper bound as the entries x does not pass
// among the first count - 1, the interval's ends by selects over them.
RF_SIMD_CLONES
void pick_in_group_lanes(const double* __restrict cdf, int count, float* __restrict ux,
                         uint32_t* __restrict k) {
  constexpr int N = LightSet::kPickLanes;
  double x[N], lo[N], hi[N], passed[N];
  for (int j = 0; j < N; ++j) x[j] = double(ux[j]), lo[j] = 0.0, hi[j] = cdf[count - 1];
  for (int j = 0; j < N; ++j) passed[j] = 0.0;
  for (int c = 0; c + 1 < count; ++c) {
    const double e = cdf[c];
#pragma GCC unroll 1  // unrolled completely, the loop would not vectorise
    for (int j = 0; j < N; ++j) {
      const bool past = !(x[j] < e);
      passed[j] += past ? 1.0 : 0.0;  // counted in double: the vectoriser wants one width
      lo[j] = past ? e : lo[j];
    }
  }
  for (int j = 0; j < N; ++j) k[j] = uint32_t(passed[j]);
  for (int c = count - 2; c >= 0; --c) {
    const double e = cdf[c];
    for (int j = 0; j < N; ++j) hi[j] = x[j] < e ? e : hi[j];
  }
  for (int j = 0; j < N; ++j) {
    const bool wide = hi[j] > lo[j];
    const double t = (x[j] - lo[j]) / (wide ? hi[j] - lo[j] : 1.0);
    const float f = wide ? float(std::clamp(t, 0.0, 1.0)) : 0.5f;
    ux[j] = std::min(f, 0x1.fffffep-1f);
  }
}
}  // namespace

void LightSet::pick_triangles(float* ux, int n, uint32_t* light) const {
  for (int j = 0; j < n; ++j) light[j] = uint32_t(select(ux[j]));  // kNoLight: kNoPick
}

void LightSet::pick_entries(float* ux, uint32_t* entry) const {
  pick_in_group_lanes(within_cdf_.data() + groups_[0].first, int(groups_[0].count), ux, entry);
}

// select()'s first step over the groups (one sphere each, so no second step): the entries of
// cdf_[1..] that ux does not pass, and ux rescaled within its group's interval.
void LightSet::pick_sphere_entries(float* ux, uint32_t* entry) const {
  pick_in_group_lanes(cdf_.data() + 1, sphere_table_.count, ux, entry);
}

// A uniformly distributed point of an area light's primitive (density 1 / area), its error bound
// and its unit normal (outward for spheres).
// Inlined into its callers (a call per light sample, with three vectors returned through memory).
[[gnu::always_inline]] inline void LightSet::sample_surface(const Tri& tri, Vec2 u, Vec3& q,
                                                            Vec3& q_error, Vec3& n) const {
  if (tri.sphere) {
    sphere_surface_point(*tri.sphere, tri.sphere->center + sample_uniform_sphere(u), q, q_error, n);
    return;
  }
  triangle_point(tri.p0, tri.p1, tri.p2, u, q, q_error);
  n = tri.n;
}

bool LightSet::sphere_cone_of(size_t i, Vec3 p, SphereCone& c) const {
  return i < tris_.size() && sphere_cone_of(tris_[i], p, c);
}

bool LightSet::sphere_cone_of(const Tri& tri, Vec3 p, SphereCone& c) const {
  if (!tri.sphere) return false;
  const SphereShape& s = *tri.sphere;
  if (!sphere_cone(s.center, s.radius, p, c.sin2_max, c.cos_max, c.one_minus_cos_max)) return false;
  c.center = s.center, c.pole = s.axis[1], c.radius = s.radius;
  c.emission = *scene_.meshes[tri.mesh].emission;
  return true;
}

// Spheres seen from outside: a direction uniform in the cone the sphere subtends (pbrt-v4), the
// point where it first meets the sphere computed directly. Otherwise a uniform point of the
// primitive, its area density converted to solid angle. pdf_solid_angle without selection.
bool LightSet::sample_area(const Tri& tri, Vec3 p, Vec2 u, LightSample& ls) const {
  const Mesh& m = scene_.meshes[tri.mesh];
  SphereCone c;
  if (sphere_cone_of(tri, p, c)) {
    float cos_alpha, sin_alpha, cos_phi, sin_phi;
    sphere_cone_angles(c.sin2_max, c.cos_max, u, cos_alpha, sin_alpha, cos_phi, sin_phi);
    return sphere_cone_point(c, p, cos_alpha, sin_alpha, cos_phi, sin_phi, ls);
  }
  if (!tri.sphere)
    return sample_triangle_area(tri.p0, tri.p1, tri.p2, tri.n, tri.area, *m.emission, p, u, ls);
  sample_surface(tri, u, ls.p, ls.p_error, ls.n);  // a sphere seen from inside: uniform on it
  return area_point_seen_from(p, tri.area, *m.emission, ls);
}

bool LightSet::sample_punctual(const Punctual& l, Vec3 p, LightSample& ls) const {
  ls.is_delta = true;
  if (l.type == LightType::Directional) {
    ls.is_infinite = true;
    ls.wi = -l.direction;
    ls.distance = 2.0f * radius_;
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

float LightSet::pdf_solid_angle(Vec3 p, Vec3 n, uint32_t mesh, uint32_t prim, Vec3 on_light,
                                Vec3 n_light) const {
  // Surface ids past the world meshes are instanced meshes, never lights (prepare_instances).
  uint32_t first = mesh < mesh_first_light_.size() ? mesh_first_light_[mesh] : kNoLight;
  if (first == kNoLight) return 0.0f;
  const Tri& tri = tris_[first + prim];
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
  return pmf_[environment_index()] * env_->pdf(dir_world);
}

bool LightSet::sample_delta_light(size_t k, Vec3 p, LightSample& ls) const {
  if (k >= punctual_.size()) return false;
  ls = LightSample{};
  ls.light = uint32_t(tris_.size() + k);
  if (!sample_punctual(punctual_[k], p, ls) || is_black(ls.radiance)) return false;
  ls.pdf_solid_angle = 1.0f;
  return true;
}

namespace {
// Uniform direction in the cone of half-angle acos(cos_max) about +z; pdf 1 / (2 pi (1 - cos_max)).
Vec3 sample_uniform_cone(Vec2 u, float cos_max) {
  float cos_t = 1.0f - u.x * (1.0f - cos_max);
  float sin_t = safe_sqrt(1.0f - cos_t * cos_t);
  float phi = 2 * kPi * u.y;
  return {sin_t * std::cos(phi), sin_t * std::sin(phi), cos_t};
}
}  // namespace

bool LightSet::sample_emission(Vec2 u_pos, Vec2 u_dir, EmissionSample& es,
                               bool infinite_lights) const {
  size_t i = select(u_pos.x);
  if (i == kNoLight) return false;
  es = EmissionSample{};
  es.light = uint32_t(i);
  float pmf = pmf_[i];
  if (i < tris_.size()) {
    const Tri& tri = tris_[i];
    const Mesh& m = scene_.meshes[tri.mesh];
    if (!(tri.area > 0)) return false;
    sample_surface(tri, u_pos, es.p, es.p_error, es.n);
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
    es.radiance = emitted(m, es.n, es.dir);
    es.pdf_pos = pmf / tri.area;
    float pdf_dir = side_pdf * local.z * kInvPi;
    es.pdf_dir = pdf_dir;
    es.beta = es.radiance * (local.z / (es.pdf_pos * pdf_dir));
    es.is_area = true;
    es.mesh = tri.mesh;
    es.prim = tri.prim;
  } else if (i < tris_.size() + punctual_.size()) {
    const Punctual& l = punctual_[i - tris_.size()];
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

uint32_t LightSet::area_light_index(uint32_t mesh, uint32_t prim) const {
  uint32_t first = mesh < mesh_first_light_.size() ? mesh_first_light_[mesh] : kNoLight;
  return first == kNoLight ? kNoLight : first + prim;
}

void LightSet::pdf_emission(uint32_t light, Vec3 n, Vec3 dir, float& pdf_pos,
                            float& pdf_dir) const {
  pdf_pos = pdf_dir = 0;
  if (light >= size()) return;
  if (light < tris_.size()) {
    const Tri& tri = tris_[light];
    if (!(tri.area > 0)) return;
    pdf_pos = pmf_[light] / tri.area;
    float cos_t = dot(n, dir);
    if (scene_.meshes[tri.mesh].emission->two_sided)
      pdf_dir = 0.5f * std::fabs(cos_t) * kInvPi;
    else
      pdf_dir = cos_t > 0 ? cos_t * kInvPi : 0.0f;
    return;
  }
  if (light >= tris_.size() + punctual_.size()) return;  // the environment
  const Punctual& l = punctual_[light - tris_.size()];
  if (l.type == LightType::Directional) return;
  pdf_pos = pmf_[light];
  if (l.type == LightType::Point)
    pdf_dir = 1.0f / (4 * kPi);
  else
    pdf_dir = dot(l.direction, dir) >= l.cos_falloff_end
                  ? 1.0f / (2 * kPi * (1.0f - l.cos_falloff_end))
                  : 0.0f;
}

}  // namespace rf
