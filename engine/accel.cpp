#include "engine/accel.h"

#include "engine/animated_transform.h"
#include "engine/shapes.h"
#include "engine/simd.h"

#include <spdlog/spdlog.h>

#include <cmath>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <string>

namespace rf {

namespace {

void embree_error(void*, RTCError code, const char* str) {
  spdlog::error("embree error {}: {}", int(code), str ? str : "");
}

// gamma(n) of pbrt: bound on the relative error of n floating-point operations.
constexpr float gamma_n(int n) {
  constexpr float eps = std::numeric_limits<float>::epsilon() * 0.5f;
  return (n * eps) / (1 - n * eps);
}

// The point, its error bound and the normals of a hit at barycentrics (b1, b2) of the triangle
// (p0, p1, p2) with vertex normals n0, n1, n2, all zero for a mesh without normals (pbrt-v4
// Triangle::InteractionFromIntersection). Written without branches: hit_from_embree calls it for
// one hit and triangle_hits for a packet's lanes in a loop that vectorises, so both give the same
// bits (exact IEEE operations, no contraction).
inline void triangle_hit(Vec3 p0, Vec3 p1, Vec3 p2, Vec3 n0, Vec3 n1, Vec3 n2, float b1, float b2,
                         Vec3& p, Vec3& p_error, Vec3& ng, Vec3& ns) {
  float b0 = 1.0f - b1 - b2;
  p = b0 * p0 + b1 * p1 + b2 * p2;
  p_error = gamma_n(7) * (abs(b0 * p0) + abs(b1 * p1) + abs(b2 * p2));
  ng = normalize(cross(p1 - p0, p2 - p0));
  // Interpolated normals, else (none, or they cancel) ng; on ng's side.
  Vec3 s = b0 * n0 + b1 * n1 + b2 * n2;
  float len = length(s);
  s = s * (1.0f / len);
  const bool keep = len > 0;  // component selects: GCC 12 vectorises no select of a struct
  s = {keep ? s.x : ng.x, keep ? s.y : ng.y, keep ? s.z : ng.z};
  const bool flip = dot(s, ng) < 0;
  ns = {flip ? -s.x : s.x, flip ? -s.y : s.y, flip ? -s.z : s.z};
}

// The triangle lanes of a packet (Accel::intersect_packet), in lane space: each lane's triangle
// and barycentrics gathered into its slot, then the hits computed by one loop over all N slots
// into the packet's hits (the slots of lanes that are not plain triangle hits hold zeros or
// earlier lanes' data: their results are overwritten or never read), so that the loop has no
// scalar remainder at any vector width.
struct TriangleLanes : LaneSlots<Accel::kPacket> {
  float b1[N], b2[N];
  V3 p0, p1, p2, n0, n1, n2;  // the normals zero for a mesh without them
};

RF_SIMD_CLONES void triangle_hits(const TriangleLanes& T, Accel::PacketHits& out) {
  using T3 = TriangleLanes;
  RF_IVDEP
  for (int j = 0; j < TriangleLanes::N; ++j) {  // all N: see TriangleLanes
    Vec3 p, p_error, ng, ns;
    triangle_hit(T3::get(T.p0, j), T3::get(T.p1, j), T3::get(T.p2, j), T3::get(T.n0, j),
                 T3::get(T.n1, j), T3::get(T.n2, j), T.b1[j], T.b2[j], p, p_error, ng, ns);
    T3::put(out.p, j, p), T3::put(out.p_error, j, p_error);
    T3::put(out.ng, j, ng), T3::put(out.ns, j, ns);
  }
}

// The uv of a triangle hit: the mesh's, interpolated, else the barycentrics.
inline Vec2 triangle_uv(const Mesh& m, uint32_t i0, uint32_t i1, uint32_t i2, float b1, float b2) {
  if (m.uvs.empty()) return {b1, b2};
  float b0 = 1.0f - b1 - b2;
  Vec2 a = m.uvs[i0], b = m.uvs[i1], c = m.uvs[i2];
  return {b0 * a.x + b1 * b.x + b2 * c.x, b0 * a.y + b1 * b.y + b2 * c.y};
}

void init_ray(RTCRay& r, Vec3 o, Vec3 d, float tmax, float time) {
  r.org_x = o.x, r.org_y = o.y, r.org_z = o.z;
  r.dir_x = d.x, r.dir_y = d.y, r.dir_z = d.z;
  r.tnear = 0.0f;
  r.tfar = tmax;
  r.time = time;
  r.mask = 0xFFFFFFFFu;  // Debian builds Embree with ray masks on: all ones hits everything
  r.id = 0;
  r.flags = 0;
}

// One Embree geometry of a mesh (triangles, or Embree's sphere primitive for an exact sphere),
// attached to `scene` under `id`.
void attach_mesh(RTCDevice device, RTCScene scene, const Mesh& m, unsigned id) {
  if (m.sphere) {
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_SPHERE_POINT);
    auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0,
                                                          RTC_FORMAT_FLOAT4, 4 * sizeof(float), 1));
    v[0] = m.sphere->center.x, v[1] = m.sphere->center.y, v[2] = m.sphere->center.z;
    v[3] = m.sphere->radius;
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(scene, g, id);
    rtcReleaseGeometry(g);
    return;
  }
  RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  // Copied into Embree-owned buffers: Embree may read 16 bytes at the last vertex, which a
  // tightly packed std::vector<Vec3> does not guarantee.
  auto* v = static_cast<float*>(rtcSetNewGeometryBuffer(
      g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, sizeof(Vec3), m.positions.size()));
  std::memcpy(v, m.positions.data(), m.positions.size() * sizeof(Vec3));
  auto* idx = static_cast<uint32_t*>(rtcSetNewGeometryBuffer(
      g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), m.triangle_count()));
  std::memcpy(idx, m.indices.data(), m.indices.size() * sizeof(uint32_t));
  rtcCommitGeometry(g);
  rtcAttachGeometryByID(scene, g, id);
  rtcReleaseGeometry(g);
}

