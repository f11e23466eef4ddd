// Light selection that sees the shading point: a bounding volume hierarchy over the lights
// (Conty Estevez and Kulla 2018, "Importance Sampling of Many Lights with Adaptive Tree Splitting";
// the form pbrt-v4's BVHLightSampler uses). Each node bounds its lights' positions, total power and
// the cone of their emitting normals; a light is picked by descending from the root and choosing
// each child with probability proportional to an importance that bounds, from above, what the
// child's lights can send to the shading point: power over squared distance, times the cosine
// of the smallest angle the bounds allow at the emitters and at the receiver.
//
// The importance is conservative: a light that can contribute at (p, n) always keeps a non-zero
// probability, so the estimator stays unbiased; lights that face away, or lie wholly below a
// reflecting receiver's horizon, get probability 0, which is exact since they contribute nothing.
//
// Limit: the descent rescales one 1D sample (24 bits of a float) at each level. A light whose
// probability is below about 2^-24 may be picked at a rate that differs from its pmf; with far
// fewer lights than 2^24 that mass is negligible (pbrt-v4 has the same limit).
#pragma once

#include <cstdint>
#include <vector>

#include "engine/math.h"

namespace rf {

// What the hierarchy knows about one light or a node's lights.
struct LightBounds {
  Vec3 lo{kInf}, hi{-kInf};  // bounding box of the emitting points
  float phi = 0;             // power (LightSet's selection weight)
  Vec3 w{0.0f, 0.0f, 1.0f};  // axis of the cone that holds every emitting normal
  float cos_theta_o = 1;     // cos of that cone's half-angle (-1: normals in every direction)
  float cos_theta_e = 0;     // cos of how far past its normal a point emits (0: a hemisphere)
  bool two_sided = false;    // emits on both sides of each normal

  // Upper bound (up to one common factor) of what these lights can send to point p. n: unit
  // normal of the hemisphere light can arrive from at p (a surface that only reflects), or zero
  // when every direction counts.
  float importance(Vec3 p, Vec3 n) const;
};

// Bounds of two nodes' lights together.
LightBounds union_bounds(const LightBounds& a, const LightBounds& b);

class LightBvh {
 public:
  LightBvh() = default;
  // Builds over lights[i] (i is what sample() returns). Lights with phi <= 0 are left out: they
  // are never picked and their pmf is 0.
  explicit LightBvh(const std::vector<LightBounds>& lights);

  bool empty() const { return nodes_.empty(); }
  size_t node_count() const { return nodes_.size(); }
  int depth() const { return depth_; }

  // Picks a light as seen from (p, n) with the 1D sample u; pmf is the probability of the pick.
  // False when no light can contribute at p.
  bool sample(Vec3 p, Vec3 n, float u, uint32_t& light, float& pmf) const;
  // The probability that sample() picks `light` from (p, n); bit-identical to sample()'s pmf.
  float pmf(Vec3 p, Vec3 n, uint32_t light) const;

 private:
  struct Node {
    LightBounds bounds;
    uint32_t second_child = 0;  // interior node: the first child is the next node
    uint32_t light = 0;         // leaf: the light
    bool leaf = false;
  };
  struct Item {
    LightBounds bounds;
    uint32_t light;
  };
  uint32_t build(std::vector<Item>& items, size_t begin, size_t end, int depth);
  // Probability of taking the first child of interior node `index` from (p, n); < 0 when neither
  // child can contribute.
  double first_child_probability(uint32_t index, Vec3 p, Vec3 n) const;

  std::vector<Node> nodes_;
  std::vector<uint64_t> trail_;   // per light: bit k = 1 when the path from the root takes the
                                  // second child at depth k
  std::vector<uint8_t> in_tree_;  // per light: 1 when the light is a leaf of the tree
  int depth_ = 0;
};

}  // namespace rf
