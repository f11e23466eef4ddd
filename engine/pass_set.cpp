#include "engine/pass_set.h"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <string_view>

namespace rf {

PassSet PassSet::range(uint32_t begin, uint32_t end) {
  PassSet s;
  if (begin < end) s.ranges.emplace_back(begin, end);
  return s;
}

uint32_t PassSet::count() const {
  uint32_t n = 0;
  for (auto [b, e] : ranges) n += e - b;
  return n;
}

bool PassSet::overlaps(const PassSet& o) const {
  size_t i = 0, j = 0;
  while (i < ranges.size() && j < o.ranges.size()) {
    if (ranges[i].second <= o.ranges[j].first) {
      ++i;
    } else if (o.ranges[j].second <= ranges[i].first) {
      ++j;
    } else {
      return true;
    }
  }
  return false;
}

void PassSet::add(const PassSet& o) {
  std::vector<std::pair<uint32_t, uint32_t>> all = ranges;
  all.insert(all.end(), o.ranges.begin(), o.ranges.end());
  std::sort(all.begin(), all.end());
  ranges.clear();
  for (auto r : all) {
    // Coalesce touching ranges ([0,4) + [4,8) = [0,8)) so equal sets compare equal.
    if (!ranges.empty() && r.first <= ranges.back().second) {
      ranges.back().second = std::max(ranges.back().second, r.second);
    } else {
      ranges.push_back(r);
    }
  }
}

// The empty set counts as the (empty) prefix [0, 0).
bool PassSet::is_prefix() const {
  return ranges.empty() || (ranges.size() == 1 && ranges[0].first == 0);
}

std::string PassSet::to_string() const {
  std::string s;
  for (auto [b, e] : ranges) {
    if (!s.empty()) s += ',';
    s += std::to_string(b);
    if (e - b > 1) s += '-' + std::to_string(e - 1);
  }
  return s;
}

namespace {

// A pass number: decimal digits only, at most UINT32_MAX - 1 (so its half-open end fits).
uint32_t parse_pass_number(std::string_view tok, const std::string& whole) {
  auto fail = [&](const std::string& why) {
    return std::invalid_argument("invalid pass set \"" + whole + "\": " + why);
  };
  if (tok.empty()) throw fail("empty pass number");
  uint64_t v = 0;
  for (char c : tok) {
    if (c < '0' || c > '9') throw fail("\"" + std::string(tok) + "\" is not a pass number");
    v = v * 10 + uint64_t(c - '0');
    if (v >= std::numeric_limits<uint32_t>::max()) {
      throw fail("pass number \"" + std::string(tok) + "\" is too large");
    }
  }
  return uint32_t(v);
}

}  // namespace

PassSet intersection(const PassSet& a, const PassSet& b) {
  PassSet out;
  size_t i = 0, j = 0;
  while (i < a.ranges.size() && j < b.ranges.size()) {
    uint32_t lo = std::max(a.ranges[i].first, b.ranges[j].first);
    uint32_t hi = std::min(a.ranges[i].second, b.ranges[j].second);
    if (lo < hi) out.ranges.emplace_back(lo, hi);
    (a.ranges[i].second < b.ranges[j].second) ? ++i : ++j;
  }
  return out;
}

// Accepts "", "5", "0-3,8-11" and the same ranges in any order; a pass listed twice is an error.
PassSet PassSet::parse(const std::string& s) {
  PassSet out;
  size_t pos = 0;
  while (!s.empty() && pos <= s.size()) {
    size_t comma = std::min(s.find(',', pos), s.size());
    std::string_view tok(s.data() + pos, comma - pos);
    size_t dash = tok.find('-');
    uint32_t first = parse_pass_number(tok.substr(0, dash), s);
    uint32_t last =
        dash == std::string_view::npos ? first : parse_pass_number(tok.substr(dash + 1), s);
    if (last < first) {
      throw std::invalid_argument("invalid pass set \"" + s + "\": range \"" + std::string(tok) +
                                  "\" ends before it begins");
    }
    PassSet r = range(first, last + 1);
    if (out.overlaps(r)) {
      throw std::invalid_argument("invalid pass set \"" + s + "\": passes " +
                                  intersection(out, r).to_string() + " listed twice");
    }
    out.add(r);
    pos = comma + 1;
  }
  return out;
}

}  // namespace rf