// Embree's quaternion decomposition of an affine matrix, M = T R S with S upper triangular (its
// RTCQuaternionDecomposition): the QR decomposition of M's linear part by Gram-Schmidt on its
// columns, in double, R made a rotation (determinant +1) by moving a mirror into S's last scale.
RTCQuaternionDecomposition quaternion_decomposition(const Mat4& m) {
  double c[3][3];  // c[j]: column j of the linear part
  for (int j = 0; j < 3; ++j)
    for (int i = 0; i < 3; ++i) c[j][i] = m.m[i][j];
  auto dot3 = [](const double* a, const double* b) {
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  };
  double q[3][3], u[3][3] = {};
  for (int j = 0; j < 3; ++j) {
    double v[3] = {c[j][0], c[j][1], c[j][2]};
    for (int k = 0; k < j; ++k) {
      u[k][j] = dot3(q[k], c[j]);
      for (int i = 0; i < 3; ++i) v[i] -= u[k][j] * q[k][i];
    }
    u[j][j] = std::sqrt(dot3(v, v));
    for (int i = 0; i < 3; ++i) q[j][i] = v[i] / u[j][j];
  }
  const double det = q[0][0] * (q[1][1] * q[2][2] - q[1][2] * q[2][1]) -
                     q[1][0] * (q[0][1] * q[2][2] - q[0][2] * q[2][1]) +
                     q[2][0] * (q[0][1] * q[1][2] - q[0][2] * q[1][1]);
  if (det < 0) {
    for (int i = 0; i < 3; ++i) q[2][i] = -q[2][i];
    u[2][2] = -u[2][2];
  }
  double r[3][3];  // row-major rotation: its columns are q[0], q[1], q[2]
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r[i][j] = q[j][i];
  const Quaternion quat = matrix_to_quaternion(r);
  RTCQuaternionDecomposition d;
  rtcInitQuaternionDecomposition(&d);
  d.scale_x = float(u[0][0]), d.scale_y = float(u[1][1]), d.scale_z = float(u[2][2]);
  d.skew_xy = float(u[0][1]), d.skew_xz = float(u[0][2]), d.skew_yz = float(u[1][2]);
  d.quaternion_r = float(quat.w), d.quaternion_i = float(quat.x);
  d.quaternion_j = float(quat.y), d.quaternion_k = float(quat.z);
  d.translation_x = m.m[0][3], d.translation_y = m.m[1][3], d.translation_z = m.m[2][3];
  return d;
}

// Moves an object-space hit point to world space with pbrt-v4's error bound of a transformed
// point: |M| e (1 + gamma3) + gamma3 (|M_linear p| + |t|), per axis.
void transform_hit_point(const Mat4& m, Vec3& p, Vec3& p_error) {
  Vec3 w = m.point(p), e;
  for (int i = 0; i < 3; ++i) {
    float lin =
        std::fabs(m.m[i][0] * p.x) + std::fabs(m.m[i][1] * p.y) + std::fabs(m.m[i][2] * p.z);
    float err = std::fabs(m.m[i][0]) * p_error.x + std::fabs(m.m[i][1]) * p_error.y +
                std::fabs(m.m[i][2]) * p_error.z;
    e[i] = (1 + gamma_n(3)) * err + gamma_n(3) * (lin + std::fabs(m.m[i][3]));
  }
  p = w, p_error = e;
}

