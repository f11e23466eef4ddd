// pbrt-v4's analytic shapes as triangle meshes in their object space (z up), with pbrt's uv
// parametrisation and outward right-hand winding (docs/formats/pbrt.md "Shapes").
#pragma once

#include <vector>

#include "engine/mesh_io.h"

namespace rf::pbrt {

// pbrt's "sphere": radius r, cut to zmin <= z <= zmax and 0 <= phi <= phimax (degrees).
// n_theta rows over the full polar range (fewer when cut), n_phi columns over 360 degrees (fewer
// when cut); smooth normals, uv = (phi / phimax, (theta - theta_zmin) / (theta_zmax - theta_zmin)).
MeshData make_pbrt_sphere(float r, float zmin, float zmax, float phimax_deg, int n_theta,
                          int n_phi);

// pbrt's "disk" in the plane z = height, normal +z: radius, innerradius (an annulus), phimax;
// uv = (phi / phimax, (radius - rho) / (radius - innerradius)).
MeshData make_pbrt_disk(float height, float radius, float inner_radius, float phimax_deg,
                        int n_phi);

// pbrt's "bilinearmesh": patches of 4 vertex indices (p00, p10, p01, p11). A planar patch is two
// triangles (exact); a curved one an n x n grid of the bilinear surface. Normals and uvs are
// interpolated bilinearly (uv defaults to the patch's (u, v)). patch_of_triangle receives, per
// output triangle, the index of its patch.
MeshData make_bilinear_patches(const std::vector<Vec3>& p, const std::vector<uint32_t>& indices,
                               const std::vector<Vec3>& n, const std::vector<Vec2>& uv, int n_grid,
                               std::vector<uint32_t>& patch_of_triangle);

}  // namespace rf::pbrt
