// Lights and light selection for next-event estimation.
//
// Kinds: area lights (every triangle of a mesh with an emission is one light, sampled uniformly
// by area; an emissive exact sphere is one light, sampled from outside uniformly in the cone of
// directions it subtends, from inside uniformly by area), point, spot and directional lights
// (Scene::lights; delta distributions), and the environment (Scene::environment, see envmap.h).
//
// Numbering (selection_pmf, LightSample::light): area primitives first, mesh by mesh, then
// Scene::lights in order, then the environment last.
//
// Selection: one light is picked with probability proportional to its power, measured by the
// selection weight w(c) = luminance(c) (the largest component when that is 0 but c is not black,
// so every light that emits can be chosen). R is the radius of the bounding sphere of the scene's
// meshes (1 if there are none):
//   area triangle  Phi = pi * A * w(Le) * (2 if two-sided)      (Lambertian emitter)
//   sphere         the same with A = 4 pi r^2
//   point          Phi = 4 pi * w(I)
//   spot           Phi = 2 pi * w(I) * (1 - (cos_start + cos_end) / 2)   (pbrt-v4 SpotLight::Phi;
//                  exact, since the smoothstep falloff integrates to half its width in cos)
//   directional    Phi = pi R^2 * w(E)          (the flux through the scene's bounding disk)
//   environment    Phi = pi R^2 * integral over the sphere of w(L(w)) dw
//                      = 4 pi^2 R^2 * (sphere average of w(L))   (pbrt-v4 ImageInfiniteLight::Phi)
// The pick is made in two steps with the same probabilities, both by the first coordinate of the
// 2D point sample (Mitsuba's sample reuse): it picks a group (an emissive mesh, or one other light)
// by its power and is rescaled to [0, 1) within the group's interval, then picks the triangle of
// the mesh by its power and is rescaled again within that triangle's interval. So a stratified 2D
// sample stays stratified over each light and over the whole emitting mesh (a quad light's two
// triangles), where a separate 1D pick would hand each light a random subset of the points
// (more squared error on veach-mis's three spheres; docs/performance.md, "Many lights: the light
// BVH").
// If every power is 0 (say, only zero-area triangles), lights are picked uniformly.
//
// Selection that sees the shading point (RenderSettings::light_selection, "bvh", or "auto" with
// more than kAutoBvhLights lights that have a position): a light BVH (light_bvh.h) over the area
// primitives, point and spot lights picks one by an importance bound at the shading point; the
// infinite lights (directional, environment) keep their power share. The set of all BVH lights is
// chosen with the sum of their power pmfs, so pdf_environment() is the same in both modes. With
// the BVH the two-step reuse of u_point.x does not apply: each primitive is its own light, picked
// by the separate u_select (which power selection leaves unread).
// Light tracing, BDPT's light subpaths and its s = 1 connections stay power-based
// (sample_by_power, pdf_emission), whose MIS weights need a pmf that does not depend on a point.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "engine/accel.h"
#include "engine/envmap.h"
#include "engine/light_bvh.h"
#include "engine/sampling.h"
#include "engine/scene.h"
#include "engine/shapes.h"
#include "engine/simd.h"

namespace rf {

// One light sample as seen from a shading point. For every kind the estimator of the light's
// contribution is f * radiance * |cos| / pdf_solid_angle (times visibility).
struct LightSample {
  Vec3 p, p_error, n;         // point on the light, its error bound and unit normal (-wi if none)
  RGB radiance;               // area/environment: emitted radiance; point/spot: I / r^2;
                              // directional: irradiance E (all towards the shading point)
  Vec3 wi;                    // unit direction from the shading point to the light
  float distance = 0;         // |p - shading point| (2R for infinite lights)
  float pdf_solid_angle = 0;  // including the selection probability; for a delta light this is
                              // a probability mass (the selection probability)
  bool is_delta = false;      // point, spot, directional: MIS must not weight against BSDFs
  bool is_infinite = false;   // directional, environment: visibility is a ray to infinity along
                              // wi; p is the shading point + wi * 2R, beyond every mesh when
                              // the shading point is inside the scene's bounding sphere
  uint32_t light = 0;         // which light (the numbering above)
};

enum class LightKind : uint8_t { Area, Point, Spot, Directional, Environment };

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
  size_t area_light_count() const { return tris_.size(); }
  LightKind kind(size_t light) const { return kinds_[light]; }
  // Light index of Scene::lights[k], and of the environment (only when has_environment()).
  size_t scene_light_index(size_t k) const { return tris_.size() + k; }
  size_t environment_index() const { return tris_.size() + punctual_.size(); }

