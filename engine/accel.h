// The Embree 3 scene: one triangle geometry (or one exact sphere) per world-space mesh (geometry id
// == mesh index), one Embree scene per instanced object placed by an Embree instance per
// Scene::instances entry (geometry id == meshes + instance index), closest-hit and occlusion
// queries, and the surface interaction rebuilt from a hit with a floating-point error bound for
// robust ray spawning.
//
// Surfaces: a hit names the mesh it is on by a surface id, Accel::mesh(id). Ids below
// Scene::meshes.size() are the world meshes (so a light's mesh index is its surface id); the
// meshes of objects follow, object by object. A hit on an instance is computed in object space
// and moved to world space by the instance's transform (normals by the inverse transpose).
#pragma once

#include <embree3/rtcore.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "engine/frame.h"
#include "engine/scene.h"

namespace rf {

// A ray at a time: `time` is the position in the frame's shutter, 0 at its opening and 1 at its
// closing (Embree's ray time; docs/design.md "Time"). A path keeps its camera sample's time:
// spawned and shadow rays take it from the hit they leave (SurfaceHit::time). A scene without
// moving geometry ignores it.
struct Ray {
  Vec3 o, d;
  float tmax = kInf;
  float time = 0;
};

struct SurfaceHit {
  Vec3 p;        // world position, rebuilt from barycentrics
  Vec3 p_error;  // conservative absolute error bound of p per axis
  Vec3 ng;       // unit geometric normal (right-hand winding of the triangle)
  Vec3 ns;       // unit shading normal (interpolated vertex normals, else ng), same side as ng
  Vec2 uv;
  float t = 0;
  float time = 0;               // the time of the ray that found it (Ray::time)
  uint32_t mesh = 0, prim = 0;  // mesh: surface id (Accel::mesh); prim: its triangle
};

// std::nextafter(v, +inf) and (v, -inf) for finite v by stepping the bit pattern (pbrt-v4's
// NextFloatUp/Down): the same values, without the library call's checks. Written as selects
// without branches, so that loops over lanes that offset rays vectorise (the path tracer's).
inline uint32_t float_bits(float v) {
  uint32_t b;
  std::memcpy(&b, &v, 4);
  return b;
}
inline float bits_float(uint32_t b) {
  float v;
  std::memcpy(&v, &b, 4);
  return v;
}
inline float next_float_up(float v) {
  uint32_t b = float_bits(v);
  uint32_t up = v >= 0 ? b + 1 : b - 1;
  up = b == 0x80000000u ? 1u : up;  // -0 steps as +0
  return bits_float(v == kInf ? b : up);
}
inline float next_float_down(float v) {
  uint32_t b = float_bits(v);
  uint32_t down = v > 0 ? b - 1 : b + 1;
  down = b == 0 ? 0x80000001u : down;  // +0 steps as -0
  return bits_float(v == -kInf ? b : down);
}

// Moves p off its surface along ng, towards the side w points to, by the hit's error bound
// (pbrt-v4's OffsetRayOrigin), then one ulp further away from p per axis. Inline: it runs three
// times per path vertex (the spawned ray and both ends of the shadow ray), and a call would move
// its four vectors through the stack each time (docs/performance.md, "The path tracer's inner
// loop").
inline Vec3 offset_ray_origin(Vec3 p, Vec3 p_error, Vec3 ng, Vec3 w) {
  float d = dot(abs(ng), p_error);
  Vec3 offset = ng * d;
  if (dot(w, ng) < 0) offset = -offset;
  Vec3 po = p + offset;
  auto away = [](float v, float off) {
    float r = off > 0 ? next_float_up(v) : v;
    return off < 0 ? next_float_down(v) : r;
  };
  return {away(po.x, offset.x), away(po.y, offset.y), away(po.z, offset.z)};
}

// Embree's time steps for an instance moving along `motion` during the shutter [open, close]
// (seconds): 1 when it does not move then (a static placement at `open`); 2 when the shutter lies
// within one key segment that only translates and rotates (Embree's interpolation between the two
// steps, translation linear and rotation by slerp, is then the track's own); otherwise the track
// resampled uniformly, kStepsPerSegment steps per key segment the shutter overlaps, at most
// kMaxTimeSteps (Embree's limit): Embree's time steps are uniform per geometry, so keys that fall
// between steps are approximated by their neighbours' interpolation (docs/design.md "Time").
inline constexpr uint32_t kMaxTimeSteps = RTC_MAX_TIME_STEP_COUNT, kStepsPerSegment = 8;
uint32_t motion_time_steps(const AnimatedTransform& motion, double open, double close);
// The same for a deforming mesh's vertex keys (Mesh::deform): 1 when it holds its shape during
// the shutter, 2 within one key segment (vertices linear between keys, as Embree interpolates
// steps: exact), else kStepsPerSegment per key segment overlapped, at most kMaxTimeSteps.
uint32_t deform_time_steps(const Mesh& mesh, double open, double close);

// The part of a scene's BVH that no frame changes: the Embree device, one Embree scene per placed
// object, the surfaces by id, and the world: the world meshes that keep their shape and the
// instances that do not move. Built once per scene and shared by the frames' Accels (Renderer),
// so that a frame of a shot builds only a scene over its moving instances and deforming meshes.
// Which part is which is a function of the scene alone: a frame's BVH is the same whichever frames
// were built before it.
struct AccelGeometry {
  explicit AccelGeometry(const Scene& scene);
  ~AccelGeometry();
  AccelGeometry(const AccelGeometry&) = delete;
  AccelGeometry& operator=(const AccelGeometry&) = delete;

