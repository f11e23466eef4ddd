#include "engine/lights/light_bvh.h"

#include <algorithm>
#include <array>
#include <cmath>

namespace rf {

namespace {

// cos(max(0, a - b)) from the cosines (and sines) of angles a, b in [0, pi]: 1 when a <= b.
float cos_sub_clamped(float cos_a, float sin_a, float cos_b, float sin_b) {
  if (cos_a >= cos_b) return 1.0f;
  return cos_a * cos_b + sin_a * sin_b;
}

double angle_of(double cos_t) { return std::acos(std::clamp(cos_t, -1.0, 1.0)); }

// Rotates unit vector v about unit axis k by angle t (Rodrigues).
Vec3 rotate_about(Vec3 v, Vec3 k, double t) {
  double c = std::cos(t), s = std::sin(t);
  Vec3 kxv = cross(k, v);
  double kv = dot(k, v);
  return Vec3(float(v.x * c + kxv.x * s + k.x * kv * (1 - c)),
              float(v.y * c + kxv.y * s + k.y * kv * (1 - c)),
              float(v.z * c + kxv.z * s + k.z * kv * (1 - c)));
}

// The smallest cone (axis, cos of half-angle) holding cones a and b (pbrt-v4's DirectionCone
// Union, after Conty Estevez and Kulla): -1 when only the whole sphere does.
void cone_union(Vec3 wa, float cos_a, Vec3 wb, float cos_b, Vec3& w, float& cos_o) {
  if (cos_a <= -1.0f || cos_b <= -1.0f) {
    w = wa, cos_o = -1.0f;
    return;
  }
  double ta = angle_of(cos_a), tb = angle_of(cos_b), td = angle_of(dot(wa, wb));
  if (std::min(td + tb, double(kPi)) <= ta) {
    w = wa, cos_o = cos_a;
    return;
  }
  if (std::min(td + ta, double(kPi)) <= tb) {
    w = wb, cos_o = cos_b;
    return;
  }
  double to = 0.5 * (ta + td + tb);
  Vec3 axis = cross(wa, wb);
  if (to >= double(kPi) || length_sq(axis) == 0) {
    w = wa, cos_o = -1.0f;
    return;
  }
  w = normalize(rotate_about(wa, normalize(axis), to - ta));
  // Rounded outwards a little, so the float cone still holds both.
  cos_o = float(std::max(-1.0, std::cos(to) - 1e-5));
}

// Conty Estevez and Kulla's orientation measure M_Omega of a node: the solid angle its normal
// cone, widened by the emission spread, sweeps (weighted by cosine).
double orientation_measure(const LightBounds& b) {
  double to = angle_of(b.cos_theta_o), te = angle_of(b.cos_theta_e);
  double tw = std::min(to + te, double(kPi));
  double so = std::sin(to);
  return 2 * kPi * (1 - std::cos(to)) +
         kPi / 2 * (2 * tw * so - std::cos(to - 2 * tw) - 2 * to * so + std::cos(to));
}

double surface_area(Vec3 lo, Vec3 hi) {
  Vec3 d = vmax(hi - lo, Vec3(0.0f));
  return 2.0 * (double(d.x) * d.y + double(d.y) * d.z + double(d.z) * d.x);
}

// Split cost of a node (pbrt-v4's EvaluateCost): power x orientation measure x surface area, the
// area scaled up for boxes thin along the split axis so that slabs are not preferred.
double split_cost(const LightBounds& b, Vec3 parent_lo, Vec3 parent_hi, int axis) {
  Vec3 d = parent_hi - parent_lo;
  float max_d = max_component(d);
  double kr = d[axis] > 0 ? max_d / d[axis] : 1.0;
  return double(b.phi) * orientation_measure(b) * kr * surface_area(b.lo, b.hi);
}

constexpr int kBuckets = 12;
constexpr int kMaxDepth = 64;          // the trail is 64 bits
constexpr int kMedianSplitDepth = 40;  // from here on, halve by count so the depth stays bounded

}  // namespace

float LightBounds::importance(Vec3 p, Vec3 n) const {
  if (!(phi > 0)) return 0.0f;
  Vec3 pc = 0.5f * (lo + hi);
  Vec3 dp = p - pc;
  float d2 = length_sq(dp);
  float r2 = 0.25f * length_sq(hi - lo);  // squared radius of the box's bounding sphere
  // Directions from the lights' centre to p, and the half-angle of the cone of directions from p
  // that holds the whole bounding sphere (every direction when p is inside it).
  float cos_b = -1.0f, sin_b = 0.0f;
  Vec3 wi(0.0f, 0.0f, 1.0f);
  bool inside = !(d2 > r2);
  if (!inside) {
    wi = dp / std::sqrt(d2);
    float sin2_b = r2 / d2;
    cos_b = safe_sqrt(1.0f - sin2_b);
    sin_b = std::sqrt(sin2_b);
  }
  float cos_theta_p = 1.0f;  // cos of the smallest angle between a normal and a direction to p
  if (!inside && cos_theta_o > -1.0f) {
    float cos_w = dot(w, wi);
    if (two_sided) cos_w = std::fabs(cos_w);
    float sin_w = safe_sqrt(1.0f - cos_w * cos_w);
    float sin_o = safe_sqrt(1.0f - cos_theta_o * cos_theta_o);
    float cos_x = cos_sub_clamped(cos_w, sin_w, cos_theta_o, sin_o);  // theta_w - theta_o
    float sin_x = safe_sqrt(1.0f - cos_x * cos_x);
    cos_theta_p = cos_sub_clamped(cos_x, sin_x, cos_b, sin_b);  // ... - theta_b
    if (cos_theta_p <= cos_theta_e) return 0.0f;                // beyond the emission
  }
  float receiver = 1.0f;
  if (!inside && !(n.x == 0 && n.y == 0 && n.z == 0)) {
    float cos_i = -dot(wi, n);  // cos between n and the direction from p to the centre
    float sin_i = safe_sqrt(1.0f - cos_i * cos_i);
    receiver = cos_sub_clamped(cos_i, sin_i, cos_b, sin_b);
    if (receiver <= 0) return 0.0f;  // wholly below the horizon
  }
  // Distance clamped to the bounding sphere's radius: the bound must not blow up near or inside.
  float dist2 = std::max(d2, r2);
  if (!(dist2 > 0)) dist2 = std::numeric_limits<float>::min();
  return phi * cos_theta_p * receiver / dist2;
}

LightBounds union_bounds(const LightBounds& a, const LightBounds& b) {
  if (!(a.phi > 0)) return b;
  if (!(b.phi > 0)) return a;
  LightBounds u;
  u.lo = vmin(a.lo, b.lo);
  u.hi = vmax(a.hi, b.hi);
  u.phi = a.phi + b.phi;
  cone_union(a.w, a.cos_theta_o, b.w, b.cos_theta_o, u.w, u.cos_theta_o);
  u.cos_theta_e = std::min(a.cos_theta_e, b.cos_theta_e);
  u.two_sided = a.two_sided || b.two_sided;
  return u;
}

LightBvh::LightBvh(const std::vector<LightBounds>& lights) {
  trail_.assign(lights.size(), 0);
  in_tree_.assign(lights.size(), 0);
  std::vector<Item> items;
  for (size_t i = 0; i < lights.size(); ++i)
    if (lights[i].phi > 0) items.push_back({lights[i], uint32_t(i)});
  if (items.empty()) return;
  nodes_.reserve(2 * items.size() - 1);
  build(items, 0, items.size(), 0);
  // Trails: walk the tree once.
  struct Entry {
    uint32_t node;
    uint64_t trail;
    int depth;
  };
  std::vector<Entry> stack{{0, 0, 0}};
  while (!stack.empty()) {
    Entry e = stack.back();
    stack.pop_back();
    const Node& nd = nodes_[e.node];
    depth_ = std::max(depth_, e.depth);
    if (nd.leaf) {
      trail_[nd.light] = e.trail;
      in_tree_[nd.light] = 1;
      continue;
    }
    stack.push_back({e.node + 1, e.trail, e.depth + 1});
    stack.push_back({nd.second_child, e.trail | (uint64_t(1) << e.depth), e.depth + 1});
  }
}

uint32_t LightBvh::build(std::vector<Item>& items, size_t begin, size_t end, int depth) {
  uint32_t index = uint32_t(nodes_.size());
  nodes_.emplace_back();
  if (end - begin == 1) {
    nodes_[index].bounds = items[begin].bounds;
    nodes_[index].light = items[begin].light;
    nodes_[index].leaf = true;
    return index;
  }
  LightBounds all;
  Vec3 clo(kInf), chi(-kInf);  // bounds of the centroids
  for (size_t i = begin; i < end; ++i) {
    all = union_bounds(all, items[i].bounds);
    Vec3 c = 0.5f * (items[i].bounds.lo + items[i].bounds.hi);
    clo = vmin(clo, c), chi = vmax(chi, c);
  }
  size_t mid = begin + (end - begin) / 2;
  auto centroid = [](const Item& it, int axis) {
    return 0.5f * (it.bounds.lo[axis] + it.bounds.hi[axis]);
  };
  int best_axis = -1, best_bucket = -1;
  if (depth < kMedianSplitDepth) {
    double best_cost = std::numeric_limits<double>::infinity();
    for (int axis = 0; axis < 3; ++axis) {
      float extent = chi[axis] - clo[axis];
      if (!(extent > 0)) continue;
      std::array<LightBounds, kBuckets> bucket;
      for (size_t i = begin; i < end; ++i) {
        int b = std::min(kBuckets - 1,
                         int(kBuckets * ((centroid(items[i], axis) - clo[axis]) / extent)));
        bucket[b] = union_bounds(bucket[b], items[i].bounds);
      }
      // Costs of splitting after bucket k: prefix unions from the left, suffix from the right.
      std::array<LightBounds, kBuckets> right;
      right[kBuckets - 1] = bucket[kBuckets - 1];
      for (int k = kBuckets - 2; k >= 0; --k) right[k] = union_bounds(bucket[k], right[k + 1]);
      LightBounds left;
      for (int k = 0; k < kBuckets - 1; ++k) {
        left = union_bounds(left, bucket[k]);
        if (!(left.phi > 0) || !(right[k + 1].phi > 0)) continue;
        double cost =
            split_cost(left, all.lo, all.hi, axis) + split_cost(right[k + 1], all.lo, all.hi, axis);
        if (cost < best_cost) best_cost = cost, best_axis = axis, best_bucket = k;
      }
    }
  }
  if (best_axis >= 0) {
    float extent = chi[best_axis] - clo[best_axis];
    auto it = std::partition(items.begin() + begin, items.begin() + end, [&](const Item& x) {
      int b = std::min(kBuckets - 1,
                       int(kBuckets * ((centroid(x, best_axis) - clo[best_axis]) / extent)));
      return b <= best_bucket;
    });
    mid = size_t(it - items.begin());
  }
  if (mid == begin || mid == end || depth + 1 >= kMaxDepth) {
    // No useful split (equal centroids, or deep): halve by count along the widest axis.
    int axis = 0;
    Vec3 d = chi - clo;
    if (d.y > d[axis]) axis = 1;
    if (d.z > d[axis]) axis = 2;
    mid = begin + (end - begin) / 2;
    std::nth_element(items.begin() + begin, items.begin() + mid, items.begin() + end,
                     [&](const Item& a, const Item& b) {
                       float ca = centroid(a, axis), cb = centroid(b, axis);
                       return ca < cb || (ca == cb && a.light < b.light);
                     });
  }
  build(items, begin, mid, depth + 1);
  uint32_t second = build(items, mid, end, depth + 1);
  nodes_[index].bounds = all;
  nodes_[index].second_child = second;
  return index;
}

double LightBvh::first_child_probability(uint32_t index, Vec3 p, Vec3 n) const {
  float i0 = nodes_[index + 1].bounds.importance(p, n);
  float i1 = nodes_[nodes_[index].second_child].bounds.importance(p, n);
  if (!(i0 > 0) && !(i1 > 0)) return -1.0;
  return double(i0) / (double(i0) + double(i1));
}

bool LightBvh::sample(Vec3 p, Vec3 n, float u, uint32_t& light, float& pmf) const {
  if (nodes_.empty()) return false;
  if (nodes_[0].leaf && !(nodes_[0].bounds.importance(p, n) > 0)) return false;
  double uu = u, prob = 1.0;
  uint32_t index = 0;
  while (!nodes_[index].leaf) {
    const Node& node = nodes_[index];
    double p0 = first_child_probability(index, p, n);
    if (p0 < 0) return false;
    if (uu < p0) {
      uu = uu / p0;
      prob *= p0;
      index = index + 1;
    } else {
      uu = (uu - p0) / (1.0 - p0);
      prob *= 1.0 - p0;
      index = node.second_child;
    }
    uu = std::min(uu, 0x1.fffffffffffffp-1);
  }
  light = nodes_[index].light;
  pmf = float(prob);
  return pmf > 0;
}

float LightBvh::pmf(Vec3 p, Vec3 n, uint32_t light) const {
  if (light >= in_tree_.size() || !in_tree_[light]) return 0.0f;
  if (nodes_[0].leaf) return nodes_[0].bounds.importance(p, n) > 0 ? 1.0f : 0.0f;
  uint64_t trail = trail_[light];
  double prob = 1.0;
  uint32_t index = 0;
  while (!nodes_[index].leaf) {
    const Node& node = nodes_[index];
    double p0 = first_child_probability(index, p, n);
    if (p0 < 0) return 0.0f;
    if (trail & 1) {
      prob *= 1.0 - p0;
      index = node.second_child;
    } else {
      prob *= p0;
      index = index + 1;
    }
    trail >>= 1;
  }
  return float(prob);
}

}  // namespace rf
