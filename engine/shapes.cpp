#include "engine/shapes.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace rf {

MeshData make_rectangle() {
  MeshData m;
  m.positions = {{-1, -1, 0}, {1, -1, 0}, {1, 1, 0}, {-1, 1, 0}};
  m.uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  m.indices = {0, 1, 2, 0, 2, 3};  // cross(p1 - p0, p2 - p0) points along +z
  return m;
}

// Face with outward normal n = s*e_a spans u = s*e_(a+1), v = e_(a+2), so cross(u, v) = n and
// the corners n-u-v, n+u-v, n+u+v, n-u+v wind counter-clockwise seen from outside.
MeshData make_cube() {
  MeshData m;
  for (int a = 0; a < 3; ++a)
    for (float s : {1.0f, -1.0f}) {
      Vec3 n(0.0f), u(0.0f), v(0.0f);
      n[a] = s, u[(a + 1) % 3] = s, v[(a + 2) % 3] = 1;
      auto base = static_cast<uint32_t>(m.positions.size());
      m.positions.insert(m.positions.end(), {n - u - v, n + u - v, n + u + v, n - u + v});
      m.uvs.insert(m.uvs.end(), {{0, 0}, {1, 0}, {1, 1}, {0, 1}});
      m.indices.insert(m.indices.end(), {base, base + 1, base + 2, base, base + 2, base + 3});
    }
  return m;
}

// Unit-normal UV sphere: rows from the north pole (+y) down; uv = (phi / 2pi, 1 - theta / pi).
MeshData make_sphere(Vec3 c, float r, int n_theta, int n_phi) {
  MeshData m;
  for (int i = 0; i <= n_theta; ++i) {
    float th = kPi * float(i) / float(n_theta);
    for (int j = 0; j <= n_phi; ++j) {  // seam column duplicated so uvs wrap cleanly
      float ph = 2 * kPi * float(j) / float(n_phi);
      Vec3 n(std::sin(th) * std::cos(ph), std::cos(th), -std::sin(th) * std::sin(ph));
      m.positions.push_back(c + r * n);
      m.normals.push_back(n);
      m.uvs.push_back({float(j) / float(n_phi), 1.0f - float(i) / float(n_theta)});
    }
  }
  uint32_t row = uint32_t(n_phi + 1);
  for (int i = 0; i < n_theta; ++i)
    for (int j = 0; j < n_phi; ++j) {
      uint32_t a = uint32_t(i) * row + uint32_t(j), b = a + 1, d = a + row, e = d + 1;
      // phi grows towards -z, so (a, d, b) winds counter-clockwise seen from outside.
      if (i != 0) m.indices.insert(m.indices.end(), {a, d, b});
      if (i != n_theta - 1) m.indices.insert(m.indices.end(), {b, d, e});
    }
  return m;
}

// Unit disk in the z = 0 plane, normal +z, as a fan; uv = polar (r, phi / 2pi).
MeshData make_disk(int segments) {
  MeshData m;
  m.positions.push_back({0, 0, 0});
  m.uvs.push_back({0, 0});
  for (int k = 0; k < segments; ++k) {
    float ph = 2 * kPi * float(k) / float(segments);
    m.positions.push_back({std::cos(ph), std::sin(ph), 0});
    m.uvs.push_back({1, float(k) / float(segments)});
  }
  for (int k = 0; k < segments; ++k)
    m.indices.insert(m.indices.end(), {0u, uint32_t(1 + k), uint32_t(1 + (k + 1) % segments)});
  return m;
}

bool place_sphere(Vec3 c, float r, const Vec3 axes[3], const Mat4& to_world, SphereShape& out) {
  Vec3 col[3] = {to_world.vector({1, 0, 0}), to_world.vector({0, 1, 0}), to_world.vector({0, 0, 1})};
  float len[3] = {length(col[0]), length(col[1]), length(col[2])};
  if (!(len[0] > 0) || !std::isfinite(len[0]) || !(r > 0)) return false;
  constexpr float tol = 1e-5f;
  for (int i = 0; i < 3; ++i) {
    if (std::fabs(len[i] - len[0]) > tol * len[0]) return false;
    for (int j = i + 1; j < 3; ++j)
      if (std::fabs(dot(col[i], col[j])) > tol * len[i] * len[j]) return false;
  }
  out.center = to_world.point(c);
  out.radius = r * len[0];
  for (int i = 0; i < 3; ++i) out.axis[i] = normalize(to_world.vector(axes[i]));
  return std::isfinite(out.radius) && out.radius > 0 && is_finite(out.center);
}

MeshData tessellate_sphere(const SphereShape& s, int n_theta, int n_phi) {
  MeshData m = make_sphere(Vec3(0.0f), 1.0f, n_theta, n_phi);
  auto place = [&](Vec3 v) { return s.axis[0] * v.x + s.axis[1] * v.y + s.axis[2] * v.z; };
  for (Vec3& p : m.positions) p = s.center + s.radius * place(p);
  for (Vec3& n : m.normals) n = normalize(place(n));
  // Left-handed axes mirror the mesh: keep the outward side the front side.
  if (dot(cross(s.axis[0], s.axis[1]), s.axis[2]) < 0)
    for (size_t t = 0; t + 2 < m.indices.size(); t += 3) std::swap(m.indices[t + 1], m.indices[t + 2]);
  return m;
}

void sphere_surface_point(const SphereShape& s, Vec3 near, Vec3& p, Vec3& p_error, Vec3& n,
                          Vec2* uv) {
  sphere_point(s.center, s.radius, s.axis[1], near, p, p_error, n);
  if (!uv) return;
  Vec3 local(dot(n, s.axis[0]), dot(n, s.axis[1]), dot(n, s.axis[2]));
  float theta = std::acos(std::clamp(local.y, -1.0f, 1.0f));
  float phi = std::atan2(-local.z, local.x);
  if (phi < 0) phi += 2 * kPi;
  *uv = {phi / (2 * kPi), 1.0f - theta / kPi};
}

}  // namespace rf
