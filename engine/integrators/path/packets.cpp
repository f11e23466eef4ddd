// The path tracer's packets: see packets.h.
#include "engine/integrators/path/packets.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "engine/check.h"
#include "engine/integrators/path/path_tracer.h"
#include "engine/integrators/sample_layout.h"

namespace rf {

// The phases are functions of their own for the reader, and one function for the compiler: a
// depth's state stays in registers across them, as it did when they were one loop.
#define RF_PHASE [[gnu::always_inline]] inline

thread_local SurfaceLanes PacketPaths::dl_{};

PacketPaths::PacketPaths(const RenderContext& ctx, const LaneLights& lights, Sampler* samplers,
                         int n, TraceCounters& counters)
    : ctx_(ctx),
      lane_lights_(lights),
      settings_(ctx.scene.render.integrator),
      samplers_(samplers),
      n_(n),
      counters_(counters),
      lockstep_draws_(samplers[0].kind() != Sampler::Kind::Independent),
      light_choice_(ctx.lights.uses_bvh()),
      lobe_choice_(!ctx.all_in_lanes),
      given_light_(!lights.triangles_by_power()),
      spheres_in_lanes_(lights.spheres_in_lanes()),
      live_(n) {
  RF_CHECK(n >= 2 && n <= K, std::to_string(n) + " paths for a packet of " + std::to_string(K));
  static_assert(K <= Sampler::kMaxLanes);
  static_assert(SurfaceLanes::N == LaneLights::kLanes);  // pick_entries fills all its lanes
}

// One live lane left after the camera rays: the one-lane loop takes it over, with Embree's
// single-ray queries and the one-vertex code (a packet step with one lane costs about what
// sixteen slots of loops and a 16-wide query cost, well above a one-lane step;
// docs/performance.md, "Where a render's time goes"). The lane's numbers and terms are those it
// gets traced alone from its camera ray (the packet test), so its radiance keeps its bits.
RF_PHASE bool PacketPaths::hand_off(int depth) {
  if (live_ != 1 || depth == 0) return false;
  int i = 0;
  while (!rays_.active(i)) ++i;
  S::put(
      sum_, i,
      trace_alone(ctx_, lanes_[i], S::get(sum_, i), rays_.ray(i), depth, samplers_[i], counters_));
  return true;
}

// The camera rays of one pixel as a coherent packet (docs/performance.md, "The path tracer's
// inner loop"); the later rays and the shadow rays as incoherent ones: marked coherent they are
// no faster (docs/performance.md, "What was tried and not taken").
RF_PHASE void PacketPaths::intersect(int depth) {
  counters_.rays += uint64_t(live_);
  ctx_.accel.intersect_packet(rays_, n_, dl_.hit, depth == 0);
  roulette_ = depth + 1 >= settings_.rr_min_depth;
  // A diffuse vertex at the last depth ends its path after its light sample (trace_alone says
  // why); other lobes keep both strategies.
  last_ = depth + 1 == settings_.max_depth;
}

// With lockstep draws, the numbers of every lane that hits something, at once.
RF_PHASE void PacketPaths::draw(int depth) {
  if (!lockstep_draws_ || depth >= settings_.max_depth) return;
  int m = 0;
  for (int i = 0; i < n_; ++i)  // without a branch (found: traced and hit)
    shading_[m] = i, m += dl_.hit.found[i] != 0;
  const uint8_t draws[kVertexDraws] = {light_choice_, vertex_draw(depth, kPointPair), lobe_choice_,
                                       vertex_draw(depth, kDirPair), uint8_t(roulette_)};
  Sampler::get_lanes(samplers_, shading_, m, draws, kVertexDraws, dl_.u);
}

// The lanes' hits: escaped rays and emission, then plain vertices to the kernels (dl_.lane) and
// the others to shade_rest (generic_).
RF_PHASE void PacketPaths::arrive(int depth) {
  Accel::PacketHits& hits = dl_.hit;
  Sampler::LaneDraws* u = dl_.u;
  any_shadow_ = false, conductors_ = false;
  generics_ = 0;
  dl_.m = 0;
  for (int i = 0; i < n_; ++i) {
    shadow_.clear(i);
    if (!rays_.active(i)) continue;
    CameraPath& a = lanes_[i];
    const Vec3 wo = -rays_.ray(i).d;
    if (!hits.found[i]) {
      RGB r = S::get(sum_, i);
      a.escape(ctx_, -wo, r);
      S::put(sum_, i, r);
      rays_.clear(i), --live_;
      continue;
    }
    const Mesh& mesh = ctx_.accel.mesh(hits.mesh[i]);
    a.widen_cone(ctx_, hits.t[i]);
    RGB term;
    if (a.emission(ctx_, mesh, hits.mesh[i], hits.prim[i], D::get(hits.p, i), D::get(hits.ng, i),
                   wo, hits.time[i], term))
      S::put(sum_, i, S::get(sum_, i) + term);
    if (depth == settings_.max_depth) {
      rays_.clear(i), --live_;
      continue;
    }
    const Material& material = ctx_.scene.materials[mesh.material];
    const LaneKind kind = ctx_.lane_kinds[mesh.material];
    const bool rough_conductor = kind == LaneKind::RoughConductor;
    D::put(dl_.wo, i, wo);  // (lanes_to_packets overwrites the ray packet)
    if (kind == LaneKind::OneByOne) {
      generic_[generics_++] = i;
      continue;
    }
    dl_.lane[dl_.m++] = i;
    D::put(dl_.reflectance, i, material.reflectance.value);
    dl_.conductor[i] = rough_conductor;
    if (rough_conductor) {  // Bsdf::make's lobe of constant_params(material)
      conductors_ = true;
      ++counters_.conductor_lane_vertices;
      dl_.c_alpha[i] = material.roughness.value, dl_.c_separable[i] = material.separable_masking;
      D::put(dl_.c_eta, i, material.eta), D::put(dl_.c_k, i, material.k);
      D::put(dl_.c_tint, i, material.specular.value), dl_.c_use_tint[i] = material.conductor_tint;
    }
    D::put(dl_.beta, i, a.beta);
    dl_.eta_scale[i] = a.eta_scale;
    dl_.roulette[i] = roulette_;
    dl_.last[i] = last_;
    // Without lockstep draws, this lane's numbers in the one-lane order (the lobe choice is not
    // read); with them, u[kURoulette] is read only where roulette runs.
    if (!lockstep_draws_) {
      Sampler& sampler = samplers_[i];
      u[kULight][0][i] = sampler.get_1d_if(light_choice_);
      const Vec2 u_point = vertex_2d(sampler, true, depth, kPointPair);
      sampler.skip_1d();
      const Vec2 u_dir = vertex_2d(sampler, true, depth, kDirPair);
      u[kUPoint][0][i] = u_point.x, u[kUPoint][1][i] = u_point.y;
      u[kUDir][0][i] = u_dir.x, u[kUDir][1][i] = u_dir.y;
      // Drawn before the sample is known to succeed: a lane whose sample fails ends, and
      // nothing reads its sampler after that, so the extra draw changes no value.
      u[kURoulette][0][i] = sampler.get_1d_if(roulette_);
    }
  }
}

// The plain vertices' light samples as light_sample_mis_unshadowed() takes them, one by one
// (other lights than triangles by power or spheres in lanes): a sphere seen from outside goes to
// the sphere loops, any other light is sampled here into the given sample (g_*).
RF_PHASE void PacketPaths::sample_lights_one_by_one() {
  const Accel::PacketHits& hits = dl_.hit;
  Sampler::LaneDraws* u = dl_.u;
  for (int j = 0; j < dl_.m; ++j) {
    const int i = dl_.lane[j];
    const Vec3 p = D::get(hits.p, i), ng = D::get(hits.ng, i), wo = D::get(dl_.wo, i);
    const Vec3 receiver = dot(wo, ng) >= 0 ? ng : -ng;
    size_t light;
    float pmf;
    SphereCone c;
    Vec2 u_point{u[kUPoint][0][i], u[kUPoint][1][i]};
    const bool picked = ctx_.lights.pick(p, receiver, u[kULight][0][i], u_point, light, pmf);
    u[kUPoint][0][i] = u_point.x, u[kUPoint][1][i] = u_point.y;
    const bool sphere = picked && ctx_.lights.sphere_cone_of(light, p, c);
    dl_.l_sphere[i] = sphere;
    if (sphere) {  // sampled in the loops
      dl_.l_delta[i] = false, dl_.l_pmf[i] = pmf;
      D::put(dl_.s_center, i, c.center), D::put(dl_.s_pole, i, c.pole);
      dl_.s_radius[i] = c.radius, dl_.s_sin2_max[i] = c.sin2_max;
      dl_.s_cos_max[i] = c.cos_max, dl_.s_omc[i] = c.one_minus_cos_max;
      D::put(dl_.l_radiance, i, c.emission.radiance);
      dl_.l_two_sided[i] = c.emission.two_sided;
      continue;
    }
    LightSample ls;
    const bool ok =
        picked && ctx_.lights.sample_selected(light, pmf, p, u_point, ls, ctx_.at(hits.time[i]));
    give_light_sample(i, ok, ls);
  }
}

// Spheres in lanes: a plain vertex inside its picked sphere samples it one by one
// (sample_selected), into the given sample.
RF_PHASE void PacketPaths::sample_spheres_inside(const uint32_t* entry) {
  const Accel::PacketHits& hits = dl_.hit;
  const LaneLights::SphereTable& st = lane_lights_.sphere_table();
  for (int j = 0; j < dl_.m; ++j) {
    const int i = dl_.lane[j];
    if (dl_.l_sphere[i]) continue;
    const Vec2 u_point{dl_.u[kUPoint][0][i], dl_.u[kUPoint][1][i]};
    LightSample ls;
    const bool ok =
        ctx_.lights.sample_selected(st.light[entry[i]], st.pmf[entry[i]], D::get(hits.p, i),
                                    u_point, ls, ctx_.at(hits.time[i]));
    give_light_sample(i, ok, ls);
  }
}

// A light sample taken one by one (ok: it succeeded) into slot i's given sample and shadow ray,
// which the sphere loops select where the slot's light is not a sphere seen from outside.
RF_PHASE void PacketPaths::give_light_sample(int i, bool ok, const LightSample& ls) {
  dl_.g_ok[i] = ok;
  D::put(dl_.g_wi, i, ls.wi), D::put(dl_.g_radiance, i, ls.radiance);
  dl_.g_pdf[i] = ls.pdf_solid_angle, dl_.l_delta[i] = ls.is_delta;
  if (ok) {
    const Ray r = light_shadow_ray(ctx_, dl_.hit.hit(i), ls);
    D::put(dl_.g_shadow_o, i, r.o), D::put(dl_.g_shadow_d, i, r.d);
    dl_.g_shadow_tmax[i] = r.tmax;
  }
}

// The plain vertices in the kernels: their light samples (picked in lane space where the lights
// allow it), NEE terms, BSDF samples and continuations, then their rays into the packets.
RF_PHASE void PacketPaths::shade_lanes() {
  if (dl_.m == 0) return;
  counters_.lane_vertices += uint64_t(dl_.m);
  Sampler::LaneDraws* u = dl_.u;
  constexpr int N = SurfaceLanes::N;
  if (given_light_) {
    if (spheres_in_lanes_) {
      alignas(64) float ux[N];
      alignas(64) uint32_t entry[N];
      for (int i = 0; i < N; ++i) ux[i] = u[kUPoint][0][i];
      lane_lights_.pick_sphere_entries(ux, entry);  // ux rescaled
      // Only the plain lanes take the rescaled x: a generic lane's pick (shade_rest) rescales
      // its own, as it does alone.
      for (int j = 0; j < dl_.m; ++j) u[kUPoint][0][dl_.lane[j]] = ux[dl_.lane[j]];
      lanes_sphere_lights(dl_, lane_lights_.sphere_table(), entry);
      sample_spheres_inside(entry);
    } else {
      sample_lights_one_by_one();
    }
    diffuse_lanes_sphere_angles(dl_);
    diffuse_lanes_sphere_points(dl_);
    diffuse_lanes_nee_given_light(dl_);
  } else if (lane_lights_.pick_in_lanes()) {  // picked in lane space, all slots together
    alignas(64) float ux[N];
    alignas(64) uint32_t entry[N];
    alignas(64) int plain[N] = {};
    for (int i = 0; i < N; ++i) ux[i] = u[kUPoint][0][i];
    lane_lights_.pick_entries(ux, entry);
    for (int j = 0; j < dl_.m; ++j) plain[dl_.lane[j]] = 1;
    lanes_picked_lights(dl_, lane_lights_.pick_table(), entry, ux, plain);
    diffuse_lanes_nee_triangles(dl_);
  } else {
    // Picked lane by lane as LightSelection::select picks, back into the slots.
    float ux[N];
    uint32_t picked[N];
    for (int j = 0; j < dl_.m; ++j) ux[j] = u[kUPoint][0][dl_.lane[j]];
    lane_lights_.pick_triangles(ux, dl_.m, picked);
    for (int j = 0; j < dl_.m; ++j) {
      const int i = dl_.lane[j];
      u[kUPoint][0][i] = ux[j];
      dl_.light_ok[i] = picked[j] != LaneLights::kNoPick;
      const TriangleLight t =
          dl_.light_ok[i] ? ctx_.lights.triangle_light(picked[j]) : TriangleLight{};
      D::put(dl_.l_p0, i, t.p0), D::put(dl_.l_p1, i, t.p1), D::put(dl_.l_p2, i, t.p2);
      D::put(dl_.l_n, i, t.n), D::put(dl_.l_radiance, i, t.emission.radiance);
      dl_.l_area[i] = t.area, dl_.l_pmf[i] = t.pmf, dl_.l_two_sided[i] = t.emission.two_sided;
    }
    diffuse_lanes_nee_triangles(dl_);
  }
  if (!last_) diffuse_lanes_continue(dl_);  // else the diffuse lanes end here
  if (conductors_) conductor_lanes(dl_);
  // Every slot's spawned and shadow rays into the packets; only the plain lanes' are read (the
  // others are inactive, or a generic lane's, set again in shade_rest).
  lanes_to_packets(dl_, rays_.rh, shadow_.rh.ray);
  lane_results();
}

// The kernels' results into the lanes' states, without branches (the lanes' patterns mispredict
// them): a lane that ends keeps the state it is given here unread.
RF_PHASE void PacketPaths::lane_results() {
  int shadows = 0, ends = 0;
  for (int j = 0; j < dl_.m; ++j) {
    const int i = dl_.lane[j];
    CameraPath& a = lanes_[i];
    const bool c = dl_.conductor[i] != 0;  // the conductor loop's results, else the diffuse
    const bool nee_ok =
        c ? (dl_.ls_ok[i] != 0) & !is_black(D::get(dl_.c_f, i)) : dl_.nee_ok[i] != 0;
    S::put(nee_term_, i,
           a.beta * (c ? vselect(nee_ok, D::get(dl_.c_nee, i), RGB(0.0f)) : D::get(dl_.nee, i)));
    shadow_.activate_if(i, nee_ok);
    shadows += nee_ok;
    const SurfaceLanes::Continuation& next = c ? dl_.c_cont : dl_.cont;
    const bool lives = (next.continues[i] != 0) & (next.survives[i] != 0) &
                       (!c | (next.bsdf_pdf[i] > 0)) & (c | !last_);
    rays_.activate_if(i, lives);
    ends += !lives;
    a.beta = D::get(next.beta_out, i);
    a.prev_bsdf_pdf = next.bsdf_pdf[i];
    a.prev_delta = false;
    a.prev_p = D::get(dl_.hit.p, i);
    a.prev_n = D::get(dl_.receiver_n, i);
  }
  any_shadow_ |= shadows > 0;
  counters_.rays += uint64_t(shadows);
  live_ -= ends;
}

// The other vertices, one by one, as trace_alone shades them (their numbers from the lockstep
// draws where there are some).
RF_PHASE void PacketPaths::shade_rest(int depth) {
  const Accel::PacketHits& hits = dl_.hit;
  Sampler::LaneDraws* u = dl_.u;
  for (int g = 0; g < generics_; ++g) {
    const int i = generic_[g];
    CameraPath& a = lanes_[i];
    Sampler& sampler = samplers_[i];
    const SurfaceHit hit = hits.hit(i);
    const Vec3 wo = D::get(dl_.wo, i);
    const Bsdf bsdf = bsdf_at(ctx_, hit, a.cone_width);
    const bool nee = !bsdf.is_delta();
    const bool ends = last_ && bsdf.is_diffuse();  // see `last_`
    const float u_light = lockstep_draws_ ? u[kULight][0][i] : sampler.get_1d_if(nee);
    const Vec2 u_point = lockstep_draws_ ? Vec2{u[kUPoint][0][i], u[kUPoint][1][i]}
                                         : vertex_2d(sampler, nee, depth, kPointPair);
    if (nee) {
      Ray r;
      RGB l;
      if (light_sample_mis_unshadowed(ctx_, hit, bsdf, wo, u_light, u_point, l, r, !ends)) {
        S::put(nee_term_, i, a.beta * l);
        shadow_.set(i, r);
        any_shadow_ = true;
        ++counters_.rays;
      }
    }
    if (ends) {
      rays_.clear(i), --live_;
      continue;
    }
    BsdfSample bs;
    const float uc =
        lockstep_draws_ ? u[kUChoice][0][i] : sampler.get_1d_if(bsdf.sample_uses_choice());
    const Vec2 u_dir = lockstep_draws_
                           ? Vec2{u[kUDir][0][i], u[kUDir][1][i]}
                           : vertex_2d(sampler, bsdf.sample_uses_direction(), depth, kDirPair);
    if (!bsdf.sample(wo, uc, u_dir, TransportMode::Radiance, bs)) {
      rays_.clear(i), --live_;
      continue;
    }
    rays_.set(i, a.scatter(ctx_, hit, bsdf, wo, bs));
    const float u_rr = lockstep_draws_ ? u[kURoulette][0][i] : sampler.get_1d_if(roulette_);
    if (roulette_ && !a.survives_roulette(u_rr)) rays_.clear(i), --live_;
  }
}

RF_PHASE void PacketPaths::cast_shadows() {
  if (any_shadow_) ctx_.accel.occluded_packet(shadow_, n_, blocked_);
}

// The NEE terms whose shadow rays got through, as selects in lane space (a lane's shadow ray is
// active only after its term is written; branches on the lanes' patterns mispredict).
RF_PHASE void PacketPaths::add() {
  for (int i = 0; i < K; ++i) {
    const bool add = shadow_.active(i) & (blocked_[i] == 0);
    sum_[0][i] = add ? sum_[0][i] + nee_term_[0][i] : sum_[0][i];
    sum_[1][i] = add ? sum_[1][i] + nee_term_[1][i] : sum_[1][i];
    sum_[2][i] = add ? sum_[2][i] + nee_term_[2][i] : sum_[2][i];
  }
}

void PacketPaths::trace(const Ray* camera_rays, RGB* radiance) {
  for (int i = 0; i < K; ++i) S::put(sum_, i, RGB(0.0f));
  for (int i = 0; i < n_; ++i) {
    rays_.set(i, camera_rays[i]);
    // The lane's time for all its rays: lanes_to_packets writes the rest of the rays in place.
    shadow_.rh.ray.time[i] = camera_rays[i].time;
    lanes_[i].prev_p = camera_rays[i].o;
  }
  for (int depth = 0; live_ > 0; ++depth) {
    if (hand_off(depth)) break;
    intersect(depth);
    draw(depth);
    arrive(depth);
    shade_lanes();
    shade_rest(depth);
    cast_shadows();
    add();
  }
  for (int i = 0; i < n_; ++i) radiance[i] = S::get(sum_, i);
}

}  // namespace rf
