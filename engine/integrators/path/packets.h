// The path estimator for up to Accel::kPacket camera samples of one pixel, traced in lockstep:
// at every depth the live lanes' rays are cast together (one packet query), each lane is shaded,
// then the lanes' shadow rays are cast together. A lane's numbers are drawn in the same order
// whatever the other lanes do (light sample, BSDF sample, roulette; its shadow test is known only
// after all three), and its NEE term is added after the test and before its next vertex, so each
// lane's radiance is the one it would get traced alone (trace_alone): bit-identical
// (tests/integrators_test.cpp), given the same hits. A ray that meets two triangles at one
// distance (e.g. exactly on a shared edge) is the exception: Embree's packet and single-ray
// kernels may report different ones (docs/performance.md, "Open observations"); packets depend
// on the pixel and pass alone, so a tile and the frame still trace the same packets.
//
// A depth runs its phases in order, one function each: intersect (the packet query), draw (the
// lanes' numbers in lockstep), arrive (escapes, emission, and the lanes sorted into plain
// vertices for the kernels and the others), shade_lanes (the plain vertices in the vectorised
// kernels, surface_lanes.h), shade_rest (the others one by one), cast_shadows, and add (the NEE
// terms whose shadow rays got through). When one lane is left after the camera rays, hand_off
// gives it to the one-lane loop.
#pragma once

#include "engine/accel.h"
#include "engine/integrators/camera_path.h"
#include "engine/integrators/common.h"
#include "engine/integrators/path/lane_lights.h"
#include "engine/integrators/path/surface_lanes.h"
#include "engine/sampler.h"

namespace rf {

class PacketPaths {
 public:
  static constexpr int K = Accel::kPacket;
  // n in [2, K] camera samples, sample i with samplers[i] (started, camera numbers drawn).
  PacketPaths(const RenderContext& ctx, const LaneLights& lights, Sampler* samplers, int n,
              TraceCounters& counters);
  // Traces the camera rays to the ends of their paths; radiance[i] is sample i's.
  void trace(const Ray* camera_rays, RGB* radiance);

 private:
  using S = LaneSlots<K>;
  using D = SurfaceLanes;

  bool hand_off(int depth);
  void intersect(int depth);
  void draw(int depth);
  void arrive(int depth);
  void shade_lanes();
  void sample_lights_one_by_one();
  void sample_spheres_inside(const uint32_t* entry);
  void give_light_sample(int i, bool ok, const LightSample& ls);
  void lane_results();
  void shade_rest(int depth);
  void cast_shadows();
  void add();

  const RenderContext& ctx_;
  const LaneLights& lane_lights_;
  const IntegratorSettings& settings_;
  Sampler* samplers_;
  const int n_;
  TraceCounters& counters_;
  // With a Sobol sampler the lanes that shade a vertex draw its numbers together, in the order
  // one lane draws them (Sampler::get_lanes): all that some vertex of the scene may read, where
  // one lane alone skips those it does not read; a skip and a draw consume the same dimension, so
  // the values are the same.
  const bool lockstep_draws_;
  // The numbers nothing reads are skipped, in the lockstep draws too (a skip consumes the
  // dimension a draw would, so no later number changes): the light choice is read only by the
  // light BVH (selection by power takes the point sample's x), the lobe choice only by the
  // vertices shaded one by one, which a scene whose materials all have a lane kind never has. A
  // skip saves the draw's Owen-scrambled Sobol arithmetic (docs/performance.md, "What the Sobol
  // draws cost").
  const uint8_t light_choice_, lobe_choice_;
  // Plain diffuse and rough-conductor vertices are shaded together (SurfaceLanes); their light
  // samples too when all lights are triangles by power, else their lights are picked one by one
  // (and spheres' cones sampled together). Everything is in lane space: lane i's hit, numbers and
  // results in slot i of dl_'s arrays, where the packet query and the draws wrote them.
  const bool given_light_;
  // All lights spheres by power: their pick and cones in lane space too (lanes_sphere_lights).
  const bool spheres_in_lanes_;
  // Per thread, zeroed once: the slots no vertex has filled hold zeros or earlier vertices.
  static thread_local SurfaceLanes dl_;

  CameraPath lanes_[K];
  Accel::RayPacket rays_, shadow_;
  // In lane space, for the loop that adds the NEE terms: each lane's radiance, its pending NEE
  // term (beta at the vertex times f Le cos w / pdf) and whether its shadow ray was blocked.
  alignas(64) float sum_[3][K], nee_term_[3][K] = {};
  alignas(64) int blocked_[K] = {};
  int live_;
  int shading_[K], generic_[K], generics_ = 0;
  // This depth: whether roulette runs, whether it is the last (see arrive), whether some lane
  // has a shadow ray, whether some plain vertex is a rough conductor.
  bool roulette_ = false, last_ = false, any_shadow_ = false, conductors_ = false;
};

}  // namespace rf
