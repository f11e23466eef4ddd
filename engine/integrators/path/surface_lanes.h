// The path tracer's vectorised kernels: a packet's plain vertices shaded together.
//
// A packet's vertices on plain diffuse surfaces and plain rough conductors (no texture), shaded
// together: light sample, MIS weight and shadow ray, BSDF sample, throughput, spawned ray and
// roulette, each a loop over the vertices' arrays (the diffuse_lanes_* loops for all of them, then
// conductor_lanes for the rough conductors' BSDF, whose results replace the diffuse loops' ones
// for those vertices). When every light is a triangle picked by power
// (LaneLights::triangles_by_power) the light sample is a loop too. With other lights (spheres,
// environment, point lights, the light BVH: kGivenLight) each vertex's light is picked one by one
// as light_sample_mis_unshadowed picks it (LightSet::pick); a sphere seen from outside is then
// sampled in loops (its cone), any other light one by one (LightSet::sample_selected), and the
// result goes into the arrays. The loops call the one-vertex code (light_sampling.h:
// sample_triangle, sphere_cone_angles and sphere_cone_point, Bsdf's pieces, DiffuseBxdf,
// RoughConductorBxdf, offset_ray_origin), whose operations are exact IEEE ones (no FMA
// contraction), so the compiled vector loops give each vertex the bits the one-lane path gives it
// (the packet test holds them to that). The loops call no library function: the cosines and sines
// (the disk's, the sphere cone's phi, the visible-normal sample's phi) are polynomials
// (sin_cos_quarter_pi, cos_sin_turn). The arrays are in lane space: slot i is packet lane i, so the
// packet query writes the hits (Accel::PacketHits), Sampler::get_lanes the numbers and
// lanes_to_packets the next rays where the next step reads them, with no copies between (not a
// compacted layout: it would spend its time in those copies; docs/performance.md, "The path
// tracer's inner loop"); lane[0..m) lists the plain vertices' lanes for the one-by-one parts. The
// loops run over all N slots, the plain vertices and whatever the others hold (zeros or earlier
// vertices; their results are never read; likewise a diffuse loop's results on a conductor's slot
// and the conductor loops' on a diffuse one): with a trip count that is a multiple of every vector
// width the loops have no scalar remainder.
#pragma once

#include <cstdint>

#include "engine/accel.h"
#include "engine/bsdf.h"
#include "engine/integrators/path/lane_lights.h"
#include "engine/integrators/sample_layout.h"
#include "engine/sampler.h"
#include "engine/simd.h"

namespace rf {

struct SurfaceLanes : LaneSlots<Accel::kPacket> {
  // The vertex: the hit (hit point and its error, geometric and shading normals, as the packet
  // query wrote them), direction to the previous vertex, albedo, throughput and eta scale.
  Accel::PacketHits hit;
  V3 wo, reflectance, beta;
  float eta_scale[N];
  // The vertex's numbers (u[kUDir]: the BSDF sample's, u[kURoulette]: roulette's; u[kUPoint]'s x
  // rescaled by the light pick), as Sampler::get_lanes draws them.
  Sampler::LaneDraws u[kVertexDraws];
  int roulette[N];  // whether roulette runs at this depth (per lane: the vectoriser wants arrays)
  int last[N];      // whether this is the last depth (PacketPaths' `last_`; likewise)
  // The light pick (light_ok) and the picked triangle.
  int light_ok[N];  // flags as int: the vectoriser handles no bool arrays
  float l_area[N], l_pmf[N];
  V3 l_p0, l_p1, l_p2, l_n, l_radiance;
  int l_two_sided[N];
  // With other lights (kGivenLight) a vertex's light sample is taken one by one (g_*: ok,
  // direction, radiance, pdf including selection, shadow ray), unless its light is a sphere seen
  // from outside (l_sphere), whose cone is sampled in the loops (SphereCone; emission
  // in l_radiance and l_two_sided, selection in l_pmf, the numbers in u[kUPoint]): the angles
  // (with phi's cosine and sine), then the point (l_p0, its error l_p1, normal l_n). The
  // loops then select the sphere's sample or the given one into light_ok, l_wi, l_radiance, l_pdf
  // and the shadow ray (two arrays: GCC 12 vectorises no conditional store of an array's own
  // element back to it).
  int l_delta[N], l_sphere[N];
  V3 l_wi, g_wi, g_radiance, g_shadow_o, g_shadow_d;
  float l_pdf[N], g_pdf[N], g_shadow_tmax[N];
  int g_ok[N];
  V3 s_center, s_pole;
  float s_radius[N], s_sin2_max[N], s_cos_max[N], s_omc[N];
  float s_cos_alpha[N], s_sin_alpha[N], s_cos_phi[N], s_sin_phi[N];
  // Next-event estimation: whether it has a shadow ray, the ray, the term.
  int nee_ok[N];
  V3 shadow_o, shadow_d, nee;
  float shadow_tmax[N];
  // The BSDF sample's disk point; wo mirrored; the sample not failed yet.
  float disk[2][N];
  int mirror[N], sample_ok[N];
  // The continuation: receiver normal, spawned ray, new throughput, BSDF pdf, whether it lives on.
  V3 receiver_n;
  struct Continuation {
    V3 ray_o, ray_d, beta_out;
    float bsdf_pdf[N];
    int continues[N], survives[N];
  } cont;
  // Rough-conductor vertices (LaneKind::RoughConductor) share the arrays above: the vertex, the
  // light sample (the NEE loop keeps it in ls_*: direction, radiance, pdf, usable, delta) and the
  // shadow ray. Their lobe (alpha, masking, Fresnel) and their results (c_*), taken over the
  // diffuse loops' ones lane by lane.
  int conductor[N];
  V3 ls_wi, ls_radiance;
  float ls_pdf[N];
  int ls_ok[N], ls_delta[N];
  float c_alpha[N];
  int c_separable[N], c_use_tint[N];
  V3 c_eta, c_k, c_tint;
  V3 c_f, c_nee;
  Continuation c_cont;

