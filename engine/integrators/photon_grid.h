// A spatial hash grid over points for fixed-radius queries (photon gathering).
//
// Cells are cubes of side 2r, so the ball of radius r around any point touches at most 2x2x2
// cells. Cell (i, j, k) hashes into a power-of-two table of about twice as many buckets as items;
// the items are stored sorted by bucket (a stable counting sort, so the order, and every sum over
// a query, is a pure function of the input order). A query visits each distinct bucket of its
// cells once and tests the distance, so hash collisions cost time, never correctness. Queries
// allocate nothing.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "engine/math.h"

namespace rf {

template <class Item>  // Item has a member `Vec3 p`
class PointHashGrid {
 public:
  PointHashGrid() = default;
  PointHashGrid(std::vector<Item> items, float radius) { build(std::move(items), radius); }

  void build(std::vector<Item> items, float radius) {
    radius_ = radius;
    cell_ = 2 * radius;
    inv_cell_ = cell_ > 0 ? 1 / cell_ : 0;
    size_t buckets = 1;
    while (buckets < 2 * items.size()) buckets <<= 1;
    mask_ = uint32_t(buckets - 1);
    start_.assign(buckets + 1, 0);
    std::vector<uint32_t> bucket_of(items.size());
    for (size_t i = 0; i < items.size(); ++i) {
      bucket_of[i] =
          bucket(cell_coord(items[i].p.x), cell_coord(items[i].p.y), cell_coord(items[i].p.z));
      ++start_[bucket_of[i] + 1];
    }
    for (size_t b = 0; b < buckets; ++b) start_[b + 1] += start_[b];
    std::vector<uint32_t> next(start_.begin(), start_.end() - 1);
    items_.resize(items.size());
    for (size_t i = 0; i < items.size(); ++i) items_[next[bucket_of[i]]++] = std::move(items[i]);
  }

  // Calls f(item) for every item within the radius of x (distance <= r).
  template <class F>
  void for_each_near(Vec3 x, F&& f) const {
    if (items_.empty()) return;
    int lo[3], hi[3];
    const float c[3] = {x.x, x.y, x.z};
    for (int a = 0; a < 3; ++a) {
      lo[a] = cell_coord(c[a] - radius_);
      hi[a] = cell_coord(c[a] + radius_);
    }
    uint32_t seen[27];  // 2x2x2 cells, 3 per axis when rounding widens the range
    int n_seen = 0;
    const float r2 = radius_ * radius_;
    for (int i = lo[0]; i <= hi[0]; ++i)
      for (int j = lo[1]; j <= hi[1]; ++j)
        for (int k = lo[2]; k <= hi[2]; ++k) {
          uint32_t b = bucket(i, j, k);
          if (std::find(seen, seen + n_seen, b) != seen + n_seen) continue;
          seen[n_seen++] = b;
          for (uint32_t m = start_[b]; m < start_[b + 1]; ++m) {
            Vec3 d = items_[m].p - x;
            if (dot(d, d) <= r2) f(items_[m]);
          }
        }
  }

  float radius() const { return radius_; }
  const std::vector<Item>& items() const { return items_; }

 private:
  // Cell index along one axis; the clamp keeps far-away or non-finite points in range (they only
  // share cells with each other, which the distance test sorts out).
  int cell_coord(float v) const {
    float c = std::floor(v * inv_cell_);
    return c >= -1e9f && c <= 1e9f ? int(c) : (c > 0 ? 1000000000 : -1000000000);
  }
  uint32_t bucket(int i, int j, int k) const {
    // Teschner et al. 2003, "Optimized Spatial Hashing for Collision Detection".
    uint32_t h = (uint32_t(i) * 73856093u) ^ (uint32_t(j) * 19349663u) ^ (uint32_t(k) * 83492791u);
    return h & mask_;
  }

  float radius_ = 0, cell_ = 0, inv_cell_ = 0;
  uint32_t mask_ = 0;
  std::vector<uint32_t> start_;  // bucket b holds items_[start_[b], start_[b + 1])
  std::vector<Item> items_;
};

}  // namespace rf
