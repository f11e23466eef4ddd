// The `path` integrator: see path.h.
#include "engine/integrators/path.h"

#include "engine/check.h"
#include "engine/integrators/drivers.h"
#include "engine/simd.h"

namespace rf {

namespace {

// The one-lane stand-in for Accel::RayPacket: Embree's single-ray queries, for groups of one
// sample (a pass of one sample per pixel), where a 16-wide packet would carry one live lane.
struct SingleRay {
  Ray r;
  bool on = false;
  void set(int, const Ray& ray) { r = ray, on = true; }
  void clear(int) { on = false; }
  bool active(int) const { return on; }
  Ray ray(int) const { return r; }
};
void intersect(const Accel& accel, Accel::RayPacket& p, int n, Accel::PacketHits& hits,
               bool coherent) {
  accel.intersect_packet(p, n, hits, coherent);
}
void intersect(const Accel& accel, SingleRay& p, int, Accel::PacketHits& hits, bool) {
  SurfaceHit hit;
  hits.found[0] = accel.intersect(p.r, hit);
  if (hits.found[0]) hits.set(0, hit);
}
void occluded(const Accel& accel, Accel::RayPacket& p, int n, int* blocked) {
  accel.occluded_packet(p, n, blocked);
}
void occluded(const Accel& accel, SingleRay& p, int, int* blocked) {
  blocked[0] = accel.occluded(p.r.o, p.r.d, p.r.tmax);
}

// A packet's vertices on plain diffuse surfaces and plain rough conductors (no texture), shaded
// together: light sample, MIS weight and shadow ray, BSDF sample, throughput, spawned ray and
// roulette, each a loop over the vertices' arrays (the diffuse_lanes_* loops for all of them, then
// conductor_lanes for the rough conductors' BSDF, whose results replace the diffuse loops' ones
// for those vertices). When every light is a triangle picked by power
// (LightSet::triangles_by_power) the light sample is a loop too. With other lights (spheres,
// environment, point lights, the light BVH: kGivenLight) each vertex's light is picked one by one
// as light_sample_mis_unshadowed picks it (LightSet::pick); a sphere seen from outside is then
// sampled in loops (its cone), any other light one by one (LightSet::sample_selected), and the
// result goes into the arrays. The loops call the one-vertex code (LightSet::sample_triangle,
// sphere_cone_angles and sphere_cone_point, Bsdf's pieces, DiffuseBxdf, RoughConductorBxdf,
// offset_ray_origin), whose operations are exact IEEE ones (no FMA contraction), so the compiled
// vector loops give each vertex the bits the one-lane path gives it (the packet test holds them to
// that). The loops call no library function: the cosines and sines (the disk's, the sphere
// cone's phi, the visible-normal sample's phi) are polynomials (sin_cos_quarter_pi,
// cos_sin_turn).
// The arrays are in lane space: slot i is packet lane i, so the packet query writes the hits
// (Accel::PacketHits), Sampler::get_lanes the numbers and lanes_to_packets the next rays where
// the next step reads them, with no copies between (not a compacted layout: it would spend its
// time in those copies; docs/performance.md, "The path tracer's inner loop"); lane[0..m) lists
// the plain vertices' lanes for the one-by-one parts.
// The loops run over all N slots, the plain vertices and whatever the others hold (zeros or
// earlier vertices; their results are never read; likewise a diffuse loop's results on a
// conductor's slot and the conductor loops' on a diffuse one): with a trip count that is a
// multiple of every vector width the loops have no scalar remainder.
// A vertex's draws: light choice, light point, lobe choice, direction, roulette (each a skip where
// nothing reads it: see trace_paths).
enum { kULight, kUPoint, kUChoice, kUDir, kURoulette, kVertexDraws };
// The first vertex's light point and direction are stratified jointly with the camera sample's
// filter offset (Sampler::get_2d_joint, pairs 0 and 1), the second vertex's with the first
// vertex's direction (pairs 2 and 3); later vertices' draws are padded. This lowers the error
// where veach-mis's sits, the small light's image in the smoothest plate, and the variance of the
// Cornell box's one-bounce light (docs/performance.md, "Draws stratified with the pixel: joint
// pairs").
constexpr int kPointPair = 0, kDirPair = 1, kJointDepths = 2;
// The joint pair of a vertex's light point or direction (kPointPair or kDirPair), or -1 (padded).
inline int joint_pair(int depth, int pair) { return depth < kJointDepths ? pair + 2 * depth : -1; }
// Its lockstep draw code (Sampler::get_lanes).
inline uint8_t vertex_draw(int depth, int pair) {
  const int k = joint_pair(depth, pair);
  return k >= 0 ? uint8_t(Sampler::kJointDraw + k) : 2;
}
inline Vec2 vertex_2d(Sampler& s, bool needed, int depth, int pair) {
  const int k = joint_pair(depth, pair);
  return k >= 0 ? s.get_2d_joint_if(needed, k) : s.get_2d_if(needed);
}

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
  int last[N];      // whether this is the last depth (trace_paths' `last`; likewise)
  // The light pick (light_ok) and the picked triangle.
  int light_ok[N];  // flags as int: the vectoriser handles no bool arrays
  float l_area[N], l_pmf[N];
  V3 l_p0, l_p1, l_p2, l_n, l_radiance;
  int l_two_sided[N];
  // With other lights (kGivenLight) a vertex's light sample is taken one by one (g_*: ok,
  // direction, radiance, pdf including selection, shadow ray), unless its light is a sphere seen
  // from outside (l_sphere), whose cone is sampled in the loops (LightSet::SphereCone; emission
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

// The sphere cones' angles (LightSet::sphere_cone_angles), for every slot.
RF_SIMD_CLONES void diffuse_lanes_sphere_angles(SurfaceLanes& L) {
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j)  // all N: see SurfaceLanes
    LightSet::sphere_cone_angles(L.s_sin2_max[j], L.s_cos_max[j],
                                 {L.u[kUPoint][0][j], L.u[kUPoint][1][j]}, L.s_cos_alpha[j],
                                 L.s_sin_alpha[j], L.s_cos_phi[j], L.s_sin_phi[j]);
}

// The sphere cones' points: the rest of sample_selected() (sphere_cone_point, with_selection),
// the light sample of the slots whose light is a sphere (l_sphere), the given one (g_*) of the
// others; then their shadow rays (a loop of its own: GCC 12 does not vectorise the two as one).
RF_SIMD_CLONES void diffuse_lanes_sphere_points(SurfaceLanes& L) {
  using D = SurfaceLanes;
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j) {  // all N: see SurfaceLanes
    const Vec3 p = D::get(L.hit.p, j);
    LightSet::SphereCone c{D::get(L.s_center, j),
                           D::get(L.s_pole, j),
                           L.s_radius[j],
                           L.s_sin2_max[j],
                           L.s_cos_max[j],
                           L.s_omc[j],
                           {D::get(L.l_radiance, j), L.l_two_sided[j] != 0}};
    LightSample ls;
    bool ok = LightSet::sphere_cone_point(c, p, L.s_cos_alpha[j], L.s_sin_alpha[j], L.s_cos_phi[j],
                                          L.s_sin_phi[j], ls);
    ok = LightSet::with_selection(ok, L.l_pmf[j], ls);
    const bool sphere = L.l_sphere[j] != 0;
    D::put(L.l_wi, j, vselect(sphere, ls.wi, D::get(L.g_wi, j)));
    D::put(L.l_radiance, j, vselect(sphere, ls.radiance, D::get(L.g_radiance, j)));
    L.l_pdf[j] = sphere ? ls.pdf_solid_angle : L.g_pdf[j];
    L.light_ok[j] = sphere ? int(ok) : L.g_ok[j];
    D::put(L.l_p0, j, ls.p), D::put(L.l_p1, j, ls.p_error), D::put(L.l_n, j, ls.n);
  }
  // The shadow rays: light_shadow_ray() to the sphere's point, or the given ray.
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j) {  // all N: see SurfaceLanes
    Ray r = Accel::shadow_segment(D::get(L.hit.p, j), D::get(L.hit.p_error, j), D::get(L.hit.ng, j),
                                  D::get(L.l_p0, j), D::get(L.l_p1, j), D::get(L.l_n, j));
    const bool sphere = L.l_sphere[j] != 0;
    D::put(L.shadow_o, j, vselect(sphere, r.o, D::get(L.g_shadow_o, j)));
    D::put(L.shadow_d, j, vselect(sphere, r.d, D::get(L.g_shadow_d, j)));
    L.shadow_tmax[j] = sphere ? r.tmax : L.g_shadow_tmax[j];
  }
}