  // More lights with a position than this make "auto" selection use the BVH.
  static constexpr size_t kAutoBvhLights = 8;

  // Samples a light point as seen from p; false when nothing can be sampled (pdf 0, outside a
  // spot's cone, a one-sided emitter seen from behind). n: the unit normal of the hemisphere
  // light can arrive from at p (a surface that only reflects, turned to the side of the outgoing
  // direction), or zero; only the BVH selection uses it.
  bool sample(Vec3 p, Vec3 n, float u_select, Vec2 u_point, LightSample& ls) const;
  // sample() in two steps: pick() finds the light it picks for (p, n), its selection
  // probability, and u_point as sample_selected() then takes it (rescaled by a pick by power);
  // false when nothing can be picked. sample() is pick() followed by sample_selected().
  bool pick(Vec3 p, Vec3 n, float u_select, Vec2& u_point, size_t& light, float& pmf) const;
  // Point sampling of light i once it is selected with probability pmf.
  bool sample_selected(size_t i, float pmf, Vec3 p, Vec2 u_point, LightSample& ls) const;

  // A sphere light seen from outside, whose light samples are directions uniform in the cone it
  // subtends (pbrt-v4 Sphere::Sample): its centre, pole (the normal sphere_point gives its
  // centre), radius, emission, and the cone as seen from p (sin^2 and cos of the half-angle,
  // 1 - cos in a form that does not cancel).
  struct SphereCone {
    Vec3 center, pole;
    float radius = 0, sin2_max = 0, cos_max = 0, one_minus_cos_max = 0;
    Emission emission;
  };
  // Whether light i is a sphere that p sees from outside, with its cone.
  bool sphere_cone_of(size_t i, Vec3 p, SphereCone& c) const;
  // The cone a sphere (centre, radius) subtends from p: sin^2 and cos of its half-angle and 1 -
  // cos, with the small-angle form of 1 - cos where it would cancel; true when p is outside.
  // Without branches (the path tracer's lanes compute it in a loop); sphere_cone_of's numbers.
  // The three numbers are written on false too, meaningless then (every caller drops them).
  [[gnu::always_inline]] static bool sphere_cone(Vec3 center, float radius, Vec3 p, float& sin2_max,
                                                 float& cos_max, float& one_minus_cos_max) {
    const float dc2 = length_sq(center - p), r2 = sqr(radius);
    const bool outside = dc2 > r2 * 1.0001f;
    sin2_max = r2 / dc2;
    cos_max = safe_sqrt(1.0f - sin2_max);
    one_minus_cos_max = sin2_max < 0.00068523f ? 0.5f * sin2_max : 1.0f - cos_max;
    return outside & (one_minus_cos_max > 0);
  }
  // sample_selected() of such a light is sphere_cone_angles(), sphere_cone_point() and
  // with_selection(): steps without branches or library calls, so that the path tracer's lanes
  // run them in loops that vectorise and get the bits sample() gets. The angles: between the axis
  // back to p and the sampled point, at the centre, as cosine and sine, and phi about the axis,
  // as its cosine and sine.
  [[gnu::always_inline]] static void sphere_cone_angles(float sin2_max, float cos_max, Vec2 u,
                                                        float& cos_alpha, float& sin_alpha,
                                                        float& cos_phi, float& sin_phi) {
    float cos_t = (cos_max - 1.0f) * u.x + 1.0f, sin2_t = 1.0f - cos_t * cos_t;
    // A small cone: sin^2 is uniform to first order.
    const bool small = sin2_max < 0.00068523f;
    float sin2_small = sin2_max * u.x;
    float cos_small = std::sqrt(1.0f - sin2_small);
    sin2_t = small ? sin2_small : sin2_t;
    cos_t = small ? cos_small : cos_t;
    float sin_max = std::sqrt(sin2_max);
    cos_alpha = sin2_t / sin_max + cos_t * safe_sqrt(1.0f - sin2_t / sin2_max);
    sin_alpha = safe_sqrt(1.0f - cos_alpha * cos_alpha);
    cos_sin_turn(u.y, cos_phi, sin_phi);  // phi = 2 pi u.y
  }
  // The sampled point, its direction and distance from p, radiance and solid-angle density
  // (without selection).
  [[gnu::always_inline]] static bool sphere_cone_point(const SphereCone& c, Vec3 p, float cos_alpha,
                                                       float sin_alpha, float cos_phi,
                                                       float sin_phi, LightSample& ls) {
    Frame f = Frame::from_normal(normalize(c.center - p));
    Vec3 n = f.to_world({sin_alpha * cos_phi, sin_alpha * sin_phi, -cos_alpha});
    sphere_point(c.center, c.radius, c.pole, c.center + n * c.radius, ls.p, ls.p_error, ls.n);
    Vec3 d = ls.p - p;
    float dist2 = length_sq(d);
    ls.distance = std::sqrt(dist2);
    ls.wi = d / ls.distance;
    ls.radiance = emitted(c.emission, ls.n, -ls.wi);
    ls.pdf_solid_angle = 1.0f / (2 * kPi * c.one_minus_cos_max);
    return dist2 > 0;
  }
  // The same with selection by power alone, whatever the mode (BDPT's s = 1 connections).
  bool sample_by_power(Vec3 p, Vec2 u_point, LightSample& ls) const;
  // True when sample() picks lights with the BVH.
  bool uses_bvh() const { return !bvh_.empty(); }
  const LightBvh& bvh() const { return bvh_; }
  // Samples Scene::lights[k] (point, spot, directional) as seen from p, without selection: the
  // estimator f * radiance * |cos| is then exact for that light (Whitted's "delta lights exactly").
  bool sample_delta_light(size_t k, Vec3 p, LightSample& ls) const;
  size_t delta_light_count() const { return punctual_.size(); }
  // Samples the start of a light path: a light by power, a point on it, a direction (area:
  // cosine-weighted about the emitting side, both sides for two-sided; point: uniform sphere;
  // spot: uniform in its cone). False when the picked light cannot emit.
  // Directional and environment lights have no emission position of their own. With
  // `infinite_lights` they start as pbrt-v4 starts them: a direction (the light's; the
  // environment's by its importance map, pdf_dir its solid-angle density), and a point uniform
  // on the disk of the scene's bounding radius R perpendicular to it, R outside the bounding
  // sphere on the light's side (pdf_pos 1 / (pi R^2) times the selection probability): every
  // ray of that parallel beam that can reach the scene starts on the disk, so the beam carries
  // the light's whole flux into it. Without it (BDPT, whose MIS weights give such lights only
  // the camera-side strategies) a pick of one is false.
  // The light is picked by u_pos.x (select()), which is then rescaled for the point.
  bool sample_emission(Vec2 u_pos, Vec2 u_dir, EmissionSample& es,
                       bool infinite_lights = false) const;
  // Solid-angle pdf of sampling light point `on_light` (triangle mesh/prim) from (p, n), as
  // sample() would, including selection; 0 when that triangle is not a light.
  float pdf_solid_angle(Vec3 p, Vec3 n, uint32_t mesh, uint32_t prim, Vec3 on_light,
                        Vec3 n_light) const;
  // The probability that sample() picks `light` from (p, n).
  float selection_pmf_at(size_t light, Vec3 p, Vec3 n) const;
  // Light index of triangle prim of mesh, or ~0u when that triangle is not a light.
  uint32_t area_light_index(uint32_t mesh, uint32_t prim) const;
  // The densities with which sample_emission() starts a light path at a point of `light` (normal
  // n for area lights) leaving in unit direction dir (BDPT's MIS weights): pdf_pos the area
  // density of the point including selection (point and spot lights: the selection
  // probability), pdf_dir the solid-angle density of dir (0 outside a spot's cone or behind a
  // one-sided emitter). Both 0 for directional and environment lights, on which BDPT (the only
  // caller) never starts paths.
  void pdf_emission(uint32_t light, Vec3 n, Vec3 dir, float& pdf_pos, float& pdf_dir) const;
  // Probability of selecting each light by power (sums to 1 over size() lights): sample_by_power,
  // sample_emission, and sample() without the BVH.
  float selection_pmf(size_t light) const { return pmf_[light]; }
  // The power (Phi above) the selection is proportional to.
  double selection_power(size_t light) const { return power_[light]; }

