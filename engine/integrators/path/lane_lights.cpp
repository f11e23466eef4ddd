// The lane light tables: see lane_lights.h.
#include "engine/integrators/path/lane_lights.h"

#include <algorithm>

namespace rf {

namespace {
// LightSelection::select()'s second step for kLanes lanes in one group of 1 <= count <= kLanes
// entries (or its first step over groups, pick_sphere_entries) of cumulative probability
// cdf[0..count) (last 1), none of zero probability (equal entries, from probabilities that vanish
// in the sum, are met as select() meets them): k[j] the entry (upper bound of x = ux[j], clamped
// to the last) and ux[j] rescaled to it. The same operations as select() in the same order, so
// the same bits: the upper bound as the entries x does not pass among the first count - 1, the
// interval's ends by selects over them.
RF_SIMD_CLONES
void pick_in_group_lanes(const double* __restrict cdf, int count, float* __restrict ux,
                         uint32_t* __restrict k) {
  constexpr int N = LaneLights::kLanes;
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

LaneLights::LaneLights(const LightSet& lights) : selection_(lights.selection()) {
  const std::vector<LightSelection::Group>& groups = selection_.groups();
  // (O(1) in the lights: built once per task.)
  // Moving emitters are sampled one by one at each lane's time (LightSet::sample_selected), so a
  // scene with one takes none of the lane tables.
  const bool still = !lights.has_moving_area_lights();
  triangles_by_power_ = still && lights.area_light_count() > 0 &&
                        lights.area_light_count() == lights.size() && !lights.uses_bvh() &&
                        !lights.has_area_spheres();
  const auto positive = [&](uint32_t i) { return selection_.pmf(i) > 0; };
  // One emissive mesh of 2 to kLanes triangles, none of zero probability.
  bool one_mesh =
      still && groups.size() == 1 && groups[0].count >= 2 && groups[0].count <= uint32_t(kLanes);
  for (uint32_t k = 0; one_mesh && k < groups[0].count; ++k)
    one_mesh &= positive(groups[0].first + k);
  if (one_mesh) {
    PickTable& pt = pick_table_;
    pt.count = int(groups[0].count);
    within_ = selection_.within_cdf() + groups[0].first;
    for (int k = 0; k < pt.count; ++k) {
      const TriangleLight t = lights.triangle_light(groups[0].first + uint32_t(k));
      pt.put(pt.p0, k, t.p0), pt.put(pt.p1, k, t.p1), pt.put(pt.p2, k, t.p2), pt.put(pt.n, k, t.n);
      pt.put(pt.radiance, k, t.emission.radiance);
      pt.area[k] = t.area, pt.pmf[k] = t.pmf, pt.two_sided[k] = t.emission.two_sided;
    }
  }
  const bool spheres =
      still && !lights.uses_bvh() && !groups.empty() && groups.size() <= size_t(kLanes) &&
      std::all_of(groups.begin(), groups.end(), [&](const LightSelection::Group& g) {
        return g.count == 1 && g.first < lights.area_light_count() &&
               lights.area_light(g.first).sphere && positive(g.first);
      });
  for (size_t g = 0; spheres && g < groups.size(); ++g) {
    SphereTable& st = sphere_table_;
    const uint32_t i = groups[g].first;
    const SphereShape& s = *lights.area_light(i).sphere;
    const Emission& e = lights.area_emission(i);
    const int k = int(g);
    st.put(st.center, k, s.center), st.put(st.pole, k, s.axis[1]);
    st.put(st.radiance, k, e.radiance);
    st.radius[k] = s.radius, st.pmf[k] = selection_.pmf(i), st.two_sided[k] = e.two_sided;
    st.light[k] = i;
    st.count = int(g) + 1;
  }
}

void LaneLights::pick_triangles(float* ux, int n, uint32_t* light) const {
  for (int j = 0; j < n; ++j) light[j] = uint32_t(selection_.select(ux[j]));  // kNone: kNoPick
}

void LaneLights::pick_entries(float* ux, uint32_t* entry) const {
  pick_in_group_lanes(within_, pick_table_.count, ux, entry);
}

// select()'s first step over the groups (one sphere each, so no second step): the entries of the
// group cdf that ux does not pass, and ux rescaled within its group's interval.
void LaneLights::pick_sphere_entries(float* ux, uint32_t* entry) const {
  pick_in_group_lanes(selection_.group_cdf(), sphere_table_.count, ux, entry);
}

}  // namespace rf
