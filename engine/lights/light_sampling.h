// Sampling a light once it is selected, kind by kind, and the emission a light point sends.
//
// Kinds: area lights (every triangle of a mesh with an emission is one light, sampled uniformly
// by area; an emissive exact sphere is one light, sampled from outside uniformly in the cone of
// directions it subtends, from inside uniformly by area), point, spot and directional lights
// (Scene::lights; delta distributions), and the environment (Scene::environment, see envmap.h).
// Which light is sampled is light_selection.h's; the list of lights is light_set.h's.
//
// The triangle and sphere-cone kernels here have no branches and call no library function
// (sin_cos_quarter_pi, cos_sin_turn), and their operations are exact IEEE ones (no FMA
// contraction): the path tracer's lane loops (integrators/path/surface_lanes.cpp) run them over
// many shading points in vectorised loops and get the bits the one-vertex code gets.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "engine/accel.h"
#include "engine/math.h"
#include "engine/sampling.h"
#include "engine/scene.h"
#include "engine/shapes.h"

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
  uint32_t light = 0;         // which light (LightSet's numbering)
};

enum class LightKind : uint8_t { Area, Point, Spot, Directional, Environment };

// Radiance an emitter sends in direction w (world) from a point with geometric normal ng.
// (Black as +0 through a bit mask rather than a branch: the lanes' loops run it, and GCC 12
// does not vectorise the select of flags a branch here turns is_black(radiance) into.)
inline RGB emitted_radiance(const Emission& e, Vec3 ng, Vec3 w) {
  uint32_t keep = e.two_sided || !(dot(ng, w) <= 0) ? ~0u : 0u;
  auto masked = [keep](float v) { return bits_float(float_bits(v) & keep); };
  return {masked(e.radiance.x), masked(e.radiance.y), masked(e.radiance.z)};
}
// Radiance a surface point of `mesh` emits in direction w (world), given its geometric normal.
inline RGB emitted_radiance(const Mesh& mesh, Vec3 ng, Vec3 w) {
  return mesh.emission ? emitted_radiance(*mesh.emission, ng, w) : RGB(0.0f);
}

// An area light's primitive: a triangle, or a whole exact sphere (prim 0).
struct AreaLight {
  uint32_t mesh, prim;
  float area;
  const SphereShape* sphere;  // nullptr for a triangle
  Vec3 p0, p1, p2, n;         // a triangle's vertices and unit normal (copied: no index lookup)
  bool moves = false;         // on a deforming mesh: the above is its first key (LightSet::at)
};

// Point, spot and directional lights.
struct PunctualLight {
  LightType type;
  Vec3 position, direction;  // direction: spot axis / direction the light travels
  RGB intensity;             // I (point, spot) or E (directional)
  float cos_falloff_start, cos_falloff_end;
};

// A triangle light as the lane kernels take it: vertices, unit normal, area, selection
// probability and emission.
struct TriangleLight {
  Vec3 p0, p1, p2, n;
  float area = 0, pmf = 0;
  Emission emission;
};

// A sphere light seen from outside, whose light samples are directions uniform in the cone it
// subtends (pbrt-v4 Sphere::Sample): its centre, pole (the normal sphere_point gives its
// centre), radius, emission, and the cone as seen from p (sin^2 and cos of the half-angle,
// 1 - cos in a form that does not cancel).
struct SphereCone {
  Vec3 center, pole;
  float radius = 0, sin2_max = 0, cos_max = 0, one_minus_cos_max = 0;
  Emission emission;
};

// The end of every light sample: a sample that succeeded with a non-black radiance, its density
// times the selection probability pmf, finite and positive.
// (Selects, no early return: it runs in the lanes' vectorised loops.)
[[gnu::always_inline]] inline bool with_selection(bool ok, float pmf, LightSample& ls) {
  bool good = ok & !is_black(ls.radiance);
  float pdf = pmf * ls.pdf_solid_angle;
  ls.pdf_solid_angle = good ? pdf : ls.pdf_solid_angle;
  return good & std::isfinite(pdf) & (pdf > 0);
}

// A uniform point of a triangle (density 1 / area) and its error bound.
[[gnu::always_inline]] inline void triangle_point(Vec3 p0, Vec3 p1, Vec3 p2, Vec2 u, Vec3& q,
                                                  Vec3& q_error) {
  Vec2 b = sample_uniform_triangle(u);
  float b2 = 1.0f - b.x - b.y;
  q = b.x * p0 + b.y * p1 + b2 * p2;
  constexpr float g7 = 7 * std::numeric_limits<float>::epsilon() * 0.5f;
  q_error = g7 * (abs(b.x * p0) + abs(b.y * p1) + abs(b2 * p2));
}

// Once ls holds a uniform point of an area light's surface (p, p_error, n): its direction and
// distance from p, radiance and solid-angle density (without selection).
[[gnu::always_inline]] inline bool area_point_seen_from(Vec3 p, float area, const Emission& e,
                                                        LightSample& ls) {
  Vec3 d = ls.p - p;
  float dist2 = length_sq(d);
  ls.distance = std::sqrt(dist2);
  ls.wi = d / ls.distance;
  float cos_light = std::fabs(dot(ls.n, ls.wi));
  ls.radiance = emitted_radiance(e, ls.n, -ls.wi);
  ls.pdf_solid_angle = dist2 / (area * cos_light);
  return (dist2 > 0) & (area > 0) & (cos_light > 0);  // no early return: see with_selection
}