  bool has_environment() const { return env_ != nullptr; }
  // Radiance arriving from world direction dir (unit) at infinity; black without environment.
  RGB environment_radiance(Vec3 dir_world) const;
  // Solid-angle pdf of sample() choosing the environment and producing dir_world, including the
  // selection probability (for MIS when a BSDF ray escapes); 0 without environment.
  float pdf_environment(Vec3 dir_world) const;

  // Bounding sphere of the meshes (centre 0, radius 1 when there are none).
  Vec3 scene_center() const { return center_; }
  float scene_radius() const { return radius_; }

  // Radiance a surface point of `mesh` emits in direction w (world), given its geometric normal.
  static RGB emitted(const Mesh& mesh, Vec3 ng, Vec3 w) {
    return mesh.emission ? emitted(*mesh.emission, ng, w) : RGB(0.0f);
  }
  // (Black as +0 through a bit mask rather than a branch: the lanes' loops run it, and GCC 12
  // does not vectorise the select of flags a branch here turns is_black(radiance) into.)
  static RGB emitted(const Emission& e, Vec3 ng, Vec3 w) {
    uint32_t keep = e.two_sided || !(dot(ng, w) <= 0) ? ~0u : 0u;
    auto masked = [keep](float v) { return bits_float(float_bits(v) & keep); };
    return {masked(e.radiance.x), masked(e.radiance.y), masked(e.radiance.z)};
  }