template <bool kGivenLight>
RF_SIMD_CLONES void diffuse_lanes_nee(SurfaceLanes& L) {
  using D = SurfaceLanes;
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j) {  // all N: see SurfaceLanes
    const auto [p, p_error, ng, wo, frame, lobe] = L.vertex(j);
    // light_sample_mis_unshadowed(), with LightSet::sample() as pick + sample_triangle or taken
    // before the loop.
    LightSample ls;
    bool ok = true;
    if constexpr (kGivenLight) {
      ls.wi = D::get(L.l_wi, j);
      ls.radiance = D::get(L.l_radiance, j);
      ls.pdf_solid_angle = L.l_pdf[j];
    } else {
      LightSet::TriangleLight t{D::get(L.l_p0, j),
                                D::get(L.l_p1, j),
                                D::get(L.l_p2, j),
                                D::get(L.l_n, j),
                                L.l_area[j],
                                L.l_pmf[j],
                                {D::get(L.l_radiance, j), L.l_two_sided[j] != 0}};
      ok = LightSet::sample_triangle(t, p, {L.u[kUPoint][0][j], L.u[kUPoint][1][j]}, ls);
    }
    // Bsdf::eval_pdf.
    Vec3 lo, li;
    bool pair = Bsdf::to_lobe(frame, ng, DiffuseBxdf::kTwoSided, wo, ls.wi, lo, li);
    RGB f_pair = lobe.eval(lo, li, TransportMode::Radiance);
    float bsdf_pdf = pair ? lobe.pdf(lo, li, TransportMode::Radiance) : 0.0f;
    RGB f = pair ? f_pair : RGB(0.0f);
    // !is_black(f), spelt as the lobe's own condition (f is R / pi above both lobe directions) so
    // that GCC 12 vectorises it (it does not vectorise the select of flags is_black(f) becomes).
    bool f_nonzero = !(lo.z <= 0) & !(li.z <= 0) & !is_black(lobe.reflectance * kInvPi);
    const bool light = ok & (L.light_ok[j] != 0);
    ok = light & pair & f_nonzero;
    float w = power_heuristic(ls.pdf_solid_angle, bsdf_pdf);
    if constexpr (kGivenLight) w = L.l_delta[j] != 0 ? 1.0f : w;
    w = L.last[j] != 0 ? 1.0f : w;  // light sampling the only strategy (trace_paths' `last`)
    D::put(L.ls_wi, j, ls.wi), D::put(L.ls_radiance, j, ls.radiance);
    L.ls_pdf[j] = ls.pdf_solid_angle, L.ls_ok[j] = light;
    L.ls_delta[j] = kGivenLight ? L.l_delta[j] : 0;
    float cos_i = std::fabs(dot(ls.wi, frame.n));
    RGB c = f * ls.radiance * (cos_i * w / ls.pdf_solid_angle);
    L.nee_ok[j] = ok;
    if constexpr (!kGivenLight) {
      Ray shadow = Accel::shadow_segment(p, p_error, ng, ls.p, ls.p_error, ls.n);
      D::put(L.shadow_o, j, shadow.o);
      D::put(L.shadow_d, j, shadow.d);
      L.shadow_tmax[j] = shadow.tmax;
    }
    D::put(L.nee, j, ok ? c : RGB(0.0f));
    D::put(L.receiver_n, j, dot(wo, ng) >= 0 ? ng : -ng);
    // Bsdf::sample up to the lobe's disk point.
    Vec3 lo_wo = frame.to_local(wo);
    bool mirror = lo_wo.z < 0;
    float z = mirror ? -lo_wo.z : lo_wo.z;
    L.mirror[j] = mirror;
    L.sample_ok[j] = !(lo_wo.z == 0) && !(z <= 0);
    const Vec2 disk = sample_concentric_disk({L.u[kUDir][0][j], L.u[kUDir][1][j]});
    L.disk[0][j] = disk.x, L.disk[1][j] = disk.y;
  }
}