  const Scene& scene;
  RTCDevice device = nullptr;
  // Whether the device lacks 16-wide kernels, so that a 16-wide query takes Embree's ray-stream
  // path, which ignores the valid mask (RayPacket::quiet_inactive).
  bool quiet_packets = false;
  // Whether intersect_packet prefetches the hits' triangles: when the meshes' data is larger than
  // a core's L2 cache (about 1 MiB on the machines measured), not on scenes that fit.
  static constexpr size_t kPrefetchAboveBytes = size_t(1) << 20;
  bool prefetch = false;
  std::vector<const Mesh*> surfaces;           // by surface id
  std::vector<uint32_t> object_first_surface;  // surface id of each object's first mesh
  std::vector<RTCScene> object_scenes;         // one per object (nullptr: placed by no instance)
  RTCScene world = nullptr;  // the world meshes that keep their shape and the still instances
};

class Accel {
 public:
  // The scene's BVH for frame `frame`: the placements of moving instances and the vertices of
  // deforming meshes over that frame's shutter (a scene without moving geometry builds the same
  // BVH for every frame).
  explicit Accel(const Scene& scene, FrameNumber frame = 0);
  // The same on geometry built before (its scene's), building only the frame's top level.
  Accel(std::shared_ptr<const AccelGeometry> geometry, FrameNumber frame);
  ~Accel();
  Accel(const Accel&) = delete;
  Accel& operator=(const Accel&) = delete;

  // Closest hit along ray within (0, tmax). Returns false on a miss.
  bool intersect(const Ray& ray, SurfaceHit& hit) const;
  // True when anything blocks the segment o + t d, t in (0, tmax), at the ray's time.
  bool occluded(const Ray& ray) const;