// The distance along o + t d to the sphere, computed in double from the ray and the sphere alone:
// the root of |o + t d - c|^2 = r^2 nearest Embree's t_embree (which picks the near or far one).
// Embree's single-ray and packet kernels round t differently in the last bits; this way a hit
// does not depend on which of them found it. Embree's t where the ray only grazes.
float sphere_distance(const SphereShape& s, Vec3 o, Vec3 d, float t_embree) {
  const double ox = double(o.x) - s.center.x, oy = double(o.y) - s.center.y,
               oz = double(o.z) - s.center.z;
  const double a = double(d.x) * d.x + double(d.y) * d.y + double(d.z) * d.z;
  const double b = ox * d.x + oy * d.y + oz * d.z;  // half the linear coefficient
  const double c = ox * ox + oy * oy + oz * oz - double(s.radius) * s.radius;
  const double disc = b * b - a * c;
  if (!(disc >= 0) || !(a > 0)) return t_embree;
  // The two roots without cancellation: q / a and c / q.
  const double q = b >= 0 ? -(b + std::sqrt(disc)) : -(b - std::sqrt(disc));
  const double t0 = q / a, t1 = q != 0 ? c / q : t0;
  const double t = std::fabs(t0 - t_embree) <= std::fabs(t1 - t_embree) ? t0 : t1;
  return std::isfinite(t) ? float(t) : t_embree;
}

}  // namespace

namespace {

// The key segments that the shutter [open, close] overlaps, for n keys at times(k) (increasing);
// 0 when the track holds still during it (no key segment overlapped, or an instant).
template <class Times>
uint32_t overlapped_segments(const Times& times, size_t n, double open, double close) {
  if (n < 2 || !(close > open)) return 0;
  if (close <= times(0) || open >= times(n - 1)) return 0;  // held still
  uint32_t segments = 1;
  for (size_t k = 0; k < n; ++k) segments += times(k) > open && times(k) < close;
  return segments;
}

}  // namespace

uint32_t motion_time_steps(const AnimatedTransform& motion, double open, double close) {
  const std::vector<Keyframe>& keys = motion.keys();
  const uint32_t segments = overlapped_segments([&](size_t k) { return keys[k].time; },
                                                motion.animated() ? keys.size() : 0, open, close);
  if (segments == 0) return 1;
  if (segments == 1 && motion.rigid_at((open + close) / 2)) return 2;
  return std::min<uint32_t>(kMaxTimeSteps, 1 + kStepsPerSegment * segments);
}

uint32_t deform_time_steps(const Mesh& mesh, double open, double close) {
  const std::vector<VertexKey>& keys = mesh.deform;
  const uint32_t segments = overlapped_segments([&](size_t k) { return keys[k].time; },
                                                mesh.deforms() ? keys.size() : 0, open, close);
  if (segments == 0) return 1;
  if (segments == 1) return 2;  // linear within a segment, as Embree interpolates: exact
  return std::min<uint32_t>(kMaxTimeSteps, 1 + kStepsPerSegment * segments);
}