// The end of slot j's vertex once its BSDF sample bs is known (ok: not failed), as trace_paths
// ends a vertex one by one: throughput, spawned ray, BSDF pdf, roulette; into `out`.
[[gnu::always_inline]] inline void continue_slot(const SurfaceLanes& L, int j, Vec3 p,
                                                 Vec3 p_error, Vec3 ng, const Frame& frame,
                                                 const BsdfSample& bs, bool ok,
                                                 SurfaceLanes::Continuation& out) {
  using D = SurfaceLanes;
  float cos_i = std::fabs(dot(bs.wi, frame.n));
  RGB beta = D::get(L.beta, j) * (bs.f * (cos_i / bs.pdf_solid_angle));
  D::put(out.ray_o, j, offset_ray_origin(p, p_error, ng, bs.wi));
  D::put(out.ray_d, j, bs.wi);
  out.bsdf_pdf[j] = bs.pdf_solid_angle;
  float survive = std::min(1.0f, max_component(beta * L.eta_scale[j]));
  out.continues[j] = ok;
  bool roulette = L.roulette[j] != 0;
  out.survives[j] = !(roulette & (L.u[kURoulette][0][j] >= survive));
  D::put(out.beta_out, j, roulette ? beta / survive : beta);
}

// The lights LightSet::pick_entries picked (entry[j] of the pick table) into every slot's light
// arrays, and its rescaled numbers ux into u[kUPoint] of the slots where plain[j] (the others
// keep their own for their one-by-one shading). Selects over the table's few entries, which
// vectorise where indexed loads would not (GCC's generic tuning emits no gathers).
RF_SIMD_CLONES void lanes_picked_lights(SurfaceLanes& L, const LightSet::PickTable& T,
                                        const uint32_t* entry, const float* ux, const int* plain) {
  using D = SurfaceLanes;
  for (int e = 0; e < T.count; ++e) {
    const Vec3 p0 = T.get(T.p0, e), p1 = T.get(T.p1, e), p2 = T.get(T.p2, e);
    const Vec3 n = T.get(T.n, e), le = T.get(T.radiance, e);
    const float area = T.area[e], pmf = T.pmf[e];
    const int two_sided = T.two_sided[e];
    RF_IVDEP
    for (int j = 0; j < SurfaceLanes::N; ++j) {  // all N: see SurfaceLanes
      const bool s = e == 0 || entry[j] == uint32_t(e);
      D::put(L.l_p0, j, vselect(s, p0, D::get(L.l_p0, j)));
      D::put(L.l_p1, j, vselect(s, p1, D::get(L.l_p1, j)));
      D::put(L.l_p2, j, vselect(s, p2, D::get(L.l_p2, j)));
      D::put(L.l_n, j, vselect(s, n, D::get(L.l_n, j)));
      D::put(L.l_radiance, j, vselect(s, le, D::get(L.l_radiance, j)));
      L.l_area[j] = s ? area : L.l_area[j];
      L.l_pmf[j] = s ? pmf : L.l_pmf[j];
      L.l_two_sided[j] = s ? two_sided : L.l_two_sided[j];
    }
  }
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j) {
    L.light_ok[j] = 1;
    L.u[kUPoint][0][j] = plain[j] != 0 ? ux[j] : L.u[kUPoint][0][j];
  }
}

// The spheres LightSet::pick_sphere_entries picked (entry[j] of the sphere table) into every
// slot's sphere arrays, with the cone each subtends from the slot's hit point (LightSet::
// sphere_cone): l_sphere where the point is outside its sphere (sampled in the loops); a point
// inside is sampled one by one afterwards. Selects over the table's few entries, as
// lanes_picked_lights.
RF_SIMD_CLONES void lanes_sphere_lights(SurfaceLanes& L, const LightSet::SphereTable& T,
                                        const uint32_t* entry) {
  using D = SurfaceLanes;
  for (int e = 0; e < T.count; ++e) {
    const Vec3 c = T.get(T.center, e), pole = T.get(T.pole, e), le = T.get(T.radiance, e);
    const float radius = T.radius[e], pmf = T.pmf[e];
    const int two_sided = T.two_sided[e];
    RF_IVDEP
    for (int j = 0; j < SurfaceLanes::N; ++j) {  // all N: see SurfaceLanes
      const bool s = e == 0 || entry[j] == uint32_t(e);
      D::put(L.s_center, j, vselect(s, c, D::get(L.s_center, j)));
      D::put(L.s_pole, j, vselect(s, pole, D::get(L.s_pole, j)));
      D::put(L.l_radiance, j, vselect(s, le, D::get(L.l_radiance, j)));
      L.s_radius[j] = s ? radius : L.s_radius[j];
      L.l_pmf[j] = s ? pmf : L.l_pmf[j];
      L.l_two_sided[j] = s ? two_sided : L.l_two_sided[j];
    }
  }
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j) {
    L.l_sphere[j] = LightSet::sphere_cone(D::get(L.s_center, j), L.s_radius[j], D::get(L.hit.p, j),
                                          L.s_sin2_max[j], L.s_cos_max[j], L.s_omc[j]);
    L.l_delta[j] = 0;
  }
}