  // The same queries for up to kPacket rays at once, through Embree's 16-wide packet queries.
  // A RayPacket holds the rays in Embree's layout between queries: set(i, ray) makes lane i
  // active with that ray, clear(i) inactive; the queries trace the active lanes only (on a device
  // without 16-wide kernels after quieting the others, RayPacket::quiet_inactive) and give,
  // lane by lane, what intersect / occluded give for the same ray: Embree's triangle kernels agree
  // bit for bit, and a sphere hit takes rayfarm's own distance (hit_from_embree), since Embree's
  // packet and single-ray sphere kernels round t differently. A grazing occlusion test could
  // still differ between kernels, so a caller that must be bit-identical across tiles forms its
  // packets from a fixed set of samples (one pixel's, see the path integrator). Coherent rays
  // (the samples of one pixel, shadow rays towards one light) traverse the BVH together, faster
  // than one by one (docs/performance.md, "The path tracer's inner loop").
  static constexpr int kPacket = 16;
  struct RayPacket {
    RayPacket() { std::memset(static_cast<void*>(this), 0, sizeof(*this)); }
    void set(int i, const Ray& r) {
      rh.ray.org_x[i] = r.o.x, rh.ray.org_y[i] = r.o.y, rh.ray.org_z[i] = r.o.z;
      rh.ray.dir_x[i] = r.d.x, rh.ray.dir_y[i] = r.d.y, rh.ray.dir_z[i] = r.d.z;
      rh.ray.tfar[i] = r.tmax;
      rh.ray.time[i] = r.time;
      rh.ray.mask[i] = 0xFFFFFFFFu;  // tnear, id and flags stay 0
      rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
      valid[i] = -1;
    }
    void clear(int i) { valid[i] = 0; }
    // Lane i active with the ray its arrays already hold (written in place: the path tracer's
    // lanes_to_packets).
    void activate(int i) { valid[i] = -1; }
    void activate_if(int i, bool on) { valid[i] = on ? -1 : 0; }  // activate or clear
    bool active(int i) const { return valid[i] != 0; }
    // Every inactive lane's ray made an empty segment of finite numbers (origin and direction 0,
    // tnear 0, tfar -inf). A 16-wide query on a device without 16-wide kernels (an AVX2 CPU) goes
    // through Embree's ray-stream path, which ignores the valid mask: it traces every lane with
    // tnear <= tfar and asserts every traced ray finite, so the NaNs a lane loop leaves in unused
    // slots aborted the process there (tests/accel_test.cpp,
    // Accel.PacketQueriesOnEmbreesAvx2Kernels). The queries call it on such a device only: its
    // scalar stores right before Embree's vector loads slow a render down (docs/performance.md,
    // "What was tried and not taken").
    void quiet_inactive() {
      for (int i = 0; i < kPacket; ++i) {
        const bool on = valid[i] != 0;
        rh.ray.org_x[i] = on ? rh.ray.org_x[i] : 0.0f;
        rh.ray.org_y[i] = on ? rh.ray.org_y[i] : 0.0f;
        rh.ray.org_z[i] = on ? rh.ray.org_z[i] : 0.0f;
        rh.ray.dir_x[i] = on ? rh.ray.dir_x[i] : 0.0f;
        rh.ray.dir_y[i] = on ? rh.ray.dir_y[i] : 0.0f;
        rh.ray.dir_z[i] = on ? rh.ray.dir_z[i] : 0.0f;
        rh.ray.tnear[i] = on ? rh.ray.tnear[i] : 0.0f;
        rh.ray.tfar[i] = on ? rh.ray.tfar[i] : -kInf;
      }
    }
    Ray ray(int i) const {
      return {{rh.ray.org_x[i], rh.ray.org_y[i], rh.ray.org_z[i]},
              {rh.ray.dir_x[i], rh.ray.dir_y[i], rh.ray.dir_z[i]},
              kInf,
              rh.ray.time[i]};
    }
    alignas(64) RTCRayHit16 rh;
    alignas(64) int valid[kPacket];
  };
  // A packet's closest hits in lane space: lane i's SurfaceHit in slot i of the arrays, so that
  // loops over lanes read them where the queries wrote them. found[i]: whether lane i hit
  // anything; a slot whose lane found nothing (or was not traced) holds values nobody reads.
  struct PacketHits {
    static constexpr int N = kPacket;
    using V3 = float[3][N];
    V3 p, p_error, ng, ns;
    float uv[2][N], t[N], time[N];
    uint32_t mesh[N], prim[N];
    int found[N];
    static Vec3 get(const V3& a, int i) { return {a[0][i], a[1][i], a[2][i]}; }
    SurfaceHit hit(int i) const {
      SurfaceHit h;
      h.p = get(p, i), h.p_error = get(p_error, i), h.ng = get(ng, i), h.ns = get(ns, i);
      h.uv = {uv[0][i], uv[1][i]}, h.t = t[i], h.time = time[i], h.mesh = mesh[i], h.prim = prim[i];
      return h;
    }
    void set(int i, const SurfaceHit& h) {
      for (int a = 0; a < 3; ++a)
        p[a][i] = h.p[a], p_error[a][i] = h.p_error[a], ng[a][i] = h.ng[a], ns[a][i] = h.ns[a];
      uv[0][i] = h.uv.x, uv[1][i] = h.uv.y, t[i] = h.t, time[i] = h.time, mesh[i] = h.mesh;
      prim[i] = h.prim;
    }
  };
  // Closest hits of the active lanes i < n: hits.found[i], and lane i's hit in slot i when found.
  // coherent: the rays are near one another (a pixel's camera rays), so Embree traverses the
  // whole packet together (RTC_INTERSECT_CONTEXT_FLAG_COHERENT: its frustum traversal on a
  // triangle BVH) where an incoherent packet goes ray by ray at a node with 14 or fewer active
  // (docs/performance.md).
  void intersect_packet(RayPacket& packet, int n, PacketHits& hits, bool coherent = false) const;
  // Whether something blocks each active lane's segment (t in (0, tmax)): blocked[i] 1 or 0, i < n.
  void occluded_packet(RayPacket& packet, int n, int* blocked) const;
  // Whether the packet queries quiet the inactive lanes (RayPacket::quiet_inactive): the device
  // has no 16-wide kernels.
  bool quiets_inactive_lanes() const { return geometry_->quiet_packets; }

