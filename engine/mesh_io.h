// Triangle mesh readers for the scene loader: Wavefront OBJ and Stanford PLY (ascii, binary little
// and big endian). Small hand-written parsers so a bad file gets a message naming the file and the
// line (OBJ, ascii PLY) or element row (binary PLY) that is wrong.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "engine/math.h"
#include "engine/scene_error.h"

namespace rf {

// One triangle mesh in object space. normals and uvs are per vertex and either empty or the same
// length as positions; indices hold 3 per triangle, each < positions.size().
struct MeshData {
  std::vector<Vec3> positions;
  std::vector<Vec3> normals;
  std::vector<Vec2> uvs;
  std::vector<uint32_t> indices;
};

// Read a file and parse it; throw SceneError naming the file (and line) on any problem.
MeshData load_obj(const std::string& path);
MeshData load_ply(const std::string& path);

// Parse bytes already in memory; `name` is the file name used in messages. The scene loader uses
// these so it reads each asset once for both the digest and the geometry.
//
// OBJ: v, vt, vn and f statements (f corners as v, v/vt, v//vn or v/vt/vn, 1-based or negative
// relative indices); polygons are fan-triangulated; every other statement (o, g, s, usemtl, ...)
// is ignored. Corners with distinct (v, vt, vn) triples become distinct vertices. If only some
// corners carry a normal (or uv), normals (uvs) are dropped for the whole mesh with a warning.
MeshData parse_obj(std::string_view text, const std::string& name);
// PLY: element "vertex" with x, y, z and optional nx, ny, nz and u, v (or s, t, or texture_u,
// texture_v); element "face" with a list property vertex_indices (or vertex_index); polygons are
// fan-triangulated; other elements and properties are skipped.
MeshData parse_ply(std::string_view bytes, const std::string& name);

}  // namespace rf
