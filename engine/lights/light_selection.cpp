// Light selection: see light_selection.h.
#include "engine/lights/light_selection.h"

#include <algorithm>
#include <cmath>

#include "engine/check.h"

namespace rf {

LightSelection::LightSelection(std::vector<double> power, std::vector<Group> groups,
                               std::vector<LightBounds> bounds, const std::vector<bool>& positioned,
                               const std::string& mode)
    : power_(std::move(power)), groups_(std::move(groups)), positioned_(positioned) {
  // Two steps with the same per-light probability as one power-proportional pick: a group by its
  // power, then a light of the group by its power within the group.
  const size_t n = power_.size();
  RF_CHECK(bounds.size() == n && positioned.size() == n,
           std::to_string(bounds.size()) + " bounds for " + std::to_string(n) + " lights");
  double total = 0;
  for (double p : power_) total += p;
  pmf_.resize(n);
  for (size_t i = 0; i < n; ++i) pmf_[i] = float(total > 0 ? power_[i] / total : 1.0 / double(n));
  if constexpr (kDchecks) {
    double sum = 0;  // each pmf is rounded to float: the sum is 1 within n x 2^-24 relative
    for (float p : pmf_) sum += double(p);
    RF_DCHECK(n == 0 || std::fabs(sum - 1.0) < 1e-5, "light pmfs sum to " + std::to_string(sum));
  }
  cdf_.assign(groups_.size() + 1, 0.0);
  within_cdf_.assign(n, 1.0);
  for (size_t g = 0; g < groups_.size(); ++g) {
    const Group& gr = groups_[g];
    double gp = 0;
    for (uint32_t k = 0; k < gr.count; ++k) gp += power_[gr.first + k];
    cdf_[g + 1] = cdf_[g] + (total > 0 ? gp / total : double(gr.count) / double(n));
    double acc = 0;
    for (uint32_t k = 0; k < gr.count; ++k) {
      acc += gp > 0 ? power_[gr.first + k] / gp : 1.0 / double(gr.count);
      within_cdf_[gr.first + k] = acc;
    }
    within_cdf_[gr.first + gr.count - 1] = 1.0;
  }
  RF_DCHECK(groups_.empty() || std::fabs(cdf_.back() - 1.0) < 1e-9,
            "the light groups' cdf ends at " + std::to_string(cdf_.back()));
  if (!groups_.empty()) cdf_.back() = 1.0;
  build_bvh(std::move(bounds), positioned, mode);
}

void LightSelection::build_bvh(std::vector<LightBounds> bounds, const std::vector<bool>& positioned,
                               const std::string& mode) {
  size_t in_tree = 0;
  double tree_share = 0;
  for (size_t i = 0; i < bounds.size(); ++i) {
    if (!positioned[i]) {
      bounds[i] = LightBounds{};  // an infinite light: not in the tree
      continue;
    }
    float phi = float(power_[i]);
    if (!(phi > 0) || !std::isfinite(phi)) continue;
    bounds[i].phi = phi;
    ++in_tree;
    tree_share += pmf_[i];
  }
  bool use = mode == "bvh" || (mode == "auto" && in_tree > kAutoBvhLights);
  if (!use || in_tree == 0) return;
  bvh_ = LightBvh(bounds);
  bvh_share_ = float(std::min(1.0, tree_share));
  // Every positioned light with power is in the tree; the rest of the unit is the infinite ones'.
  infinite_cdf_.assign(1, 0.0);
  double acc = 0, inf_total = 0;
  for (size_t i = 0; i < positioned.size(); ++i)
    if (!positioned[i]) infinite_.push_back(uint32_t(i)), inf_total += pmf_[i];
  for (uint32_t i : infinite_) {
    acc += inf_total > 0 ? pmf_[i] / inf_total : 0.0;
    infinite_cdf_.push_back(acc);
  }
  if (!infinite_.empty()) infinite_cdf_.back() = 1.0;
  if (infinite_.empty()) bvh_share_ = 1.0f;
}

// Each rescale costs x resolution: about 2^-24 / (group pmf x primitive pmf within the group) is
// left.
size_t LightSelection::select(float& ux) const {
  const size_t ng = groups_.size();
  if (ng == 0) return kNone;
  // First cdf entry > ux: the group whose interval [cdf_g, cdf_g+1) holds ux (one group: it),
  // and ux rescaled to [0, 1) within it (as the step within the group below, whose lane version
  // in integrators/path/lane_lights.cpp also does this step for spheres).
  size_t g = 0;
  if (ng > 1) {
    g = size_t(std::upper_bound(cdf_.begin() + 1, cdf_.end(), double(ux)) - (cdf_.begin() + 1));
    g = std::min(g, ng - 1);
    while (cdf_[g + 1] == cdf_[g] && g > 0) --g;  // a zero-width interval cannot be selected
    double lo = g > 0 ? cdf_[g] : 0.0, hi = cdf_[g + 1];
    ux = hi > lo ? float(std::clamp((double(ux) - lo) / (hi - lo), 0.0, 1.0)) : 0.5f;
    ux = std::min(ux, 0x1.fffffep-1f);
  }
  const Group& gr = groups_[g];
  size_t i = gr.first;
  if (gr.count > 1) {
    auto begin = within_cdf_.begin() + gr.first, end = begin + gr.count;
    const double x = double(ux);
    if (gr.count <= 16) {
      // upper_bound's position in a sorted range is the number of entries it does not pass
      // (!(x < c)); counted without branches: a search's branches mispredict on random u.
      size_t k = 0;
      for (auto c = begin; c != end; ++c) k += !(x < *c);
      i = gr.first + k;
    } else {
      i = size_t(std::upper_bound(begin, end, x) - within_cdf_.begin());
    }
    i = std::min(i, size_t(gr.first + gr.count - 1));
    while (pmf_[i] == 0 && i > gr.first) --i;
    double lo = i > gr.first ? within_cdf_[i - 1] : 0.0, hi = within_cdf_[i];
    ux = hi > lo ? float(std::clamp((double(ux) - lo) / (hi - lo), 0.0, 1.0)) : 0.5f;
    ux = std::min(ux, 0x1.fffffep-1f);
  }
  return pmf_[i] > 0 ? i : kNone;
}

bool LightSelection::pick(Vec3 p, Vec3 n, float u_select, Vec2& u_point, size_t& light,
                          float& pmf) const {
  if (!uses_bvh()) {
    light = select(u_point.x);
    pmf = light == kNone ? 0.0f : pmf_[light];
    return light != kNone;
  }
  if (u_select < bvh_share_) {
    uint32_t i;
    float u = std::min(u_select / bvh_share_, 0x1.fffffep-1f);
    if (!bvh_.sample(p, n, u, i, pmf)) return false;
    light = i, pmf *= bvh_share_;
    return true;
  }
  if (infinite_.empty()) return false;
  double u = (double(u_select) - bvh_share_) / (1.0 - bvh_share_);
  size_t k = size_t(std::upper_bound(infinite_cdf_.begin() + 1, infinite_cdf_.end(), u) -
                    (infinite_cdf_.begin() + 1));
  k = std::min(k, infinite_.size() - 1);
  light = infinite_[k], pmf = pmf_[light];
  return pmf > 0;
}

float LightSelection::pmf_at(size_t light, Vec3 p, Vec3 n) const {
  if (light >= pmf_.size()) return 0.0f;
  if (!uses_bvh()) return pmf_[light];
  if (!positioned_[light]) return pmf_[light];  // an infinite light: its power share
  return bvh_share_ * bvh_.pmf(p, n, uint32_t(light));
}

}  // namespace rf