AccelGeometry::AccelGeometry(const Scene& scene_) : scene(scene_) {
  // RAYFARM_EMBREE_CONFIG=isa=NAME: Embree's kernels for another CPU kind (e.g. isa=avx2 on an
  // AVX-512 machine, as Accel.PacketQueriesOnEmbreesAvx2Kernels does; docs/design.md). Only that
  // key: Embree's other settings (its thread count among them) are not ours to hand out.
  const char* config = std::getenv("RAYFARM_EMBREE_CONFIG");
  if (config && *config) {
    const std::string c = config;
    const bool isa =
        c.size() > 4 && c.compare(0, 4, "isa=") == 0 &&
        c.find_first_not_of("abcdefghijklmnopqrstuvwxyz0123456789.", 4) == std::string::npos;
    if (!isa)
      throw std::runtime_error("RAYFARM_EMBREE_CONFIG=\"" + c +
                               "\": only isa=NAME is accepted (e.g. isa=avx2)");
  }
  device = rtcNewDevice(config && *config ? config : nullptr);
  if (!device)
    throw std::runtime_error(
        std::string("embree: cannot create device") +
        (config ? " with RAYFARM_EMBREE_CONFIG=\"" + std::string(config) + "\"" : std::string()));
  rtcSetDeviceErrorFunction(device, embree_error, nullptr);
  quiet_packets = !rtcGetDeviceProperty(device, RTC_DEVICE_PROPERTY_NATIVE_RAY16_SUPPORTED);
  for (const Mesh& m : scene.meshes) surfaces.push_back(&m);  // surface id == mesh index
  // Medium (Embree's default, binned SAH without spatial splits): on the million-triangle benchmark
  // scene it builds faster than high quality, and it traces as fast within the noise there and on
  // the Cornell box and veach-mis (docs/performance.md, "Fixed costs of a render: start-up,
  // import, BVH build, output"). Which triangle of a shared edge a ray hits can depend on the
  // tree, so the choice is part of the estimator version (registry.cpp).
  world = rtcNewScene(device);
  rtcSetSceneBuildQuality(world, RTC_BUILD_QUALITY_MEDIUM);
  // Geometry id == mesh index; a deforming mesh is each frame's (Accel).
  for (size_t i = 0; i < scene.meshes.size(); ++i)
    if (!scene.meshes[i].deforms()) attach_mesh(device, world, scene.meshes[i], unsigned(i));
  // Objects: one Embree scene each, built only if some instance places it.
  std::vector<bool> placed(scene.objects.size(), false);
  for (const Instance& inst : scene.instances) placed.at(inst.object) = true;
  for (size_t o = 0; o < scene.objects.size(); ++o) {
    object_first_surface.push_back(uint32_t(surfaces.size()));
    for (const Mesh& m : scene.objects[o].meshes) surfaces.push_back(&m);
    RTCScene os = nullptr;
    if (placed[o] && !scene.objects[o].meshes.empty()) {
      os = rtcNewScene(device);
      rtcSetSceneBuildQuality(os, RTC_BUILD_QUALITY_MEDIUM);
      for (size_t k = 0; k < scene.objects[o].meshes.size(); ++k)
        attach_mesh(device, os, scene.objects[o].meshes[k], unsigned(k));
      rtcCommitScene(os);
    }
    object_scenes.push_back(os);
  }
  for (size_t i = 0; i < scene.instances.size(); ++i) {  // the instances that stand still
    const Instance& inst = scene.instances[i];
    RTCScene os = object_scenes[inst.object];
    if (!os || inst.moves()) continue;
    RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(g, os);
    rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, &inst.to_world.m[0][0]);
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(world, g, unsigned(scene.meshes.size() + i));
    rtcReleaseGeometry(g);
  }
  rtcCommitScene(world);
  size_t bytes = 0;  // the meshes' indices, vertices, normals and uvs
  for (const Mesh* m : surfaces)
    bytes += m->indices.size() * sizeof(uint32_t) + m->positions.size() * sizeof(Vec3) +
             m->normals.size() * sizeof(Vec3) + m->uvs.size() * sizeof(Vec2);
  prefetch = bytes > kPrefetchAboveBytes;
}

AccelGeometry::~AccelGeometry() {
  if (world) rtcReleaseScene(world);
  for (RTCScene os : object_scenes)
    if (os) rtcReleaseScene(os);
  if (device) rtcReleaseDevice(device);
}

Accel::Accel(const Scene& scene, FrameNumber frame)
    : Accel(std::make_shared<const AccelGeometry>(scene), frame) {}

