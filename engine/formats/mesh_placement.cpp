#include "engine/formats/mesh_placement.h"

#include <spdlog/spdlog.h>

#include <cmath>

namespace rf {

namespace {

[[noreturn]] void fail(const std::string& file, const std::string& where, const std::string& what) {
  throw SceneError(file + ": " + where + ": " + what);
}

void check_mesh(const MeshData& m, const std::string& file, const std::string& where) {
  size_t n = m.positions.size();
  if (!m.normals.empty() && m.normals.size() != n)
    fail(file, where, "has " + std::to_string(m.normals.size()) + " normals for " +
                       std::to_string(n) + " vertices");
  if (!m.uvs.empty() && m.uvs.size() != n)
    fail(file, where, "has " + std::to_string(m.uvs.size()) + " uvs for " + std::to_string(n) +
                       " vertices");
  for (size_t i = 0; i < m.indices.size(); ++i)
    if (m.indices[i] >= n)
      fail(file, where, "index " + std::to_string(m.indices[i]) + " (triangle " +
                         std::to_string(i / 3) + ") out of range (" + std::to_string(n) +
                         " vertices)");
}

// Moves geometry to world space, keeps the front side under mirroring transforms, and drops
// zero-area triangles (they would only produce NaN normals and zero-area light samples).
void to_world_space(MeshData& m, const Mat4& to_world, Mesh& mesh, const std::string& file,
                  const std::string& where) {
  for (Vec3& pos : m.positions) {
    pos = to_world.point(pos);
    if (!is_finite(pos)) fail(file, where, "a vertex is not finite after the transform");
  }
  bool bad_normal = false;
  for (Vec3& n : m.normals) {
    n = to_world.normal(n);
    float len = length(n);
    bad_normal |= !(len > 0) || !std::isfinite(len);
    n = n / len;
  }
  if (bad_normal) {
    spdlog::warn("{}: {}: zero or non-finite vertex normals; using flat shading", file,
                 where);
    m.normals.clear();
  }
  bool mirror = to_world.det3() < 0;  // the winding's right-hand normal would flip
  size_t dropped = 0;
  for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
    uint32_t a = m.indices[t], b = m.indices[t + 1], c = m.indices[t + 2];
    if (mirror) std::swap(b, c);
    Vec3 e = cross(m.positions[b] - m.positions[a], m.positions[c] - m.positions[a]);
    if (!(length_sq(e) > 0) || !is_finite(e)) {
      ++dropped;
      continue;
    }
    mesh.indices.insert(mesh.indices.end(), {a, b, c});
  }
  if (dropped)
    spdlog::warn("{}: {}: dropped {} degenerate (zero-area) triangle{}", file, where,
                 dropped, dropped == 1 ? "" : "s");
  if (mesh.indices.empty())
    fail(file, where, dropped ? "all triangles are degenerate (zero area)" : "has no triangles");
  mesh.positions = std::move(m.positions);
  mesh.normals = std::move(m.normals);
  mesh.uvs = std::move(m.uvs);
}

}  // namespace

void place_mesh(MeshData data, const Mat4& to_world, const std::string& file,
                const std::string& where, Mesh& mesh) {
  check_mesh(data, file, where);
  to_world_space(data, to_world, mesh, file, where);
}

}  // namespace rf