  // Spawns a ray from a hit towards w.
  Ray spawn(const SurfaceHit& from, Vec3 w) const {
    return {offset_ray_origin(from.p, from.p_error, from.ng, w), w, kInf, from.time};
  }
  // The shadow ray between surface point `from` and point `to` (itself on a surface with normal
  // to_ng and error to_error): both ends offset off their surfaces, the direction unnormalised
  // so that t in (0, 1) spans the segment, tmax just short of the target.
  Ray shadow_ray(const SurfaceHit& from, Vec3 to, Vec3 to_error, Vec3 to_ng) const {
    return shadow_segment(from.p, from.p_error, from.ng, to, to_error, to_ng, from.time);
  }
  // The same from a point p with error p_error on a surface with geometric normal ng, at `time`.
  static Ray shadow_segment(Vec3 p, Vec3 p_error, Vec3 ng, Vec3 to, Vec3 to_error, Vec3 to_ng,
                            float time) {
    Vec3 o = offset_ray_origin(p, p_error, ng, to - p);
    Vec3 target = offset_ray_origin(to, to_error, to_ng, o - to);
    return {o, target - o, 1.0f - 1e-4f, time};
  }
  // Shadow test along shadow_ray(from, to, to_error, to_ng); true when unoccluded.
  bool visible(const SurfaceHit& from, Vec3 to, Vec3 to_error, Vec3 to_ng) const {
    return !occluded(shadow_ray(from, to, to_error, to_ng));
  }

  // Embree's bare cast for the baseline benchmark: hit distance or infinity, no shading.
  float cast(Vec3 o, Vec3 d) const;
  // The same for up to 8 rays at once with Embree's 8-wide packet query (rtcIntersect8), for the
  // benchmark that asks whether packets pay (bench/bench.cpp); t[i] for i < n.
  void cast8(const Ray* rays, int n, float* t) const;

  const Scene& scene() const { return scene_; }
  // The most time steps of any instance (1 when nothing moves during the frame).
  uint32_t time_steps() const { return time_steps_; }
  // Instance i's object-to-world transform at shutter position `time` (Ray::time): Embree's
  // interpolation for a moving instance, the placement otherwise.
  Mat4 instance_transform_at(size_t i, float time) const;
  // The vertices of triangle `prim` of world mesh `mesh` at shutter position `time` (Ray::time):
  // a deforming mesh's as a hit rebuilds them from the frame's time steps, so that a light
  // sample on a moving emitter lies on the triangle rays meet at that time; any other mesh's own.
  void triangle_at(uint32_t mesh, uint32_t prim, float time, Vec3& p0, Vec3& p1, Vec3& p2) const;
  // The mesh of a surface id (see above): its material, emission and object-space geometry.
  const Mesh& mesh(uint32_t surface) const { return *surfaces_[surface]; }