RF_SIMD_CLONES void diffuse_lanes_continue(SurfaceLanes& L) {
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j) {  // all N: see SurfaceLanes
    const auto [p, p_error, ng, wo, frame, lobe] = L.vertex(j);
    BsdfSample bs;
    bool ok = lobe.sample_from_disk({L.disk[0][j], L.disk[1][j]}, bs);
    ok = Bsdf::sample_to_world(frame, ng, wo, L.mirror[j] != 0, bs) & ok & (L.sample_ok[j] != 0);
    continue_slot(L, j, p, p_error, ng, frame, bs, ok, L.cont);
  }
}

// The rough-conductor vertices among the lanes (conductor[j]; the loop runs over all N slots and
// its results, in c_*, are read for those only): light_sample_mis_unshadowed's BSDF part for the
// light sample the NEE loop took (Bsdf::eval_pdf, MIS weight, term), then Bsdf::sample by visible
// normals (phi's cosine and sine by cos_sin_turn, in the loop), throughput, spawned ray and
// roulette, as diffuse_lanes_continue.
RF_SIMD_CLONES void conductor_lanes(SurfaceLanes& L) {
  using D = SurfaceLanes;
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j) {  // all N: see SurfaceLanes
    const Vec3 ng = D::get(L.hit.ng, j), wo = D::get(L.wo, j);
    const Frame frame = Bsdf::shading_frame(D::get(L.hit.ns, j), ng);
    const RoughConductorBxdf lobe = L.rough_conductor(j);
    // Next-event estimation.
    const Vec3 wi = D::get(L.ls_wi, j);
    Vec3 lo, li;
    bool pair = Bsdf::to_lobe(frame, ng, RoughConductorBxdf::kTwoSided, wo, wi, lo, li);
    float bsdf_pdf = pair ? lobe.pdf(lo, li, TransportMode::Radiance) : 0.0f;
    RGB f = vselect(pair, lobe.eval(lo, li, TransportMode::Radiance), RGB(0.0f));
    float w = power_heuristic(L.ls_pdf[j], bsdf_pdf);
    w = L.ls_delta[j] != 0 ? 1.0f : w;
    float cos_l = std::fabs(dot(wi, frame.n));
    RGB c = f * D::get(L.ls_radiance, j) * (cos_l * w / L.ls_pdf[j]);
    // The term counts where the light sample is usable and f is not black; the latter test is
    // left to the caller (GCC 12 does not vectorise a select on is_black(f) here).
    D::put(L.c_f, j, f);
    D::put(L.c_nee, j, c);
  }
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j) {  // all N: see SurfaceLanes
    const Vec3 p = D::get(L.hit.p, j), p_error = D::get(L.hit.p_error, j), ng = D::get(L.hit.ng, j);
    const Vec3 wo = D::get(L.wo, j);
    const Frame frame = Bsdf::shading_frame(D::get(L.hit.ns, j), ng);
    const RoughConductorBxdf lobe = L.rough_conductor(j);
    // Bsdf::sample: wo in the lobe's frame, mirrored where the NEE loop found it below the
    // shading frame (mirror, sample_ok: zero or below is a failed sample; there the mirrored z is
    // |z|, written so: GCC 12 does not vectorise the select of flags -z : z becomes), then the
    // lobe's sample (its last test, pdf > 0, left to the caller: c_cont.bsdf_pdf).
    Vec3 lo_wo = frame.to_local(wo);
    lo_wo.z = std::fabs(lo_wo.z);
    const bool mirror = L.mirror[j] != 0;
    BsdfSample bs;
    float cos_phi, sin_phi;
    TrowbridgeReitz::visible_normal_phi({L.u[kUDir][0][j], L.u[kUDir][1][j]}, cos_phi, sin_phi);
    bool sampled = lobe.sample_from_phi(lo_wo, L.u[kUDir][0][j], cos_phi, sin_phi,
                                        TransportMode::Radiance, bs) &
                   (L.sample_ok[j] != 0);
    sampled = Bsdf::sample_to_world(frame, ng, wo, mirror, bs) & sampled;
    continue_slot(L, j, p, p_error, ng, frame, bs, sampled, L.c_cont);
  }
}

// Every slot's spawned ray (the conductor loop's where the slot is a rough conductor, else the
// diffuse loops') and shadow ray into the packets' arrays, as RayPacket::set writes them but for
// the lanes' flags (the caller activates the shadow rays of the lanes that have one, and clears
// the lanes whose paths end; the others stay active). A slot that is not a plain
// vertex gets values nobody reads: its lane is inactive, or a generic vertex's, which sets its
// rays afterwards.
RF_SIMD_CLONES void lanes_to_packets(const SurfaceLanes& L, RTCRayHit16& next, RTCRay16& shadow) {
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j) {  // all N: see SurfaceLanes
    const bool c = L.conductor[j] != 0;
    next.ray.org_x[j] = c ? L.c_cont.ray_o[0][j] : L.cont.ray_o[0][j];
    next.ray.org_y[j] = c ? L.c_cont.ray_o[1][j] : L.cont.ray_o[1][j];
    next.ray.org_z[j] = c ? L.c_cont.ray_o[2][j] : L.cont.ray_o[2][j];
    next.ray.dir_x[j] = c ? L.c_cont.ray_d[0][j] : L.cont.ray_d[0][j];
    next.ray.dir_y[j] = c ? L.c_cont.ray_d[1][j] : L.cont.ray_d[1][j];
    next.ray.dir_z[j] = c ? L.c_cont.ray_d[2][j] : L.cont.ray_d[2][j];
    next.ray.tfar[j] = kInf;
    next.hit.geomID[j] = RTC_INVALID_GEOMETRY_ID;
    next.hit.instID[0][j] = RTC_INVALID_GEOMETRY_ID;
    shadow.org_x[j] = L.shadow_o[0][j], shadow.org_y[j] = L.shadow_o[1][j];
    shadow.org_z[j] = L.shadow_o[2][j];
    shadow.dir_x[j] = L.shadow_d[0][j], shadow.dir_y[j] = L.shadow_d[1][j];
    shadow.dir_z[j] = L.shadow_d[2][j];
    shadow.tfar[j] = L.shadow_tmax[j];
    shadow.mask[j] = 0xFFFFFFFFu;
  }
}

