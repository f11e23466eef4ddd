// Lights and light selection. Area lights: every triangle of a mesh with an emission is one
// light primitive, sampled uniformly by area. Next-event estimation picks a light primitive with
// probability proportional to its power, Phi = pi * A * luminance(Le) * (2 if two-sided), so the
// many small triangles of a big emitter are picked as often as their share of the light.
#pragma once

#include <cstdint>
#include <vector>

#include "engine/accel.h"
#include "engine/scene.h"

namespace rf {

struct LightSample {
  Vec3 p, p_error, n;   // point on the light, its error bound and unit geometric normal
  RGB radiance;         // emitted towards the shading point
  Vec3 wi;              // unit direction from the shading point to the light point
  float distance = 0;
  float pdf_solid_angle = 0;  // including the selection probability
};

class LightSet {
 public:
  explicit LightSet(const Scene& scene);

  bool empty() const { return tris_.empty(); }
  size_t size() const { return tris_.size(); }

  // Samples a light point as seen from p; false when nothing can be sampled (pdf 0).
  bool sample(Vec3 p, float u_select, Vec2 u_point, LightSample& ls) const;
  // Solid-angle pdf of sampling light point `on_light` (triangle mesh/prim) from p, as
  // sample() would, including selection; 0 when that triangle is not a light.
  float pdf_solid_angle(Vec3 p, uint32_t mesh, uint32_t prim, Vec3 on_light, Vec3 n_light) const;
  // Probability of selecting each light (sums to 1).
  float selection_pmf(size_t light) const;

  // Radiance a surface point of `mesh` emits in direction w (world), given its geometric normal.
  static RGB emitted(const Mesh& mesh, Vec3 ng, Vec3 w) {
    if (!mesh.emission) return RGB(0.0f);
    if (!mesh.emission->two_sided && dot(ng, w) <= 0) return RGB(0.0f);
    return mesh.emission->radiance;
  }

 private:
  struct Tri {
    uint32_t mesh, prim;
    float area;
  };
  const Scene& scene_;
  std::vector<Tri> tris_;
  std::vector<double> cdf_;                  // size tris_+1, cdf_[0] = 0, cdf_.back() = 1
  std::vector<float> pmf_;
  std::vector<uint32_t> mesh_first_light_;   // per mesh: index of its first light triangle or ~0
};

}  // namespace rf
