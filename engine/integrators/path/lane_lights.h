// The light tables the path tracer's lane kernels read (surface_lanes.h), built from a LightSet:
// picks and light samples for a packet's plain vertices taken in vectorised loops with the bits
// LightSet::sample gives one vertex.
#pragma once

#include <cstdint>

#include "engine/lights/light_set.h"
#include "engine/simd.h"

namespace rf {

class LaneLights {
 public:
  static constexpr int kLanes = 16;  // a packet's lanes (Accel::kPacket)
  static constexpr uint32_t kNoPick = LightSelection::kNone;

  explicit LaneLights(const LightSet& lights);

  // When every light is a triangle picked by power (no light BVH, no sphere, point or infinite
  // light), triangles_by_power() is true and LightSet::sample() is a pick by power followed by
  // sample_triangle() (light_sampling.h) with the same numbers, bit for bit.
  bool triangles_by_power() const { return triangles_by_power_; }
  // The pick by power for lanes j < n, one after another: light[j] the picked light's index
  // (kNoPick when nothing can be picked) and ux[j] rescaled (LightSelection::select);
  // LightSet::triangle_light(light[j]) is then its light.
  void pick_triangles(float* ux, int n, uint32_t* light) const;

  // When the lights are one emissive mesh of 2 to kLanes triangles, none of zero probability
  // (pick_in_lanes(), the Cornell box's light), the pick for kLanes lanes at once in a vectorised
  // loop, in place: ux[j] rescaled and entry[j] the picked light's entry in pick_table(), bit for
  // bit select()'s numbers.
  bool pick_in_lanes() const { return pick_table_.count > 0; }
  void pick_entries(float* ux, uint32_t* entry) const;
  // Those lights as lane arrays, entry k < count holding the triangle_light() numbers of the
  // mesh's k-th triangle, so loops over lanes read a picked light by its entry (LaneSlots' m and
  // lane are unused).
  struct PickTable : LaneSlots<kLanes> {
    V3 p0, p1, p2, n, radiance;
    float area[kLanes], pmf[kLanes];
    int two_sided[kLanes];
    int count = 0;  // entries: the mesh's triangles; 0 when !pick_in_lanes()
  };
  const PickTable& pick_table() const { return pick_table_; }

  // When every light is an exact sphere, picked by power among 1 to kLanes of them, none of zero
  // probability (spheres_in_lanes(), veach-mis's three), the pick for kLanes lanes at once, in
  // place: entry[j] the entry of sphere_table() that ux[j] (u_point.x) picks and ux[j] rescaled,
  // bit for bit LightSelection::pick's light (sphere_table().light[entry[j]]) and numbers.
  bool spheres_in_lanes() const { return sphere_table_.count > 0; }
  void pick_sphere_entries(float* ux, uint32_t* entry) const;
  // Those spheres as lane arrays (LaneSlots' m and lane are unused): entry k's light, selection
  // probability, and LightSet::sphere_cone_of's centre, pole, radius and emission.
  struct SphereTable : LaneSlots<kLanes> {
    V3 center, pole, radiance;
    float radius[kLanes], pmf[kLanes];
    int two_sided[kLanes];
    uint32_t light[kLanes];
    int count = 0;  // entries: the spheres; 0 when !spheres_in_lanes()
  };
  const SphereTable& sphere_table() const { return sphere_table_; }

 private:
  const LightSelection& selection_;
  bool triangles_by_power_ = false;
  const double* within_ = nullptr;  // pick_entries: the one group's cumulative probabilities
  PickTable pick_table_{};
  SphereTable sphere_table_{};
};

}  // namespace rf
