// The scene format's built-in shapes as meshes (docs/scene-format.md: rectangle, cube, sphere,
// disk), with outward right-hand winding.
#pragma once

#include "engine/math.h"
#include "engine/mesh_io.h"

namespace rf {

// An exact sphere (Embree's sphere primitive; its geometry is below): world-space centre and
// radius, and the unit axes of its parametrisation (uv and the pole are those of make_sphere:
// the pole along axis[1], phi from axis[0] towards -axis[2]). The axes may be left-handed (a
// mirrored sphere); the outward normal is (p - center) / radius either way.
struct SphereShape {
  Vec3 center{0.0f};
  float radius = 1;
  Vec3 axis[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
};

// The square [-1, 1]^2 in the z = 0 plane, normal +z.
MeshData make_rectangle();
// The cube [-1, 1]^3, four vertices per face so uvs are per face.
MeshData make_cube();
// A UV sphere of centre c and radius r: n_theta rows from the north pole (+y), n_phi columns,
// 2 n_theta n_phi - 2 n_phi triangles, unit vertex normals, uv = (phi / 2pi, 1 - theta / pi).
MeshData make_sphere(Vec3 c, float r, int n_theta, int n_phi);
// The unit disk in the z = 0 plane, normal +z, as a fan of `segments` triangles.
MeshData make_disk(int segments);

// Exact spheres (SphereShape, above).
//
// The sphere of centre c and radius r placed by to_world with its parametrisation axes `axes`
// (object space; make_sphere's are x, y, z), when to_world is a similarity (rotation, uniform
// scale, translation, possibly mirrored: the linear part's columns orthogonal and of equal length
// within 1e-5 relative). False otherwise: a sheared or unevenly scaled sphere is an ellipsoid and
// stays a mesh.
bool place_sphere(Vec3 c, float r, const Vec3 axes[3], const Mat4& to_world, SphereShape& out);
// The sphere as a UV mesh in world space (n_theta x n_phi as make_sphere, same uvs): for
// placements that are not similarities.
MeshData tessellate_sphere(const SphereShape& s, int n_theta, int n_phi);
// The default tessellation of a sphere that cannot stay exact (n_theta x n_phi): its worst-case
// distance to the true sphere is r (1 - cos(pi / 128)) = 3e-4 r.
inline constexpr int kSphereThetaSteps = 64, kSpherePhiSteps = 128;
// A point near the sphere projected onto it, with its error bound (pbrt-v4's gamma(5) |p|), the
// outward unit normal and, when uv is given, the uv of make_sphere's parametrisation (an acos and
// an atan2: light samples, which need no uv, pass nullptr).
void sphere_surface_point(const SphereShape& s, Vec3 near, Vec3& p, Vec3& p_error, Vec3& n,
                          Vec2* uv = nullptr);
// The same without uv, from the sphere's centre, radius and pole axis (the normal where `near` is
// the centre), without branches: the path tracer's lanes run it in loops that vectorise.
[[gnu::always_inline]] inline void sphere_point(Vec3 center, float radius, Vec3 pole, Vec3 near,
                                                Vec3& p, Vec3& p_error, Vec3& n) {
  Vec3 d = near - center;
  float len = length(d);
  n = vselect(len > 0, d / len, pole);
  p = center + radius * n;
  // Projecting onto the sphere is a few operations on p (pbrt-v4 Sphere: gamma(5) |p|), and the
  // centre's addition adds its own rounding.
  constexpr float eps = std::numeric_limits<float>::epsilon() * 0.5f;
  constexpr float g5 = 5 * eps / (1 - 5 * eps);
  p_error = g5 * (abs(p) + abs(center) + Vec3(radius));
}

}  // namespace rf
