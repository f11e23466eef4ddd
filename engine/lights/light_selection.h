// Which light next-event estimation samples (pbrt-v4's light samplers): by power, or by a light
// BVH that sees the shading point. The light list (light_set.h) hands each light's power, its
// group and its bounds; the numbering is the list's.
//
// Selection by power: one light is picked with probability proportional to its power (LightSet
// says how each kind's power is measured). The pick is made in two steps with the same
// probabilities, both by the first coordinate of the 2D point sample (Mitsuba's sample reuse): it
// picks a group (an emissive mesh, or one other light) by its power and is rescaled to [0, 1)
// within the group's interval, then picks the primitive of the group by its power and is
// rescaled again within that primitive's interval. So a stratified 2D sample stays stratified
// over each light and over the whole emitting mesh (a quad light's two triangles), where a
// separate 1D pick would hand each light a random subset of the points (more squared error on
// veach-mis's three spheres; docs/performance.md, "Many lights: the light BVH"). If every power is
// 0 (say, only zero-area triangles), lights are picked uniformly.
//
// Selection that sees the shading point (RenderSettings::light_selection "bvh", or "auto" with
// more than kAutoBvhLights lights that have a position): a light BVH (light_bvh.h) over the
// lights with a position (area primitives, point and spot lights) picks one by an importance
// bound at the shading point; the infinite lights (directional, environment) keep their power
// share. The set of all BVH lights is chosen with the sum of their power pmfs, so the
// environment's pmf is the same in both modes. With the BVH the two-step reuse of u_point.x does
// not apply: each primitive is its own light, picked by the separate u_select (which power
// selection leaves unread).
// Light tracing, BDPT's light subpaths and its s = 1 connections stay power-based (select(),
// pmf()), whose MIS weights need a pmf that does not depend on a point.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "engine/lights/light_bvh.h"
#include "engine/math.h"

namespace rf {

class LightSelection {
 public:
  // What the first step picks: one light, or the primitives of an emissive mesh (lights
  // first .. first + count - 1).
  struct Group {
    uint32_t first, count;
  };
  static constexpr uint32_t kNone = ~0u;
  // More lights with a position than this make "auto" selection use the BVH.
  static constexpr size_t kAutoBvhLights = 8;

  LightSelection() = default;
  // power[i]: light i's power; groups: the lights in order, partitioned; bounds[i]: a positioned
  // light's bounds (its phi is set here from its power), unread where positioned[i] is false;
  // mode: RenderSettings::light_selection.
  LightSelection(std::vector<double> power, std::vector<Group> groups,
                 std::vector<LightBounds> bounds, const std::vector<bool>& positioned,
                 const std::string& mode);

  // The light ux picks by power (both steps), ux rescaled within its interval at each step so
  // that (ux, u_point.y) stays a stratified 2D sample over the light; kNone when nothing can be
  // picked.
  size_t select(float& ux) const;
  // The light picked for a shading point p with receiver normal n (or zero), its selection
  // probability, and u_point as the light's own sampling then takes it (rescaled by a pick by
  // power); false when nothing can be picked.
  bool pick(Vec3 p, Vec3 n, float u_select, Vec2& u_point, size_t& light, float& pmf) const;
  // The probability that pick() picks `light` from (p, n).
  float pmf_at(size_t light, Vec3 p, Vec3 n) const;
  // The probability of selecting each light by power (sums to 1 over all lights).
  float pmf(size_t light) const { return pmf_[light]; }
  double power(size_t light) const { return power_[light]; }
  bool uses_bvh() const { return !bvh_.empty(); }
  const LightBvh& bvh() const { return bvh_; }

  // The two steps' tables, for lane kernels that pick for many points at once with select()'s
  // arithmetic (integrators/path/lane_lights.h): the groups, the cumulative probability over
  // groups (group_cdf()[g] is the end of group g's interval, the last 1), and within each group
  // over its lights (within_cdf()[first + k], the last of each group 1).
  const std::vector<Group>& groups() const { return groups_; }
  const double* group_cdf() const { return cdf_.data() + 1; }
  const double* within_cdf() const { return within_cdf_.data(); }

 private:
  void build_bvh(std::vector<LightBounds> bounds, const std::vector<bool>& positioned,
                 const std::string& mode);

  std::vector<double> power_;
  std::vector<Group> groups_;
  std::vector<bool> positioned_;    // per light: it has a position (not directional, environment)
  std::vector<double> cdf_;         // over groups: groups_.size()+1, cdf_[0] = 0, back() = 1
  std::vector<double> within_cdf_;  // per light: cumulative probability within its group
  std::vector<float> pmf_;
  // BVH selection (uses_bvh()): the tree over lights with a position, the probability of
  // choosing among them, and the infinite lights with their cumulative power share.
  LightBvh bvh_;
  float bvh_share_ = 0;
  std::vector<uint32_t> infinite_;
  std::vector<double> infinite_cdf_;  // infinite_.size() + 1 entries, within the infinite lights
};

}  // namespace rf