// A path's state between two depths.
struct PathLane {
  RGB beta{1.0f};
  float eta_scale = 1, prev_bsdf_pdf = 0;
  float cone_width = 0;       // ray-cone width at the current hit, for texture filtering
  bool prev_delta = true;     // the camera ray counts as "specular": emission taken unweighted
  Vec3 prev_p, prev_n{0.0f};  // the last vertex and its receiver normal (light selection)
};
// A lane handed from a packet to the one-lane loop (trace_paths): its state, radiance so far, the
// ray it casts next and that ray's depth.
struct PathResume {
  PathLane lane;
  RGB sum;
  Ray ray;
  int depth;
};

// The path estimator for n <= K camera samples of one pixel, traced in lockstep: at every depth
// the live lanes' rays are cast together (one packet query), each lane is shaded, then the lanes'
// shadow rays are cast together. A lane's numbers are drawn in the same order whatever the other
// lanes do (light sample, BSDF sample, roulette; its shadow test is known only after all three),
// and its NEE term is added after the test and before its next vertex, so each lane's radiance is
// the one it would get traced alone: bit-identical with K = 1 (tests/integrators_test.cpp), given
// the same hits. A ray that meets two triangles at one distance (e.g. exactly on a shared edge) is
// the exception: Embree's packet and single-ray kernels may report different ones
// (docs/performance.md, "Open observations"); packets depend on the pixel and pass
// alone, so a tile and the frame still trace the same packets.
// Every vertex consumes the same dimensions whether or not it reads them (skipped ones cost
// nothing), so a material change does not reshuffle the random numbers of later bounces.
template <int K, class Packet>
void trace_paths(const RenderContext& ctx, const Ray* camera_rays, Sampler* samplers, int n,
                 RGB* radiance, TraceCounters& counters, const PathResume* resume = nullptr) {
  RF_CHECK(n >= 1 && n <= K, std::to_string(n) + " paths for " + std::to_string(K) + " lanes");
  const IntegratorSettings& settings = ctx.scene.render.integrator;
  using Lane = PathLane;
  Lane lanes[K];
  Packet rays, shadow;
  // In lane space, for the loop that adds the NEE terms: each lane's radiance, its pending NEE
  // term (beta at the vertex times f Le cos w / pdf) and whether its shadow ray was blocked.
  alignas(64) float sum[3][K], nee_term[3][K] = {};
  alignas(64) int blocked[K] = {};
  // With a Sobol sampler the lanes that shade a vertex draw its numbers together, in the order one
  // lane draws them (Sampler::get_lanes): all that some vertex of the scene may read, where one
  // lane alone skips those it does not read; a skip and a draw consume the same dimension, so the
  // values are the same.
  static_assert(K <= Sampler::kMaxLanes);
  static_assert(SurfaceLanes::N == LightSet::kPickLanes);  // pick_entries fills all its lanes
  const bool lockstep_draws = K > 1 && samplers[0].kind() != Sampler::Kind::Independent;
  // The numbers nothing reads are skipped, in the lockstep draws too (a skip consumes the dimension
  // a draw would, so no later number changes): the light choice is read only by the light BVH
  // (selection by power takes the point sample's x), the lobe choice only by the vertices shaded
  // one by one, which a scene whose materials all have a lane kind never has. A skip saves the
  // draw's Owen-scrambled Sobol arithmetic (docs/performance.md, "What the Sobol draws cost").
  const uint8_t light_choice = ctx.lights.uses_bvh();
  const uint8_t lobe_choice = !(K > 1 && ctx.all_in_lanes);
  int shading[K], generic[K];
  // Plain diffuse and rough-conductor vertices are shaded together (SurfaceLanes); their light
  // samples too when all lights are triangles by power, else their lights are picked one by one
  // (and spheres' cones sampled together). Everything is in lane space: lane i's hit, numbers and
  // results in slot i of dl's arrays, where the packet query and the draws wrote them.
  const bool surface_lanes = K > 1, given_light = !ctx.lights.triangles_by_power();
  // All lights spheres by power: their pick and cones in lane space too (lanes_sphere_lights).
  const bool spheres_in_lanes = surface_lanes && ctx.lights.spheres_in_lanes();
  // Per thread, zeroed once: the slots no vertex has filled hold zeros or earlier vertices.
  thread_local SurfaceLanes dl{};
  Accel::PacketHits& hits = dl.hit;
  Sampler::LaneDraws* u = dl.u;
  using D = SurfaceLanes;
  int live = n;
  using S = LaneSlots<K>;
  for (int i = 0; i < K; ++i) S::put(sum, i, RGB(0.0f));
  int first_depth = 0;
  if constexpr (K == 1) {
    if (resume) {
      lanes[0] = resume->lane;
      S::put(sum, 0, resume->sum);
      rays.set(0, resume->ray);
      first_depth = resume->depth;
    }
  }
  if (!resume)
    for (int i = 0; i < n; ++i) {
      rays.set(i, camera_rays[i]);
      lanes[i].prev_p = camera_rays[i].o;
    }
  for (int depth = first_depth; live > 0; ++depth) {
    // One live lane left after the camera rays: the one-lane loop takes it over, with Embree's
    // single-ray queries and the one-vertex code (a packet step with one lane costs about what
    // sixteen slots of loops and a 16-wide query cost, well above a one-lane step;
    // docs/performance.md, "Where a render's time goes"). The lane's numbers and terms are those
    // it gets traced alone from its camera ray (the packet test), so its radiance keeps its bits.
    if constexpr (K > 1) {
      if (live == 1 && depth > 0) {
        int i = 0;
        while (!rays.active(i)) ++i;
        const PathResume r{lanes[i], S::get(sum, i), rays.ray(i), depth};
        RGB alone;
        trace_paths<1, SingleRay>(ctx, nullptr, samplers + i, 1, &alone, counters, &r);
        S::put(sum, i, alone);
        break;
      }
    }
    counters.rays += uint64_t(live);
    // The camera rays of one pixel as a coherent packet (docs/performance.md, "The path tracer's
    // inner loop"); the later rays and the shadow rays as incoherent ones: marked coherent they
    // are no faster (docs/performance.md, "What was tried and not taken").
    intersect(ctx.accel, rays, n, hits, depth == 0);
    const bool roulette = depth + 1 >= settings.rr_min_depth;
    // A diffuse vertex at the last depth ends its path after its light sample, which takes the
    // full weight: its BSDF ray would be cast only for the emission it hits at depth max_depth,
    // weighted by MIS against that light sample, and a Lambertian lobe's share of that is small
    // (veach-mis: at most 2e-4 in a pixel at 256 spp) for a closest-hit query. The same expected
    // value (light sampling alone is unbiased: every light it can miss emits nothing towards the
    // vertex); other lobes keep both strategies (a glossy lobe's light samples alone are noisy).
    const bool last = depth + 1 == settings.max_depth;
    if (lockstep_draws && depth < settings.max_depth) {
      int m = 0;
      for (int i = 0; i < n; ++i)  // without a branch (found: traced and hit)
        shading[m] = i, m += hits.found[i] != 0;
      const uint8_t draws[kVertexDraws] = {light_choice, vertex_draw(depth, kPointPair),
                                           lobe_choice, vertex_draw(depth, kDirPair),
                                           uint8_t(roulette)};
      Sampler::get_lanes(samplers, shading, m, draws, kVertexDraws, u);
    }
    bool any_shadow = false, conductors = false;
    int generics = 0;
    dl.m = 0;
    // The lanes' hits: escaped rays and emission, then plain vertices to the loops (dl.lane) and
    // the others to the one-by-one shading below (generic).
    for (int i = 0; i < n; ++i) {
      shadow.clear(i);
      if (!rays.active(i)) continue;
      Lane& a = lanes[i];
      Sampler& sampler = samplers[i];
      const Vec3 wo = -rays.ray(i).d;
      if (!hits.found[i]) {
        RGB r = S::get(sum, i);
        add_escaped(ctx, -wo, a.prev_delta, a.prev_bsdf_pdf, a.beta, r);
        S::put(sum, i, r);
        rays.clear(i), --live;
        continue;
      }
      const Mesh& mesh = ctx.accel.mesh(hits.mesh[i]);
      a.cone_width += ctx.pixel_spread * hits.t[i];
      const Vec3 ng = D::get(hits.ng, i);
      RGB le = LightSet::emitted(mesh, ng, wo);
      if (!is_black(le)) {
        if (a.prev_delta) {
          S::put(sum, i, S::get(sum, i) + a.beta * le);
        } else {
          float light_pdf = ctx.lights.pdf_solid_angle(a.prev_p, a.prev_n, hits.mesh[i],
                                                       hits.prim[i], D::get(hits.p, i), ng);
          S::put(sum, i,
                 S::get(sum, i) + a.beta * le * power_heuristic(a.prev_bsdf_pdf, light_pdf));
        }
      }
      if (depth == settings.max_depth) {
        rays.clear(i), --live;
        continue;
      }
      const Material& material = ctx.scene.materials[mesh.material];
      const LaneKind kind = ctx.lane_kinds[mesh.material];
      const bool rough_conductor = surface_lanes && kind == LaneKind::RoughConductor;
      D::put(dl.wo, i, wo);  // (lanes_to_packets overwrites the ray packet below)
      if (!(surface_lanes && kind != LaneKind::OneByOne)) {
        generic[generics++] = i;
        continue;
      }
      dl.lane[dl.m++] = i;
      D::put(dl.reflectance, i, material.reflectance.value);
      dl.conductor[i] = rough_conductor;
      if (rough_conductor) {  // Bsdf::make's lobe of constant_params(material)
        conductors = true;
        ++counters.conductor_lane_vertices;
        dl.c_alpha[i] = material.roughness.value, dl.c_separable[i] = material.separable_masking;
        D::put(dl.c_eta, i, material.eta), D::put(dl.c_k, i, material.k);
        D::put(dl.c_tint, i, material.specular.value), dl.c_use_tint[i] = material.conductor_tint;
      }
      D::put(dl.beta, i, a.beta);
      dl.eta_scale[i] = a.eta_scale;
      dl.roulette[i] = roulette;
      dl.last[i] = last;
      // Without lockstep draws, this lane's numbers in the one-lane order (the lobe choice is not
      // read); with them, u[kURoulette] is read only where roulette runs.
      if (!lockstep_draws) {
        u[kULight][0][i] = sampler.get_1d_if(light_choice);
        const Vec2 u_point = vertex_2d(sampler, true, depth, kPointPair);
        sampler.skip_1d();
        const Vec2 u_dir = vertex_2d(sampler, true, depth, kDirPair);
        u[kUPoint][0][i] = u_point.x, u[kUPoint][1][i] = u_point.y;
        u[kUDir][0][i] = u_dir.x, u[kUDir][1][i] = u_dir.y;
        // Drawn before the sample is known to succeed: a lane whose sample fails ends, and
        // nothing reads its sampler after that, so the extra draw changes no value.
        u[kURoulette][0][i] = sampler.get_1d_if(roulette);
      }
      if (given_light && !spheres_in_lanes) {  // as light_sample_mis_unshadowed() takes it
        const Vec3 p = D::get(hits.p, i);
        const Vec3 receiver = dot(wo, ng) >= 0 ? ng : -ng;
        size_t light;
        float pmf;
        LightSet::SphereCone c;
        Vec2 u_point{u[kUPoint][0][i], u[kUPoint][1][i]};
        const bool picked = ctx.lights.pick(p, receiver, u[kULight][0][i], u_point, light, pmf);
        u[kUPoint][0][i] = u_point.x, u[kUPoint][1][i] = u_point.y;
        const bool sphere = picked && ctx.lights.sphere_cone_of(light, p, c);
        dl.l_sphere[i] = sphere;
        if (sphere) {  // sampled in the loops
          dl.l_delta[i] = false, dl.l_pmf[i] = pmf;
          D::put(dl.s_center, i, c.center), D::put(dl.s_pole, i, c.pole);
          dl.s_radius[i] = c.radius, dl.s_sin2_max[i] = c.sin2_max;
          dl.s_cos_max[i] = c.cos_max, dl.s_omc[i] = c.one_minus_cos_max;
          D::put(dl.l_radiance, i, c.emission.radiance);
          dl.l_two_sided[i] = c.emission.two_sided;
          continue;
        }
        LightSample ls;
        const bool ok = picked && ctx.lights.sample_selected(light, pmf, p, u_point, ls);
        dl.g_ok[i] = ok;
        D::put(dl.g_wi, i, ls.wi), D::put(dl.g_radiance, i, ls.radiance);
        dl.g_pdf[i] = ls.pdf_solid_angle, dl.l_delta[i] = ls.is_delta;
        if (ok) {
          const Ray r = light_shadow_ray(ctx, hits.hit(i), ls);
          D::put(dl.g_shadow_o, i, r.o), D::put(dl.g_shadow_d, i, r.d);
          dl.g_shadow_tmax[i] = r.tmax;
        }
      }
    }
    if constexpr (K > 1)
      if (dl.m > 0) {
        counters.lane_vertices += uint64_t(dl.m);
        if (given_light) {
          if (spheres_in_lanes) {
            alignas(64) float ux[SurfaceLanes::N];
            alignas(64) uint32_t entry[SurfaceLanes::N];
            for (int i = 0; i < SurfaceLanes::N; ++i) ux[i] = u[kUPoint][0][i];
            ctx.lights.pick_sphere_entries(ux, entry);  // ux rescaled
            // Only the plain lanes take the rescaled x: a generic lane's pick (below) rescales
            // its own, as it does alone.
            for (int j = 0; j < dl.m; ++j) u[kUPoint][0][dl.lane[j]] = ux[dl.lane[j]];
            lanes_sphere_lights(dl, ctx.lights.sphere_table(), entry);
            // A point inside its sphere: the light sampled one by one (sample_selected).
            for (int j = 0; j < dl.m; ++j) {
              const int i = dl.lane[j];
              if (dl.l_sphere[i]) continue;
              const LightSet::SphereTable& st = ctx.lights.sphere_table();
              const Vec2 u_point{u[kUPoint][0][i], u[kUPoint][1][i]};
              LightSample ls;
              const bool ok = ctx.lights.sample_selected(st.light[entry[i]], st.pmf[entry[i]],
                                                         D::get(hits.p, i), u_point, ls);
              dl.g_ok[i] = ok;
              D::put(dl.g_wi, i, ls.wi), D::put(dl.g_radiance, i, ls.radiance);
              dl.g_pdf[i] = ls.pdf_solid_angle, dl.l_delta[i] = ls.is_delta;
              if (ok) {
                const Ray r = light_shadow_ray(ctx, hits.hit(i), ls);
                D::put(dl.g_shadow_o, i, r.o), D::put(dl.g_shadow_d, i, r.d);
                dl.g_shadow_tmax[i] = r.tmax;
              }
            }
          }
          diffuse_lanes_sphere_angles(dl);
          diffuse_lanes_sphere_points(dl);
          diffuse_lanes_nee<true>(dl);
        } else if (ctx.lights.pick_in_lanes()) {  // picked in lane space, all slots together
          alignas(64) float ux[SurfaceLanes::N];
          alignas(64) uint32_t entry[SurfaceLanes::N];
          alignas(64) int plain[SurfaceLanes::N] = {};
          for (int i = 0; i < SurfaceLanes::N; ++i) ux[i] = u[kUPoint][0][i];
          ctx.lights.pick_entries(ux, entry);
          for (int j = 0; j < dl.m; ++j) plain[dl.lane[j]] = 1;
          lanes_picked_lights(dl, ctx.lights.pick_table(), entry, ux, plain);
          diffuse_lanes_nee<false>(dl);
        } else {
          // Picked lane by lane as select() picks (LightSet::pick_triangles), back into the slots.
          float ux[SurfaceLanes::N];
          uint32_t picked[SurfaceLanes::N];
          for (int j = 0; j < dl.m; ++j) ux[j] = u[kUPoint][0][dl.lane[j]];
          ctx.lights.pick_triangles(ux, dl.m, picked);
          for (int j = 0; j < dl.m; ++j) {
            const int i = dl.lane[j];
            u[kUPoint][0][i] = ux[j];
            dl.light_ok[i] = picked[j] != LightSet::kNoPick;
            const LightSet::TriangleLight t =
                dl.light_ok[i] ? ctx.lights.triangle_light(picked[j]) : LightSet::TriangleLight{};
            D::put(dl.l_p0, i, t.p0), D::put(dl.l_p1, i, t.p1), D::put(dl.l_p2, i, t.p2);
            D::put(dl.l_n, i, t.n), D::put(dl.l_radiance, i, t.emission.radiance);
            dl.l_area[i] = t.area, dl.l_pmf[i] = t.pmf, dl.l_two_sided[i] = t.emission.two_sided;
          }
          diffuse_lanes_nee<false>(dl);
        }
        if (!last) diffuse_lanes_continue(dl);  // else the diffuse lanes end here
        if (conductors) conductor_lanes(dl);
        // Every slot's spawned and shadow rays into the packets; only the plain lanes' are read
        // (the others are inactive, or a generic lane's, set again below).
        lanes_to_packets(dl, rays.rh, shadow.rh.ray);
        // Without branches (the lanes' patterns mispredict them): a lane that ends keeps the
        // state it is given here unread.
        int shadows = 0, ends = 0;
        for (int j = 0; j < dl.m; ++j) {
          const int i = dl.lane[j];
          Lane& a = lanes[i];
          const bool c = dl.conductor[i] != 0;  // the conductor loop's results, else the diffuse
          const bool nee_ok =
              c ? (dl.ls_ok[i] != 0) & !is_black(D::get(dl.c_f, i)) : dl.nee_ok[i] != 0;
          S::put(
              nee_term, i,
              a.beta * (c ? vselect(nee_ok, D::get(dl.c_nee, i), RGB(0.0f)) : D::get(dl.nee, i)));
          shadow.activate_if(i, nee_ok);
          shadows += nee_ok;
          const SurfaceLanes::Continuation& next = c ? dl.c_cont : dl.cont;
          const bool lives = (next.continues[i] != 0) & (next.survives[i] != 0) &
                             (!c | (next.bsdf_pdf[i] > 0)) & (c | !last);
          rays.activate_if(i, lives);
          ends += !lives;
          a.beta = D::get(next.beta_out, i);
          a.prev_bsdf_pdf = next.bsdf_pdf[i];
          a.prev_delta = false;
          a.prev_p = D::get(hits.p, i);
          a.prev_n = D::get(dl.receiver_n, i);
        }
        any_shadow |= shadows > 0;
        counters.rays += uint64_t(shadows);
        live -= ends;
      }
    // The other vertices, one by one.
    for (int g = 0; g < generics; ++g) {
      const int i = generic[g];
      Lane& a = lanes[i];
      Sampler& sampler = samplers[i];
      const SurfaceHit hit = hits.hit(i);
      const Vec3 wo = D::get(dl.wo, i);
      Bsdf bsdf = bsdf_at(ctx, hit, a.cone_width);
      const bool nee = !bsdf.is_delta();
      const bool ends = last && bsdf.is_diffuse();  // see `last`
      float u_light = lockstep_draws ? u[kULight][0][i] : sampler.get_1d_if(nee);
      Vec2 u_point = lockstep_draws ? Vec2{u[kUPoint][0][i], u[kUPoint][1][i]}
                                    : vertex_2d(sampler, nee, depth, kPointPair);
      if (nee) {
        Ray r;
        RGB l;
        if (light_sample_mis_unshadowed(ctx, hit, bsdf, wo, u_light, u_point, l, r, !ends)) {
          S::put(nee_term, i, a.beta * l);
          shadow.set(i, r);
          any_shadow = true;
          ++counters.rays;
        }
      }
      if (ends) {
        rays.clear(i), --live;
        continue;
      }
      BsdfSample bs;
      float uc = lockstep_draws ? u[kUChoice][0][i] : sampler.get_1d_if(bsdf.sample_uses_choice());
      Vec2 u_dir = lockstep_draws
                       ? Vec2{u[kUDir][0][i], u[kUDir][1][i]}
                       : vertex_2d(sampler, bsdf.sample_uses_direction(), depth, kDirPair);
      if (!bsdf.sample(wo, uc, u_dir, TransportMode::Radiance, bs)) {
        rays.clear(i), --live;
        continue;
      }
      float cos_i = std::fabs(dot(bs.wi, bsdf.shading_normal()));
      a.beta *= bs.f * (cos_i / bs.pdf_solid_angle);
      if (bs.is_transmission) a.eta_scale *= sqr(bs.eta);
      a.prev_bsdf_pdf = bs.pdf_solid_angle;
      a.prev_delta = bs.is_delta;
      a.prev_p = hit.p;
      a.prev_n = receiver_normal(bsdf, wo);
      rays.set(i, ctx.accel.spawn(hit, bs.wi));
      float u_rr = lockstep_draws ? u[kURoulette][0][i] : sampler.get_1d_if(roulette);
      if (roulette) {
        float survive = std::min(1.0f, max_component(a.beta * a.eta_scale));
        if (u_rr >= survive) {
          rays.clear(i), --live;
          continue;
        }
        a.beta = a.beta / survive;
      }
    }
    if (any_shadow) occluded(ctx.accel, shadow, n, blocked);
    // The NEE terms whose shadow rays got through, as selects in lane space (a lane's shadow ray
    // is active only after its term is written; branches on the lanes' patterns mispredict).
    for (int i = 0; i < K; ++i) {
      const bool add = shadow.active(i) & (blocked[i] == 0);
      sum[0][i] = add ? sum[0][i] + nee_term[0][i] : sum[0][i];
      sum[1][i] = add ? sum[1][i] + nee_term[1][i] : sum[1][i];
      sum[2][i] = add ? sum[2][i] + nee_term[2][i] : sum[2][i];
    }
  }
  for (int i = 0; i < n; ++i) radiance[i] = S::get(sum, i);
}

}  // namespace

void path_radiance(const RenderContext& ctx, const Ray* rays, Sampler* samplers, int n,
                   RGB* radiance, TraceCounters& counters, bool packets) {
  if (packets && n > 1)
    trace_paths<Accel::kPacket, Accel::RayPacket>(ctx, rays, samplers, n, radiance, counters);
  else
    for (int i = 0; i < n; ++i)
      trace_paths<1, SingleRay>(ctx, rays + i, samplers + i, 1, radiance + i, counters);
}

SampleBuffer PathIntegrator::render(const RenderContext& ctx, const TaskKey& task,
                                    bool parallel) const {
  return render_camera_paths<false>(
      ctx, task, parallel,
      [&](const Ray* rays, Sampler* samplers, int n, RGB* radiance, TraceCounters& counters) {
        path_radiance(ctx, rays, samplers, n, radiance, counters);
      });
}

}  // namespace rf