  // For kernels that sample lights for many shading points at once (the path tracer's lanes,
  // whose loops vectorise): when every light is a triangle picked by power (no light BVH, no
  // sphere, point or infinite light), triangles_by_power() is true and sample() is
  // pick_triangle() followed by sample_triangle() with the same numbers, bit for bit.
  struct TriangleLight {
    Vec3 p0, p1, p2, n;  // vertices and unit normal
    float area = 0, pmf = 0;
    Emission emission;
  };
  bool triangles_by_power() const { return triangles_by_power_; }
  // The light that u_point.x (ux) picks, with ux rescaled (select()); false when nothing can be
  // picked. Only when triangles_by_power().
  bool pick_triangle(float& ux, TriangleLight& light) const;
  // pick_triangle() for lanes j < n, one after another: light[j] the picked light's index
  // (kNoPick when nothing can be picked) and ux[j] rescaled; triangle_light(light[j]) is then its
  // light.
  static constexpr int kPickLanes = 16;
  static constexpr uint32_t kNoPick = ~0u;
  void pick_triangles(float* ux, int n, uint32_t* light) const;
  // When the lights are one emissive mesh of 2 to kPickLanes triangles, none of zero probability
  // (pick_in_lanes(), the Cornell box's light), pick_triangle() for kPickLanes lanes at once in a
  // vectorised loop, in place: ux[j] rescaled and entry[j] the picked light's entry in
  // pick_table(), the light first + entry[j], bit for bit pick_triangle's numbers.
  bool pick_in_lanes() const { return pick_in_lanes_; }
  void pick_entries(float* ux, uint32_t* entry) const;
  // Those lights as lane arrays, entry k < count holding triangle_light(first + k)'s numbers, so
  // loops over lanes read a picked light by its entry (LaneSlots' m and lane are unused).
  struct PickTable : LaneSlots<kPickLanes> {
    V3 p0, p1, p2, n, radiance;
    float area[kPickLanes], pmf[kPickLanes];
    int two_sided[kPickLanes];
    int count = 0;  // entries: the mesh's triangles
  };
  const PickTable& pick_table() const { return pick_table_; }
  // When every light is an exact sphere, picked by power among 1 to kPickLanes of them, none of
  // zero probability (spheres_in_lanes(), veach-mis's three), pick() for kPickLanes lanes at once,
  // in place: entry[j] the entry of sphere_table() that ux[j] (u_point.x) picks and ux[j]
  // rescaled, bit for bit pick()'s light (sphere_table().light[entry[j]]) and numbers.
  bool spheres_in_lanes() const { return sphere_table_.count > 0; }
  void pick_sphere_entries(float* ux, uint32_t* entry) const;
  // Those spheres as lane arrays (LaneSlots' m and lane are unused): entry k's light, selection
  // probability, and sphere_cone_of's centre, pole, radius and emission.
  struct SphereTable : LaneSlots<kPickLanes> {
    V3 center, pole, radiance;
    float radius[kPickLanes], pmf[kPickLanes];
    int two_sided[kPickLanes];
    uint32_t light[kPickLanes];
    int count = 0;  // entries: the spheres; 0 when !spheres_in_lanes()
  };
  const SphereTable& sphere_table() const { return sphere_table_; }
  TriangleLight triangle_light(uint32_t i) const {
    const Tri& t = tris_[i];
    return {t.p0, t.p1, t.p2, t.n, t.area, pmf_[i], *scene_.meshes[t.mesh].emission};
  }
  [[gnu::always_inline]] static bool sample_triangle(const TriangleLight& t, Vec3 p, Vec2 u,
                                                     LightSample& ls) {
    bool ok = sample_triangle_area(t.p0, t.p1, t.p2, t.n, t.area, t.emission, p, u, ls);
    return with_selection(ok, t.pmf, ls);
  }
  // The end of sample_selected(): a sample that succeeded with a non-black radiance, its density
  // times the selection probability pmf, finite and positive.
  // (Selects, no early return: it runs in the lanes' vectorised loops.)
  [[gnu::always_inline]] static bool with_selection(bool ok, float pmf, LightSample& ls) {
    bool good = ok & !is_black(ls.radiance);
    float pdf = pmf * ls.pdf_solid_angle;
    ls.pdf_solid_angle = good ? pdf : ls.pdf_solid_angle;
    return good & std::isfinite(pdf) & (pdf > 0);
  }

