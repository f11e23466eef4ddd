// The path tracer's vectorised kernels: see surface_lanes.h.
#include "engine/integrators/path/surface_lanes.h"

#include <algorithm>
#include <cmath>

#include "engine/lights/light_sampling.h"

namespace rf {

// The sphere cones' angles (sphere_cone_angles), for every slot.
RF_SIMD_CLONES void diffuse_lanes_sphere_angles(SurfaceLanes& L) {
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j)  // all N: see SurfaceLanes
    sphere_cone_angles(L.s_sin2_max[j], L.s_cos_max[j], {L.u[kUPoint][0][j], L.u[kUPoint][1][j]},
                       L.s_cos_alpha[j], L.s_sin_alpha[j], L.s_cos_phi[j], L.s_sin_phi[j]);
}

// The sphere cones' points: the rest of sample_selected() (sphere_cone_point, with_selection),
// the light sample of the slots whose light is a sphere (l_sphere), the given one (g_*) of the
// others; then their shadow rays (a loop of its own: GCC 12 does not vectorise the two as one).
RF_SIMD_CLONES void diffuse_lanes_sphere_points(SurfaceLanes& L) {
  using D = SurfaceLanes;
  RF_IVDEP
  for (int j = 0; j < SurfaceLanes::N; ++j) {  // all N: see SurfaceLanes
    const Vec3 p = D::get(L.hit.p, j);
    SphereCone c{D::get(L.s_center, j),
                 D::get(L.s_pole, j),
                 L.s_radius[j],
                 L.s_sin2_max[j],
                 L.s_cos_max[j],
                 L.s_omc[j],
                 {D::get(L.l_radiance, j), L.l_two_sided[j] != 0}};
    LightSample ls;
    bool ok = sphere_cone_point(c, p, L.s_cos_alpha[j], L.s_sin_alpha[j], L.s_cos_phi[j],
                                L.s_sin_phi[j], ls);
    ok = with_selection(ok, L.l_pmf[j], ls);
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
                                  D::get(L.l_p0, j), D::get(L.l_p1, j), D::get(L.l_n, j),
                                  0.0f);  // the time: the packet's arrays keep the lane's
    const bool sphere = L.l_sphere[j] != 0;
    D::put(L.shadow_o, j, vselect(sphere, r.o, D::get(L.g_shadow_o, j)));
    D::put(L.shadow_d, j, vselect(sphere, r.d, D::get(L.g_shadow_d, j)));
    L.shadow_tmax[j] = sphere ? r.tmax : L.g_shadow_tmax[j];
  }
}

template <bool kGivenLight>
[[gnu::always_inline]] inline void diffuse_lanes_nee(SurfaceLanes& L) {
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
      TriangleLight t{D::get(L.l_p0, j),
                      D::get(L.l_p1, j),
                      D::get(L.l_p2, j),
                      D::get(L.l_n, j),
                      L.l_area[j],
                      L.l_pmf[j],
                      {D::get(L.l_radiance, j), L.l_two_sided[j] != 0}};
      ok = sample_triangle(t, p, {L.u[kUPoint][0][j], L.u[kUPoint][1][j]}, ls);
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
    w = L.last[j] != 0 ? 1.0f : w;  // light sampling the only strategy (PacketPaths' `last_`)
    D::put(L.ls_wi, j, ls.wi), D::put(L.ls_radiance, j, ls.radiance);
    L.ls_pdf[j] = ls.pdf_solid_angle, L.ls_ok[j] = light;
    L.ls_delta[j] = kGivenLight ? L.l_delta[j] : 0;
    float cos_i = std::fabs(dot(ls.wi, frame.n));
    RGB c = f * ls.radiance * (cos_i * w / ls.pdf_solid_angle);
    L.nee_ok[j] = ok;
    if constexpr (!kGivenLight) {
      // The time: the packet's arrays keep the lane's (PacketPaths::trace).
      Ray shadow = Accel::shadow_segment(p, p_error, ng, ls.p, ls.p_error, ls.n, 0.0f);
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

RF_SIMD_CLONES void diffuse_lanes_nee_given_light(SurfaceLanes& L) { diffuse_lanes_nee<true>(L); }
RF_SIMD_CLONES void diffuse_lanes_nee_triangles(SurfaceLanes& L) { diffuse_lanes_nee<false>(L); }

// The end of slot j's vertex once its BSDF sample bs is known (ok: not failed), as the one-lane
// loop ends a vertex: throughput, spawned ray, BSDF pdf, roulette; into `out`.
[[gnu::always_inline]] inline void continue_slot(const SurfaceLanes& L, int j, Vec3 p, Vec3 p_error,
                                                 Vec3 ng, const Frame& frame, const BsdfSample& bs,
                                                 bool ok, SurfaceLanes::Continuation& out) {
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

// The lights LaneLights::pick_entries picked (entry[j] of the pick table) into every slot's light
// arrays, and its rescaled numbers ux into u[kUPoint] of the slots where plain[j] (the others
// keep their own for their one-by-one shading). Selects over the table's few entries, which
// vectorise where indexed loads would not (GCC's generic tuning emits no gathers).
RF_SIMD_CLONES void lanes_picked_lights(SurfaceLanes& L, const LaneLights::PickTable& T,
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

// The spheres LaneLights::pick_sphere_entries picked (entry[j] of the sphere table) into every
// slot's sphere arrays, with the cone each subtends from the slot's hit point
// (sphere_cone): l_sphere where the point is outside its sphere (sampled in the loops); a point
// inside is sampled one by one afterwards. Selects over the table's few entries, as
// lanes_picked_lights.
RF_SIMD_CLONES void lanes_sphere_lights(SurfaceLanes& L, const LaneLights::SphereTable& T,
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
    L.l_sphere[j] = sphere_cone(D::get(L.s_center, j), L.s_radius[j], D::get(L.hit.p, j),
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

}  // namespace rf