Accel::Accel(std::shared_ptr<const AccelGeometry> geometry, FrameNumber frame)
    : geometry_(std::move(geometry)),
      scene_(geometry_->scene),
      surfaces_(geometry_->surfaces),
      object_first_surface_(geometry_->object_first_surface),
      prefetch_(geometry_->prefetch),
      world_(geometry_->world) {
  const Scene& scene = scene_;
  // The moving instances, in a scene of the frame's own: each samples its track at uniform time
  // steps over the frame's shutter (Embree's time 0 at the shutter's opening, 1 at its closing),
  // quaternion-decomposed so that Embree slerps the rotation between steps (motion_time_steps
  // says how many).
  const double open = scene.time.at(frame, 0.0f), close = scene.time.at(frame, 1.0f);
  instance_geometry_.assign(scene.instances.size(), nullptr);
  instance_to_world_.reserve(scene.instances.size());
  for (size_t i = 0; i < scene.instances.size(); ++i) {
    const Instance& inst = scene.instances[i];
    instance_to_world_.push_back(inst.moves() ? inst.motion.at(open) : inst.to_world);
    RTCScene os = geometry_->object_scenes[inst.object];
    if (!os || !inst.moves()) continue;
    if (!motion_) {
      motion_ = rtcNewScene(geometry_->device);
      rtcSetSceneBuildQuality(motion_, RTC_BUILD_QUALITY_MEDIUM);
    }
    const uint32_t steps = motion_time_steps(inst.motion, open, close);
    RTCGeometry g = rtcNewGeometry(geometry_->device, RTC_GEOMETRY_TYPE_INSTANCE);
    rtcSetGeometryInstancedScene(g, os);
    if (steps == 1) {
      rtcSetGeometryTransform(g, 0, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, &instance_to_world_[i].m[0][0]);
    } else {
      rtcSetGeometryTimeStepCount(g, steps);
      for (uint32_t k = 0; k < steps; ++k) {
        const double t = k + 1 == steps ? close : open + (close - open) * k / (steps - 1);
        const RTCQuaternionDecomposition d = quaternion_decomposition(inst.motion.at(t));
        rtcSetGeometryTransformQuaternion(g, k, &d);
      }
      rtcRetainGeometry(g);
      instance_geometry_[i] = g;
      time_steps_ = std::max(time_steps_, steps);
    }
    rtcCommitGeometry(g);
    rtcAttachGeometryByID(motion_, g, unsigned(scene.meshes.size() + i));
    rtcReleaseGeometry(g);
  }
  // The deforming meshes, in the same scene: each key-interpolated at its own uniform steps over
  // the shutter (deform_time_steps), one Embree vertex buffer per step, normals kept here.
  deform_slot_.assign(scene.meshes.size(), -1);
  for (size_t i = 0; i < scene.meshes.size(); ++i) {
    const Mesh& m = scene.meshes[i];
    if (!m.deforms()) continue;
    if (!motion_) {
      motion_ = rtcNewScene(geometry_->device);
      rtcSetSceneBuildQuality(motion_, RTC_BUILD_QUALITY_MEDIUM);
    }
    Deformed d;
    d.steps = deform_time_steps(m, open, close);
    d.geometry = rtcNewGeometry(geometry_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryTimeStepCount(d.geometry, d.steps);
    std::vector<Vec3> positions, normals;
    d.normals.reserve(size_t(d.steps) * m.normals.size());
    for (uint32_t k = 0; k < d.steps; ++k) {
      const double t =
          k + 1 == d.steps && k > 0 ? close : open + (close - open) * k / std::max(1u, d.steps - 1);
      deformed_vertices(m, t, positions, normals);
      // Embree-owned, as attach_mesh's: Embree may read 16 bytes at the last vertex.
      auto* v = static_cast<Vec3*>(rtcSetNewGeometryBuffer(d.geometry, RTC_BUFFER_TYPE_VERTEX, k,
                                                           RTC_FORMAT_FLOAT3, sizeof(Vec3),
                                                           positions.size()));
      std::memcpy(static_cast<void*>(v), positions.data(), positions.size() * sizeof(Vec3));
      d.positions.push_back(v);
      d.normals.insert(d.normals.end(), normals.begin(), normals.end());
    }
    auto* idx = static_cast<uint32_t*>(
        rtcSetNewGeometryBuffer(d.geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                3 * sizeof(uint32_t), m.triangle_count()));
    std::memcpy(idx, m.indices.data(), m.indices.size() * sizeof(uint32_t));
    rtcCommitGeometry(d.geometry);
    rtcAttachGeometryByID(motion_, d.geometry, unsigned(i));  // surface id == mesh index
    time_steps_ = std::max(time_steps_, d.steps);
    deform_slot_[i] = int32_t(deformed_.size());
    deformed_.push_back(std::move(d));
  }
  if (motion_) {
    rtcCommitScene(motion_);
    // The box the moving geometry sweeps over the shutter, grown by 1e-4 of its extent (and
    // 1e-6 of its coordinates' size) so that the rays that skip the motion query miss for sure.
    RTCLinearBounds lb;
    rtcGetSceneLinearBounds(motion_, &lb);
    const float lo[3] = {std::min(lb.bounds0.lower_x, lb.bounds1.lower_x),
                         std::min(lb.bounds0.lower_y, lb.bounds1.lower_y),
                         std::min(lb.bounds0.lower_z, lb.bounds1.lower_z)};
    const float hi[3] = {std::max(lb.bounds0.upper_x, lb.bounds1.upper_x),
                         std::max(lb.bounds0.upper_y, lb.bounds1.upper_y),
                         std::max(lb.bounds0.upper_z, lb.bounds1.upper_z)};
    for (int a = 0; a < 3; ++a) {
      const float pad =
          1e-4f * (hi[a] - lo[a]) + 1e-6f * std::max(std::fabs(lo[a]), std::fabs(hi[a]));
      motion_lo_[a] = lo[a] - pad, motion_hi_[a] = hi[a] + pad;
    }
  }
  instance_inverse_.reserve(scene.instances.size());
  for (const Mat4& m : instance_to_world_) instance_inverse_.push_back(m.inverse());
}

Accel::~Accel() {
  for (RTCGeometry g : instance_geometry_)
    if (g) rtcReleaseGeometry(g);
  for (const Deformed& d : deformed_) rtcReleaseGeometry(d.geometry);
  if (motion_) rtcReleaseScene(motion_);
}

bool Accel::intersect(const Ray& ray, SurfaceHit& hit) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  init_ray(rh.ray, ray.o, ray.d, ray.tmax, ray.time);
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(world_, &ctx, &rh);
  if (motion_ && may_hit_motion(ray.o, ray.d, rh.ray.tfar))
    rtcIntersect1(motion_, &ctx, &rh);  // only a nearer hit replaces the world's
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
  hit_from_embree(ray, rh.hit.geomID, rh.hit.primID, rh.hit.instID[0], rh.hit.u, rh.hit.v,
                  rh.ray.tfar, hit);
  return true;
}

