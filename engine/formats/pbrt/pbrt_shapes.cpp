#include "engine/formats/pbrt/pbrt_shapes.h"

#include <algorithm>
#include <cmath>

namespace rf::pbrt {

namespace {
constexpr double kPiD = 3.14159265358979323846;

// Appends the grid's two triangles per cell (vertex (i, j) at base + i * (cols + 1) + j), leaving
// out those with two coincident corners (at a sphere's poles, a disk's centre). Returns how many
// triangles it appended.
size_t grid_triangles(MeshData& m, uint32_t base, int rows, int cols) {
  size_t before = m.indices.size();
  auto add = [&](uint32_t a, uint32_t b, uint32_t c) {
    const auto& p = m.positions;
    if (p[a] == p[b] || p[b] == p[c] || p[a] == p[c]) return;
    m.indices.insert(m.indices.end(), {a, b, c});
  };
  for (int i = 0; i < rows; ++i)
    for (int j = 0; j < cols; ++j) {
      uint32_t a = base + uint32_t(i * (cols + 1) + j), b = a + 1;
      uint32_t c = a + uint32_t(cols + 1), d = c + 1;
      add(a, b, c);
      add(b, d, c);
    }
  return (m.indices.size() - before) / 3;
}
}  // namespace

MeshData make_pbrt_sphere(float r, float zmin, float zmax, float phimax_deg, int n_theta,
                          int n_phi) {
  double z0 = std::clamp(double(std::min(zmin, zmax)), -double(r), double(r));
  double z1 = std::clamp(double(std::max(zmin, zmax)), -double(r), double(r));
  double theta_zmin = std::acos(std::clamp(z0 / r, -1.0, 1.0));  // larger theta (lower z)
  double theta_zmax = std::acos(std::clamp(z1 / r, -1.0, 1.0));
  double phimax = std::clamp(double(phimax_deg), 0.0, 360.0) * kPiD / 180.0;
  int rows = std::max(1, int(std::ceil(n_theta * (theta_zmin - theta_zmax) / kPiD)));
  int cols = std::max(1, int(std::ceil(n_phi * phimax / (2 * kPiD))));
  MeshData m;
  // Row i goes from theta_zmin (v = 0) to theta_zmax (v = 1); column j from phi = 0 to phimax.
  for (int i = 0; i <= rows; ++i) {
    double v = double(i) / rows;
    double theta = theta_zmin + (theta_zmax - theta_zmin) * v;
    for (int j = 0; j <= cols; ++j) {
      double u = double(j) / cols;
      double phi = (j == cols && phimax >= 2 * kPiD) ? 0.0 : u * phimax;
      double st = std::sin(theta);
      if (std::fabs(st) < 1e-9) st = 0;  // the poles exactly, so their triangles are recognised
      Vec3 n(float(st * std::cos(phi)), float(st * std::sin(phi)), float(std::cos(theta)));
      m.positions.push_back(n * r);
      m.normals.push_back(n);
      m.uvs.push_back({float(u), float(v)});
    }
  }
  // Going up in z (v) and round in phi (u): d/dphi x d/dz points outward for (u, v) -> (a, b, c).
  grid_triangles(m, 0, rows, cols);
  return m;
}

MeshData make_pbrt_disk(float height, float radius, float inner_radius, float phimax_deg,
                        int n_phi) {
  double phimax = std::clamp(double(phimax_deg), 0.0, 360.0) * kPiD / 180.0;
  int cols = std::max(1, int(std::ceil(n_phi * phimax / (2 * kPiD))));
  MeshData m;
  for (int ring = 0; ring < 2; ++ring) {  // ring 0: outer edge (v = 0), ring 1: inner (v = 1)
    double rho = ring == 0 ? radius : inner_radius;
    for (int j = 0; j <= cols; ++j) {
      double u = double(j) / cols;
      double phi = (j == cols && phimax >= 2 * kPiD) ? 0.0 : u * phimax;
      m.positions.push_back({float(rho * std::cos(phi)), float(rho * std::sin(phi)), height});
      m.normals.push_back({0, 0, 1});
      m.uvs.push_back({float(u), float(ring)});
    }
  }
  // Outer (row 0) to inner (row 1) is -rho, round is +phi: (outer_j, outer_j+1, inner_j) winds +z.
  grid_triangles(m, 0, 1, cols);
  return m;
}

MeshData make_bilinear_patches(const std::vector<Vec3>& p, const std::vector<uint32_t>& indices,
                               const std::vector<Vec3>& n, const std::vector<Vec2>& uv, int n_grid,
                               std::vector<uint32_t>& patch_of_triangle) {
  MeshData m;
  const bool has_n = !n.empty(), has_uv = !uv.empty();
  for (size_t k = 0; k + 3 < indices.size(); k += 4) {
    const uint32_t* q = &indices[k];
    Vec3 p00 = p[q[0]], p10 = p[q[1]], p01 = p[q[2]], p11 = p[q[3]];
    // Planar when p11 lies in the plane of the other three (relative to the patch size).
    Vec3 nrm = cross(p10 - p00, p01 - p00);
    float size = std::max({length(p10 - p00), length(p01 - p00), length(p11 - p00)});
    float off = length(nrm) > 0 ? std::fabs(dot(normalize(nrm), p11 - p00)) : 0.0f;
    int g = off <= 1e-5f * size ? 1 : n_grid;
    uint32_t base = uint32_t(m.positions.size());
    for (int i = 0; i <= g; ++i) {
      float v = float(i) / g;
      for (int j = 0; j <= g; ++j) {
        float u = float(j) / g;
        auto lerp2 = [&](auto a00, auto a10, auto a01, auto a11) {
          return (a00 * (1 - u) + a10 * u) * (1 - v) + (a01 * (1 - u) + a11 * u) * v;
        };
        m.positions.push_back(lerp2(p00, p10, p01, p11));
        if (has_n) m.normals.push_back(normalize(lerp2(n[q[0]], n[q[1]], n[q[2]], n[q[3]])));
        if (has_uv) {
          Vec2 a = uv[q[0]], b = uv[q[1]], c = uv[q[2]], d = uv[q[3]];
          m.uvs.push_back({(a.x * (1 - u) + b.x * u) * (1 - v) + (c.x * (1 - u) + d.x * u) * v,
                           (a.y * (1 - u) + b.y * u) * (1 - v) + (c.y * (1 - u) + d.y * u) * v});
        } else {
          m.uvs.push_back({u, v});
        }
      }
    }
    // (u, v) grid: cross(dp/du, dp/dv) is pbrt's normal; (a, b, c) with b = +u, c = +v matches.
    size_t added = grid_triangles(m, base, g, g);
    patch_of_triangle.insert(patch_of_triangle.end(), added, uint32_t(k / 4));
  }
  return m;
}

}  // namespace rf::pbrt
