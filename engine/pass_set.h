// Sets of pass indices (DESIGN.md "Passes, seeds and the determinism contract"): which passes a
// sample buffer holds, as sorted, disjoint ranges; merging requires disjoint sets.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace rf {

// A set of pass indices as sorted, disjoint, non-adjacent half-open ranges [begin, end).
struct PassSet {
  std::vector<std::pair<uint32_t, uint32_t>> ranges;

  static PassSet range(uint32_t begin, uint32_t end);  // [begin, end)
  uint32_t count() const;
  bool empty() const { return ranges.empty(); }
  bool overlaps(const PassSet& o) const;
  void add(const PassSet& o);                          // precondition: !overlaps(o)
  bool is_prefix() const;                              // exactly [0, n)
  std::string to_string() const;                       // "0-3,8-11" (inclusive ends)
  static PassSet parse(const std::string& s);          // inverse of to_string; throws
  bool operator==(const PassSet&) const = default;
};

PassSet intersection(const PassSet& a, const PassSet& b);

}  // namespace rf