void Accel::intersect_packet(RayPacket& packet, int n, PacketHits& out, bool coherent) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  if (coherent) ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  if (geometry_->quiet_packets) packet.quiet_inactive();
  rtcIntersect16(packet.valid, world_, &ctx, &packet.rh);
  if (motion_) motion_query16(packet, &ctx, /*occlusion=*/false);
  const RTCHit16& h = packet.rh.hit;
  // The lanes' hits are scattered over the meshes: on a scene larger than the caches, fetch every
  // lane's index triple first, then its vertices, so that the lanes' cache misses overlap instead
  // of following one another in hit_from_embree. On a scene that fits in the caches they only
  // cost, hence kPrefetchAboveBytes (docs/performance.md, "The path tracer's inner loop").
  // Triangles of meshes placed without an instance are then computed together (triangle_hits);
  // the other hits (spheres, instances) one by one.
  const Mesh* meshes[kPacket];   // the triangle hits' meshes (prefetched)
  const Mesh* batched[kPacket];  // those placed without an instance (triangle_hits)
  for (int i = 0; i < n; ++i) {
    meshes[i] = batched[i] = nullptr;
    out.found[i] = packet.active(i) && h.geomID[i] != RTC_INVALID_GEOMETRY_ID;
    if (!out.found[i]) continue;
    const Mesh& m = *surfaces_[surface_of(h.geomID[i], h.instID[0][i])];
    if (m.sphere) continue;
    meshes[i] = &m;
    // A deforming mesh's triangle is the frame's (hit_from_embree), not its first key's.
    if (h.instID[0][i] == RTC_INVALID_GEOMETRY_ID && !(motion_ && m.deforms())) batched[i] = &m;
    if (!prefetch_) continue;
    __builtin_prefetch(&m.indices[3 * size_t(h.primID[i])]);
    __builtin_prefetch(&m.indices[3 * size_t(h.primID[i]) + 2]);
  }
  for (int i = 0; i < n && prefetch_; ++i) {
    const Mesh* m = meshes[i];
    if (!m) continue;
    const uint32_t* idx = &m->indices[3 * size_t(h.primID[i])];
    for (int k = 0; k < 3; ++k) {
      __builtin_prefetch(&m->positions[idx[k]]);
      if (!m->normals.empty()) __builtin_prefetch(&m->normals[idx[k]]);
      if (!m->uvs.empty()) __builtin_prefetch(&m->uvs[idx[k]]);
    }
  }
  using T3 = TriangleLanes;
  // Per thread, zeroed once: the slots of other lanes hold zeros or earlier lanes' data.
  thread_local TriangleLanes T{};
  bool any_batched = false;
  for (int i = 0; i < n; ++i) {
    const Mesh* m = batched[i];
    if (!m) continue;
    any_batched = true;
    const uint32_t* idx = &m->indices[3 * size_t(h.primID[i])];
    T3::put(T.p0, i, m->positions[idx[0]]);
    T3::put(T.p1, i, m->positions[idx[1]]);
    T3::put(T.p2, i, m->positions[idx[2]]);
    const bool normals = !m->normals.empty();
    T3::put(T.n0, i, normals ? m->normals[idx[0]] : Vec3(0.0f));
    T3::put(T.n1, i, normals ? m->normals[idx[1]] : Vec3(0.0f));
    T3::put(T.n2, i, normals ? m->normals[idx[2]] : Vec3(0.0f));
    T.b1[i] = h.u[i], T.b2[i] = h.v[i];
  }
  if (any_batched) triangle_hits(T, out);
  for (int i = 0; i < n; ++i) {
    if (!out.found[i]) continue;
    if (const Mesh* m = batched[i]) {
      const uint32_t* idx = &m->indices[3 * size_t(h.primID[i])];
      const Vec2 uv = triangle_uv(*m, idx[0], idx[1], idx[2], h.u[i], h.v[i]);
      out.uv[0][i] = uv.x, out.uv[1][i] = uv.y;
      out.t[i] = packet.rh.ray.tfar[i];
      out.time[i] = packet.rh.ray.time[i];
      out.mesh[i] = h.geomID[i];
      out.prim[i] = h.primID[i];
    } else {
      SurfaceHit hit;
      hit_from_embree(packet.ray(i), h.geomID[i], h.primID[i], h.instID[0][i], h.u[i], h.v[i],
                      packet.rh.ray.tfar[i], hit);
      out.set(i, hit);
    }
  }
}