 private:
  // The surface id of Embree's (geometry, instance) pair.
  uint32_t surface_of(unsigned geom, unsigned inst_id) const {
    if (inst_id == RTC_INVALID_GEOMETRY_ID) return geom;
    return object_first_surface_[scene_.instances[inst_id - scene_.meshes.size()].object] + geom;
  }
  // Whether the segment o + t d, t in [0, tfar], may meet the box of the moving geometry (a
  // slab test; a NaN leaves the interval as it was, so it never skips a ray it should not).
  bool may_hit_motion(Vec3 o, Vec3 d, float tfar) const {
    float t0 = 0, t1 = tfar;
    for (int a = 0; a < 3; ++a) {
      const float inv = 1.0f / d[a];
      const float ta = (motion_lo_[a] - o[a]) * inv, tb = (motion_hi_[a] - o[a]) * inv;
      const float near = ta < tb ? ta : tb, far = ta < tb ? tb : ta;
      t0 = near > t0 ? near : t0;
      t1 = far < t1 ? far : t1;
    }
    return !(t0 > t1 * (1 + 1e-6f) + 1e-30f);
  }
  // The moving geometry's query of a packet after the world's, for the lanes that may meet it.
  void motion_query16(RayPacket& packet, RTCIntersectContext* ctx, bool occlusion) const;
  // The surface interaction of an Embree hit of `ray` (geometry, primitive, instance ids,
  // barycentrics u, v and distance t as Embree reports them).
  void hit_from_embree(const Ray& ray, unsigned geom, unsigned prim, unsigned inst_id, float u,
                       float v, float t, SurfaceHit& hit) const;

  std::shared_ptr<const AccelGeometry> geometry_;
  const Scene& scene_;
  const std::vector<const Mesh*>& surfaces_;           // geometry_'s
  const std::vector<uint32_t>& object_first_surface_;  // geometry_'s
  bool prefetch_ = false;                              // geometry_'s
  // The queries ask the world, then, when geometry moves, the frame's moving geometry with the
  // world's hit as the ray's end (two queries where one over both would put every world ray
  // through a motion-blur top level: 30% slower on the million scene, docs/performance.md).
  RTCScene world_ = nullptr;   // geometry_'s
  RTCScene motion_ = nullptr;  // the moving instances and deforming meshes over the frame's
                               // shutter, if any
  float motion_lo_[3] = {0, 0, 0}, motion_hi_[3] = {0, 0, 0};  // their box over the shutter
  std::vector<Mat4> instance_to_world_;         // per instance: its placement (a moving one's at
                                                // the shutter's opening)
  std::vector<Mat4> instance_inverse_;          // world to object space, per instance
  std::vector<RTCGeometry> instance_geometry_;  // a moving instance's Embree geometry, else null
  // A deforming mesh over the frame's shutter: its Embree geometry, whose vertex buffer k holds
  // the positions at time step k, and the normals at each step (steps x vertices, or empty).
  struct Deformed {
    RTCGeometry geometry = nullptr;
    uint32_t steps = 1;
    std::vector<const Vec3*> positions;  // per step, Embree's buffer
    std::vector<Vec3> normals;
  };
  std::vector<Deformed> deformed_;
  // The two time steps around shutter position `time` and the weight of the second, as Embree
  // interpolates a deforming mesh's steps.
  static void step_weights(const Deformed& d, float time, uint32_t& k, uint32_t& k1, float& f) {
    const uint32_t segments = d.steps - 1;
    const float ft = time * float(segments);
    k = segments == 0 ? 0 : std::min(segments - 1, uint32_t(std::max(0.0f, std::floor(ft))));
    k1 = segments == 0 ? 0 : k + 1;
    f = segments == 0 ? 0.0f : ft - float(k);
  }
  std::vector<int32_t> deform_slot_;  // per world mesh: its index in deformed_, or -1
  uint32_t time_steps_ = 1;
};

}  // namespace rf
