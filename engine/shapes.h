// The scene format's built-in shapes as meshes (docs/scene-format.md: rectangle, cube, sphere,
// disk), with outward right-hand winding.
#pragma once

#include "engine/math.h"
#include "engine/mesh_io.h"

namespace rf {

// The square [-1, 1]^2 in the z = 0 plane, normal +z.
MeshData make_rectangle();
// The cube [-1, 1]^3, four vertices per face so uvs are per face.
MeshData make_cube();
// A UV sphere of centre c and radius r: n_theta rows from the north pole (+y), n_phi columns,
// 2 n_theta n_phi - 2 n_phi triangles, unit vertex normals, uv = (phi / 2pi, 1 - theta / pi).
MeshData make_sphere(Vec3 c, float r, int n_theta, int n_phi);
// The unit disk in the z = 0 plane, normal +z, as a fan of `segments` triangles.
MeshData make_disk(int segments);

}  // namespace rf