void Accel::motion_query16(RayPacket& packet, RTCIntersectContext* ctx, bool occlusion) const {
  // The lanes whose ray may meet the moving geometry's box before its end (a lane the world
  // blocked has tfar -inf and meets nothing).
  alignas(64) int valid[kPacket];
  int any = 0;
  const RTCRay16& r = packet.rh.ray;
  for (int i = 0; i < kPacket; ++i) {
    const bool on =
        packet.valid[i] != 0 && may_hit_motion({r.org_x[i], r.org_y[i], r.org_z[i]},
                                               {r.dir_x[i], r.dir_y[i], r.dir_z[i]}, r.tfar[i]);
    valid[i] = on ? -1 : 0;
    any |= on;
  }
  if (!any) return;
  if (occlusion)
    rtcOccluded16(valid, motion_, ctx, &packet.rh.ray);
  else
    rtcIntersect16(valid, motion_, ctx, &packet.rh);
}

void Accel::occluded_packet(RayPacket& packet, int n, int* blocked) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  if (geometry_->quiet_packets) packet.quiet_inactive();
  rtcOccluded16(packet.valid, world_, &ctx, &packet.rh.ray);
  if (motion_) motion_query16(packet, &ctx, /*occlusion=*/true);
  for (int i = 0; i < n; ++i)  // Embree: -inf on a hit; without a branch (false when inactive)
    blocked[i] = packet.active(i) & (packet.rh.ray.tfar[i] < 0);
}

Mat4 Accel::instance_transform_at(size_t i, float time) const {
  RTCGeometry g = instance_geometry_[i];
  if (!g) return instance_to_world_[i];
  // Embree's own interpolation between its time steps: the transform its traversal used.
  float xfm[12];
  rtcGetGeometryTransform(g, time, RTC_FORMAT_FLOAT3X4_ROW_MAJOR, xfm);
  Mat4 m;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) m.m[r][c] = xfm[4 * r + c];
  return m;
}

void Accel::hit_from_embree(const Ray& ray, unsigned geom, unsigned prim, unsigned inst_id, float u,
                            float v, float t, SurfaceHit& hit) const {
  const bool instanced = inst_id != RTC_INVALID_GEOMETRY_ID;
  const size_t inst = instanced ? inst_id - scene_.meshes.size() : 0;
  const bool moving = instanced && instance_geometry_[inst] != nullptr;
  Mat4 moved;  // a moving instance's transform at the ray's time
  if (moving) moved = instance_transform_at(inst, ray.time);
  const Mat4& to_world = moving || !instanced ? moved : instance_to_world_[inst];
  const uint32_t surface = surface_of(geom, inst_id);
  const Mesh& m = *surfaces_[surface];
  hit.mesh = surface;
  hit.prim = prim;
  hit.time = ray.time;
  if (m.sphere) {
    // Rebuilt from the ray (in the object's space for an instance) at our own distance and
    // projected onto the sphere.
    Vec3 o = ray.o, d = ray.d;
    if (instanced) {
      const Mat4 inv = moving ? moved.inverse() : instance_inverse_[inst];
      o = inv.point(o), d = inv.vector(d);
    }
    hit.t = sphere_distance(*m.sphere, o, d, t);
    Vec3 near = o + d * hit.t;
    sphere_surface_point(*m.sphere, near, hit.p, hit.p_error, hit.ng, &hit.uv);
    hit.ns = hit.ng;
    if (instanced) {
      transform_hit_point(to_world, hit.p, hit.p_error);
      hit.ng = hit.ns = normalize(to_world.normal(hit.ng));
    }
    return;
  }
  hit.t = t;
  uint32_t i0 = m.indices[3 * prim], i1 = m.indices[3 * prim + 1], i2 = m.indices[3 * prim + 2];
  const bool normals = !m.normals.empty();
  if (!instanced && motion_ && m.deforms()) {  // (a still scene does not read m.deform)
    // The triangle at the ray's time, between the frame's two time steps around it as Embree
    // interpolates them ((1 - f) a + f b), so that the hit is on the triangle the traversal met
    // (to the last bits of Embree's own arithmetic, which p_error's bound covers).
    const Deformed& d = deformed_[size_t(deform_slot_[surface])];
    uint32_t k, k1;
    float f;
    step_weights(d, ray.time, k, k1, f);
    const size_t n = m.positions.size();
    auto at = [f](const Vec3* a, const Vec3* b, uint32_t vtx) {
      return a[vtx] * (1 - f) + b[vtx] * f;
    };
    const Vec3 *pa = d.positions[k], *pb = d.positions[k1];
    const Vec3* na = normals ? &d.normals[k * n] : nullptr;
    const Vec3* nb = normals ? &d.normals[k1 * n] : nullptr;
    triangle_hit(at(pa, pb, i0), at(pa, pb, i1), at(pa, pb, i2),
                 normals ? at(na, nb, i0) : Vec3(0.0f), normals ? at(na, nb, i1) : Vec3(0.0f),
                 normals ? at(na, nb, i2) : Vec3(0.0f), u, v, hit.p, hit.p_error, hit.ng, hit.ns);
    hit.uv = triangle_uv(m, i0, i1, i2, u, v);
    return;
  }
  triangle_hit(m.positions[i0], m.positions[i1], m.positions[i2],
               normals ? m.normals[i0] : Vec3(0.0f), normals ? m.normals[i1] : Vec3(0.0f),
               normals ? m.normals[i2] : Vec3(0.0f), u, v, hit.p, hit.p_error, hit.ng, hit.ns);
  if (instanced) {  // object space to world space (flatten_instances' placement)
    transform_hit_point(to_world, hit.p, hit.p_error);
    hit.ng = normalize(to_world.normal(hit.ng));
    hit.ns = normalize(to_world.normal(hit.ns));
  }
  hit.uv = triangle_uv(m, i0, i1, i2, u, v);
}

