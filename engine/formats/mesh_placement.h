// Placing a mesh from a file or a built-in shape into a scene, the same way for every format.
#pragma once

#include <string>

#include "engine/math.h"
#include "engine/mesh_io.h"
#include "engine/scene.h"

namespace rf {

// Checks the mesh data (per-vertex arrays as long as the positions, indices in range), moves it by
// `to_world` (positions; normals by the inverse transpose), keeps its front side under mirroring
// transforms, and drops zero-area triangles; fills mesh's geometry, keeping its name, material
// and emission. Throws SceneError "<file>: <where>: ..."; logs a warning when it drops triangles
// or falls back to flat shading.
void place_mesh(MeshData data, const Mat4& to_world, const std::string& file,
                const std::string& where, Mesh& mesh);

}  // namespace rf
