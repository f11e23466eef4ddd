#include "engine/shapes.h"

#include <cmath>

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

}  // namespace rf