  // Lane j's vertex as the one-vertex code takes it.
  struct Vertex {
    Vec3 p, p_error, ng, wo;
    Frame frame;
    DiffuseBxdf lobe;
  };
  RoughConductorBxdf rough_conductor(int j) const {
    return {TrowbridgeReitz{c_alpha[j], c_alpha[j], c_separable[j] != 0},
            ConductorFresnel{get(c_eta, j), get(c_k, j), get(c_tint, j), c_use_tint[j] != 0}};
  }
  Vertex vertex(int j) const {
    const Vec3 n = get(hit.ng, j);
    return {get(hit.p, j),
            get(hit.p_error, j),
            n,
            get(wo, j),
            Bsdf::shading_frame(get(hit.ns, j), n),
            DiffuseBxdf{get(reflectance, j)}};
  }
};

// The kernels, in the order a depth runs them (packets.cpp, shade_lanes). Each runs over all N
// slots (see SurfaceLanes).

// The picked lights (entry[j] of the pick table, LaneLights::pick_entries) into every slot's
// light arrays, and the rescaled numbers ux into u[kUPoint] of the slots where plain[j] (the others
// keep their own for their one-by-one shading).
void lanes_picked_lights(SurfaceLanes& L, const LaneLights::PickTable& T, const uint32_t* entry,
                         const float* ux, const int* plain);
// The picked spheres (entry[j] of the sphere table, LaneLights::pick_sphere_entries) into every
// slot's sphere arrays, with the cone each subtends from the slot's hit point: l_sphere where
// the point is outside its sphere (sampled in the loops); a point inside is sampled one by one.
void lanes_sphere_lights(SurfaceLanes& L, const LaneLights::SphereTable& T, const uint32_t* entry);
// The sphere cones' angles (sphere_cone_angles), then their points, light samples and shadow rays
// (the given one g_* where the slot's light is not a sphere seen from outside).
void diffuse_lanes_sphere_angles(SurfaceLanes& L);
void diffuse_lanes_sphere_points(SurfaceLanes& L);
// Next-event estimation at the diffuse slots, with the light sample in l_* (given: taken before,
// by the sphere loops or one by one) or sampled here from the picked triangle; then the BSDF
// sample's disk point.
void diffuse_lanes_nee_given_light(SurfaceLanes& L);
void diffuse_lanes_nee_triangles(SurfaceLanes& L);
// The diffuse slots' BSDF samples, throughput, spawned rays and roulette (cont).
void diffuse_lanes_continue(SurfaceLanes& L);
// The rough-conductor slots' NEE term and continuation (c_*, c_cont).
void conductor_lanes(SurfaceLanes& L);
// Every slot's spawned ray and shadow ray into the packets' arrays.
void lanes_to_packets(const SurfaceLanes& L, RTCRayHit16& next, RTCRay16& shadow);

}  // namespace rf
