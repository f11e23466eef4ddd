// The scene's lights as one list, the way next-event estimation and light paths see them.
//
// Numbering (LightSample::light, EmissionSample::light, LightSelection): area primitives first,
// mesh by mesh (every triangle of an emissive mesh, or its one exact sphere), then Scene::lights
// in order, then the environment last.
//
// Power, which selection by power is proportional to (light_selection.h), measured by the
// selection weight w(c) = luminance(c) (the largest component when that is 0 but c is not black,
// so every light that emits can be chosen). R is the radius of the bounding sphere of the
// scene's meshes (1 if there are none):
//   area triangle  Phi = pi * A * w(Le) * (2 if two-sided)      (Lambertian emitter)
//   sphere         the same with A = 4 pi r^2
//   point          Phi = 4 pi * w(I)
//   spot           Phi = 2 pi * w(I) * (1 - (cos_start + cos_end) / 2)   (pbrt-v4 SpotLight::Phi;
//                  exact, since the smoothstep falloff integrates to half its width in cos)
//   directional    Phi = pi R^2 * w(E)          (the flux through the scene's bounding disk)
//   environment    Phi = pi R^2 * integral over the sphere of w(L(w)) dw
//                      = 4 pi^2 R^2 * (sphere average of w(L))   (pbrt-v4 ImageInfiniteLight::Phi)
// Each emissive mesh is one group of the selection's first step, every other light its own.
//
// The concepts live in their own files: the list (light_set.cpp), selection (light_selection.h),
// sampling per kind (light_sampling.h, with LightSet::sample and sample_selected in
// light_sampling.cpp), and emission for light paths (light_emission.cpp).
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "engine/envmap.h"
#include "engine/lights/light_sampling.h"
#include "engine/lights/light_selection.h"
#include "engine/scene.h"

namespace rf {

class Accel;

// When a light is sampled: the frame's BVH and the shutter position (Ray::time) of the path
// asking. Only moving emitters (area lights on deforming meshes, which moving instances' emitters
// become: prepare_instances) read it: their triangle at that time is the frame's (Accel::
// triangle_at), so a light sample lies on the surface the path's rays meet. A scene whose
// emitters stand still may pass none.
struct LightTime {
  const Accel* accel = nullptr;
  float time = 0;
};

// A light path's first vertex (light tracing): a point on a light and a direction leaving it.
struct EmissionSample {
  Vec3 p, p_error, n;    // point, its error bound, unit normal (area lights; the axis otherwise)
  Vec3 dir;              // unit direction the light travels
  RGB beta;              // Le cos / (pdf_select pdf_pos pdf_dir): the path's initial throughput
  RGB radiance;          // Le(p, dir) for area lights (the vertex's own emission towards dir)
  float pdf_pos = 0;     // area density of p, including the selection probability
  float pdf_dir = 0;     // solid-angle density of dir leaving p
  bool is_area = false;  // p lies on a surface (can be seen by the camera)
  bool is_infinite = false;  // directional, environment: p is on a disk outside the scene
  uint32_t mesh = 0, prim = 0;
  uint32_t light = 0;  // which light (the numbering above)
};

class LightSet {
 public:
  // Throws std::runtime_error when the environment map cannot be read.
  explicit LightSet(const Scene& scene);

  bool empty() const { return size() == 0; }
  size_t size() const { return kinds_.size(); }
  size_t area_light_count() const { return area_.size(); }
  // Whether some area light is an exact sphere (the others are triangles).
  bool has_area_spheres() const { return area_spheres_; }
  // Whether some area light moves (lies on a deforming mesh): its samples need a LightTime.
  bool has_moving_area_lights() const { return moving_; }
  LightKind kind(size_t light) const { return kinds_[light]; }
  // Light index of Scene::lights[k], and of the environment (only when has_environment()).
  size_t scene_light_index(size_t k) const { return area_.size() + k; }
  size_t environment_index() const { return area_.size() + punctual_.size(); }
  // Area light i < area_light_count(): its primitive and its mesh's emission.
  const AreaLight& area_light(size_t i) const { return area_[i]; }
  const Emission& area_emission(size_t i) const { return *scene_.meshes[area_[i].mesh].emission; }
  // Area light i as the lane kernels take a triangle (not a sphere, not a moving one).
  TriangleLight triangle_light(size_t i) const {
    const AreaLight& t = area_[i];
    return {t.p0, t.p1, t.p2, t.n, t.area, selection_.pmf(i), area_emission(i)};
  }

  // How lights are selected (light_selection.h).
  const LightSelection& selection() const { return selection_; }
  static constexpr size_t kAutoBvhLights = LightSelection::kAutoBvhLights;
  bool uses_bvh() const { return selection_.uses_bvh(); }
  const LightBvh& bvh() const { return selection_.bvh(); }
  // The probability of selecting each light by power (sums to 1 over size() lights):
  // sample_by_power, sample_emission, and sample() without the BVH.
  float selection_pmf(size_t light) const { return selection_.pmf(light); }
  // The power (Phi above) the selection is proportional to.
  double selection_power(size_t light) const { return selection_.power(light); }
  // The probability that sample() picks `light` from (p, n).
  float selection_pmf_at(size_t light, Vec3 p, Vec3 n) const {
    return selection_.pmf_at(light, p, n);
  }
  // The light sample() picks for (p, n) (LightSelection::pick).
  bool pick(Vec3 p, Vec3 n, float u_select, Vec2& u_point, size_t& light, float& pmf) const {
    return selection_.pick(p, n, u_select, u_point, light, pmf);
  }