// A triangle light sampled from p: a uniform point, its area density converted to solid angle
// (without selection), the radiance it sends towards p.
[[gnu::always_inline]] inline bool sample_triangle_area(Vec3 p0, Vec3 p1, Vec3 p2, Vec3 n,
                                                        float area, const Emission& e, Vec3 p,
                                                        Vec2 u, LightSample& ls) {
  triangle_point(p0, p1, p2, u, ls.p, ls.p_error);
  ls.n = n;
  return area_point_seen_from(p, area, e, ls);
}
// The same with the selection probability (LightSet::sample of a triangle, bit for bit).
[[gnu::always_inline]] inline bool sample_triangle(const TriangleLight& t, Vec3 p, Vec2 u,
                                                   LightSample& ls) {
  bool ok = sample_triangle_area(t.p0, t.p1, t.p2, t.n, t.area, t.emission, p, u, ls);
  return with_selection(ok, t.pmf, ls);
}

// The cone a sphere (centre, radius) subtends from p: sin^2 and cos of its half-angle and 1 -
// cos, with the small-angle form of 1 - cos where it would cancel; true when p is outside.
// Without branches (the path tracer's lanes compute it in a loop). The three numbers are written
// on false too, meaningless then (every caller drops them).
[[gnu::always_inline]] inline bool sphere_cone(Vec3 center, float radius, Vec3 p, float& sin2_max,
                                               float& cos_max, float& one_minus_cos_max) {
  const float dc2 = length_sq(center - p), r2 = sqr(radius);
  const bool outside = dc2 > r2 * 1.0001f;
  sin2_max = r2 / dc2;
  cos_max = safe_sqrt(1.0f - sin2_max);
  one_minus_cos_max = sin2_max < 0.00068523f ? 0.5f * sin2_max : 1.0f - cos_max;
  return outside & (one_minus_cos_max > 0);
}
// A sphere's sample from outside is sphere_cone_angles(), sphere_cone_point() and
// with_selection(). The angles: between the axis back to p and the sampled point, at the centre,
// as cosine and sine, and phi about the axis, as its cosine and sine.
[[gnu::always_inline]] inline void sphere_cone_angles(float sin2_max, float cos_max, Vec2 u,
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
[[gnu::always_inline]] inline bool sphere_cone_point(const SphereCone& c, Vec3 p, float cos_alpha,
                                                     float sin_alpha, float cos_phi, float sin_phi,
                                                     LightSample& ls) {
  Frame f = Frame::from_normal(normalize(c.center - p));
  Vec3 n = f.to_world({sin_alpha * cos_phi, sin_alpha * sin_phi, -cos_alpha});
  sphere_point(c.center, c.radius, c.pole, c.center + n * c.radius, ls.p, ls.p_error, ls.n);
  Vec3 d = ls.p - p;
  float dist2 = length_sq(d);
  ls.distance = std::sqrt(dist2);
  ls.wi = d / ls.distance;
  ls.radiance = emitted_radiance(c.emission, ls.n, -ls.wi);
  ls.pdf_solid_angle = 1.0f / (2 * kPi * c.one_minus_cos_max);
  return dist2 > 0;
}

// Whether an area light is a sphere that p sees from outside, with its cone.
bool sphere_cone_of(const AreaLight& light, const Emission& e, Vec3 p, SphereCone& c);

// A uniformly distributed point of an area light's primitive (density 1 / area), its error bound
// and its unit normal (outward for spheres).
// Inlined into its callers (a call per light sample, with three vectors returned through memory).
[[gnu::always_inline]] inline void sample_area_surface(const AreaLight& light, Vec2 u, Vec3& q,
                                                       Vec3& q_error, Vec3& n) {
  if (light.sphere) {
    sphere_surface_point(*light.sphere, light.sphere->center + sample_uniform_sphere(u), q, q_error,
                         n);
    return;
  }
  triangle_point(light.p0, light.p1, light.p2, u, q, q_error);
  n = light.n;
}

// An area light sampled from p: spheres seen from outside by a direction uniform in the cone they
// subtend (pbrt-v4), the point where it first meets the sphere computed directly; otherwise a
// uniform point of the primitive, its area density converted to solid angle. pdf_solid_angle
// without selection.
bool sample_area(const AreaLight& light, const Emission& e, Vec3 p, Vec2 u, LightSample& ls);

// A point, spot or directional light as seen from p (a delta distribution: pdf_solid_angle is
// left to the caller). Directional lights put their point 2 scene_radius away along wi.
bool sample_punctual(const PunctualLight& light, float scene_radius, Vec3 p, LightSample& ls);

// pbrt-v4's SmoothStep: 0 at x <= a, 1 at x >= b, 3t^2 - 2t^3 between; a step when a == b (a
// spot's falloff in cos from its cone to its full-strength start).
float smooth_step(float x, float a, float b);

}  // namespace rf