 private:
  struct Tri {  // an area light's primitive: a triangle, or a whole sphere (prim 0)
    uint32_t mesh, prim;
    float area;
    const SphereShape* sphere;  // nullptr for a triangle
    Vec3 p0, p1, p2, n;         // a triangle's vertices and unit normal (copied: no index lookup)
  };
  struct Group {  // what the first selection step picks: one light, or an emissive mesh
    uint32_t first, count;
  };
  size_t select(float& ux) const;
  // A uniform point of a triangle (density 1 / area) and its error bound.
  [[gnu::always_inline]] static void triangle_point(Vec3 p0, Vec3 p1, Vec3 p2, Vec2 u, Vec3& q,
                                                    Vec3& q_error) {
    Vec2 b = sample_uniform_triangle(u);
    float b2 = 1.0f - b.x - b.y;
    q = b.x * p0 + b.y * p1 + b2 * p2;
    constexpr float g7 = 7 * std::numeric_limits<float>::epsilon() * 0.5f;
    q_error = g7 * (abs(b.x * p0) + abs(b.y * p1) + abs(b2 * p2));
  }
  // sample_area() of a triangle: a uniform point, its area density converted to solid angle as
  // seen from p (without selection), the radiance it sends towards p.
  [[gnu::always_inline]] static bool sample_triangle_area(Vec3 p0, Vec3 p1, Vec3 p2, Vec3 n,
                                                          float area, const Emission& e, Vec3 p,
                                                          Vec2 u, LightSample& ls) {
    triangle_point(p0, p1, p2, u, ls.p, ls.p_error);
    ls.n = n;
    return area_point_seen_from(p, area, e, ls);
  }
  // The rest of sample_area() once ls holds a uniform point of the light's surface (p, p_error,
  // n): its direction and distance from p, radiance and solid-angle density.
  [[gnu::always_inline]] static bool area_point_seen_from(Vec3 p, float area, const Emission& e,
                                                          LightSample& ls) {
    Vec3 d = ls.p - p;
    float dist2 = length_sq(d);
    ls.distance = std::sqrt(dist2);
    ls.wi = d / ls.distance;
    float cos_light = std::fabs(dot(ls.n, ls.wi));
    ls.radiance = emitted(e, ls.n, -ls.wi);
    ls.pdf_solid_angle = dist2 / (area * cos_light);
    return (dist2 > 0) & (area > 0) & (cos_light > 0);  // no early return: see with_selection
  }
  void build_bvh(const std::string& mode);
  void sample_surface(const Tri& tri, Vec2 u, Vec3& q, Vec3& q_error, Vec3& n) const;
  struct Punctual {  // point, spot, directional
    LightType type;
    Vec3 position, direction;  // direction: spot axis / direction the light travels
    RGB intensity;             // I (point, spot) or E (directional)
    float cos_falloff_start, cos_falloff_end;
  };
  bool sample_area(const Tri& tri, Vec3 p, Vec2 u, LightSample& ls) const;
  bool sphere_cone_of(const Tri& tri, Vec3 p, SphereCone& c) const;
  bool sample_punctual(const Punctual& l, Vec3 p, LightSample& ls) const;
  // A light path of an infinite light travelling along unit `dir`: its start on the disk
  // (sample_emission), with pdf_pos including the selection probability pmf.
  void start_on_disk(Vec3 dir, Vec2 u, float pmf, EmissionSample& es) const;

  const Scene& scene_;
  Vec3 center_{0.0f};
  float radius_ = 1;
  std::vector<Tri> tris_;
  std::vector<Punctual> punctual_;
  std::unique_ptr<EnvironmentMap> env_;
  std::vector<LightKind> kinds_;
  std::vector<double> power_;
  std::vector<Group> groups_;
  std::vector<double> cdf_;         // over groups: groups_.size()+1, cdf_[0] = 0, back() = 1
  std::vector<double> within_cdf_;  // per light: cumulative probability within its group
  std::vector<float> pmf_;
  std::vector<uint32_t> mesh_first_light_;  // per mesh: index of its first light triangle or ~0
  // BVH selection (uses_bvh()): the tree over lights with a position, the probability of
  // choosing among them, and the infinite lights with their cumulative power share.
  LightBvh bvh_;
  float bvh_share_ = 0;
  bool triangles_by_power_ = false;
  // pick_entries' case: one group of 2 to 16 lights, none of zero probability.
  bool pick_in_lanes_ = false;
  PickTable pick_table_{};
  SphereTable sphere_table_{};
  std::vector<uint32_t> infinite_;
  std::vector<double> infinite_cdf_;  // infinite_.size() + 1 entries, within the infinite lights
};

}  // namespace rf