void Accel::triangle_at(uint32_t mesh, uint32_t prim, float time, Vec3& p0, Vec3& p1,
                        Vec3& p2) const {
  const Mesh& m = scene_.meshes[mesh];
  const uint32_t i0 = m.indices[3 * prim], i1 = m.indices[3 * prim + 1],
                 i2 = m.indices[3 * prim + 2];
  if (!(motion_ && m.deforms())) {
    p0 = m.positions[i0], p1 = m.positions[i1], p2 = m.positions[i2];
    return;
  }
  const Deformed& d = deformed_[size_t(deform_slot_[mesh])];
  uint32_t k, k1;
  float f;
  step_weights(d, time, k, k1, f);
  const Vec3 *a = d.positions[k], *b = d.positions[k1];
  p0 = a[i0] * (1 - f) + b[i0] * f;
  p1 = a[i1] * (1 - f) + b[i1] * f;
  p2 = a[i2] * (1 - f) + b[i2] * f;
}

bool Accel::occluded(const Ray& ray) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r;
  init_ray(r, ray.o, ray.d, ray.tmax, ray.time);
  rtcOccluded1(world_, &ctx, &r);
  if (motion_ && r.tfar >= 0 && may_hit_motion(ray.o, ray.d, r.tfar))
    rtcOccluded1(motion_, &ctx, &r);
  return r.tfar < 0;  // Embree sets tfar to -inf on a hit
}

void Accel::cast8(const Ray* rays, int n, float* t) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  alignas(32) RTCRayHit8 rh;
  alignas(32) int valid[8];
  for (int i = 0; i < 8; ++i) {
    const bool on = i < n;
    valid[i] = on ? -1 : 0;
    const Ray& r = rays[on ? i : 0];
    rh.ray.org_x[i] = r.o.x, rh.ray.org_y[i] = r.o.y, rh.ray.org_z[i] = r.o.z;
    rh.ray.dir_x[i] = r.d.x, rh.ray.dir_y[i] = r.d.y, rh.ray.dir_z[i] = r.d.z;
    rh.ray.tnear[i] = 0.0f;
    rh.ray.tfar[i] = r.tmax;
    rh.ray.time[i] = 0.0f;
    rh.ray.mask[i] = 0xFFFFFFFFu;
    rh.ray.id[i] = unsigned(i);
    rh.ray.flags[i] = 0;
    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
  }
  rtcIntersect8(valid, world_, &ctx, &rh);
  if (motion_) rtcIntersect8(valid, motion_, &ctx, &rh);
  for (int i = 0; i < n; ++i)
    t[i] = rh.hit.geomID[i] == RTC_INVALID_GEOMETRY_ID ? kInf : rh.ray.tfar[i];
}

float Accel::cast(Vec3 o, Vec3 d) const {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh;
  init_ray(rh.ray, o, d, kInf, 0.0f);
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(world_, &ctx, &rh);
  if (motion_) rtcIntersect1(motion_, &ctx, &rh);
  return rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? kInf : rh.ray.tfar;
}

}  // namespace rf