  // Samples a light point as seen from p; false when nothing can be sampled (pdf 0, outside a
  // spot's cone, a one-sided emitter seen from behind). n: the unit normal of the hemisphere
  // light can arrive from at p (a surface that only reflects, turned to the side of the outgoing
  // direction), or zero; only the BVH selection uses it. pick() followed by sample_selected().
  // `at`: when (LightTime), for moving emitters.
  bool sample(Vec3 p, Vec3 n, float u_select, Vec2 u_point, LightSample& ls,
              const LightTime& at = {}) const;
  // Point sampling of light i once it is selected with probability pmf.
  bool sample_selected(size_t i, float pmf, Vec3 p, Vec2 u_point, LightSample& ls,
                       const LightTime& at = {}) const;
  // The same with selection by power alone, whatever the mode (BDPT's s = 1 connections).
  bool sample_by_power(Vec3 p, Vec2 u_point, LightSample& ls, const LightTime& at = {}) const;
  // Whether light i is a sphere that p sees from outside, with its cone.
  bool sphere_cone_of(size_t i, Vec3 p, SphereCone& c) const {
    return i < area_.size() && rf::sphere_cone_of(area_[i], area_emission(i), p, c);
  }
  // Samples Scene::lights[k] (point, spot, directional) as seen from p, without selection: the
  // estimator f * radiance * |cos| is then exact for that light (Whitted's "delta lights exactly").
  bool sample_delta_light(size_t k, Vec3 p, LightSample& ls) const;
  size_t delta_light_count() const { return punctual_.size(); }
  // Solid-angle pdf of sampling light point `on_light` (triangle mesh/prim) from (p, n), as
  // sample() would, including selection; 0 when that triangle is not a light.
  float pdf_solid_angle(Vec3 p, Vec3 n, uint32_t mesh, uint32_t prim, Vec3 on_light, Vec3 n_light,
                        const LightTime& at = {}) const;
  // Light index of triangle prim of mesh, or ~0u when that triangle is not a light.
  uint32_t area_light_index(uint32_t mesh, uint32_t prim) const;

  // Emission for light paths (light_emission.cpp). Samples the start of a light path: a light by
  // power, a point on it, a direction (area: cosine-weighted about the emitting side, both sides
  // for two-sided; point: uniform sphere; spot: uniform in its cone). False when the picked light
  // cannot emit.
  // Directional and environment lights have no emission position of their own. With
  // `infinite_lights` they start as pbrt-v4 starts them: a direction (the light's; the
  // environment's by its importance map, pdf_dir its solid-angle density), and a point uniform
  // on the disk of the scene's bounding radius R perpendicular to it, R outside the bounding
  // sphere on the light's side (pdf_pos 1 / (pi R^2) times the selection probability): every
  // ray of that parallel beam that can reach the scene starts on the disk, so the beam carries
  // the light's whole flux into it. Without it (BDPT, whose MIS weights give such lights only
  // the camera-side strategies) a pick of one is false.
  // The light is picked by u_pos.x (LightSelection::select), which is then rescaled for the point.
  bool sample_emission(Vec2 u_pos, Vec2 u_dir, EmissionSample& es, bool infinite_lights = false,
                       const LightTime& at = {}) const;
  // The densities with which sample_emission() starts a light path at a point of `light` (normal
  // n for area lights) leaving in unit direction dir (BDPT's MIS weights): pdf_pos the area
  // density of the point including selection (point and spot lights: the selection
  // probability), pdf_dir the solid-angle density of dir (0 outside a spot's cone or behind a
  // one-sided emitter). Both 0 for directional and environment lights, on which BDPT (the only
  // caller) never starts paths.
  void pdf_emission(uint32_t light, Vec3 n, Vec3 dir, float& pdf_pos, float& pdf_dir,
                    const LightTime& at = {}) const;

  bool has_environment() const { return env_ != nullptr; }
  // Radiance arriving from world direction dir (unit) at infinity; black without environment.
  RGB environment_radiance(Vec3 dir_world) const;
  // Solid-angle pdf of sample() choosing the environment and producing dir_world, including the
  // selection probability (for MIS when a BSDF ray escapes); 0 without environment.
  float pdf_environment(Vec3 dir_world) const;

  // Bounding sphere of the meshes (centre 0, radius 1 when there are none).
  Vec3 scene_center() const { return center_; }
  float scene_radius() const { return radius_; }

 private:
  // Area light i at `at`: a moving one's triangle, normal and area then (Accel::triangle_at);
  // RF_CHECKs that a moving one is given its time.
  AreaLight area_at(size_t i, const LightTime& at) const;
  // The bounds of each light with a position (light_bvh.h), positioned[i] false for the others; a
  // moving area light's over all its keys, its normals in every direction.
  std::vector<LightBounds> bounds(std::vector<bool>& positioned) const;
  // A light path of an infinite light travelling along unit `dir`: its start on the disk
  // (sample_emission), with pdf_pos including the selection probability pmf.
  void start_on_disk(Vec3 dir, Vec2 u, float pmf, EmissionSample& es) const;

  const Scene& scene_;
  Vec3 center_{0.0f};
  float radius_ = 1;
  std::vector<AreaLight> area_;
  std::vector<PunctualLight> punctual_;
  std::unique_ptr<EnvironmentMap> env_;
  std::vector<LightKind> kinds_;
  std::vector<uint32_t> mesh_first_light_;  // per mesh: index of its first light triangle or ~0
  bool area_spheres_ = false;
  bool moving_ = false;
  LightSelection selection_;
};

}  // namespace rf
