// Sample buffers: pass sets, accumulation, batch-means variance, merging, tile assembly and the
// .rfb partial-result file (DESIGN.md "Sample buffers and variance").
//
// .rfb format, version 1 (docs/sample-buffer-format.md). All integers and floats little-endian.
//
//   offset  size     content
//   0       8        magic 89 52 46 42 0D 0A 1A 0A ("\x89RFB\r\n\x1a\n"; PNG-style, so 7-bit
//                    transfers and line-ending conversion are caught at the first bytes)
//   8       4        u32 format version = 1
//   12      4        u32 header length L
//   16      L        header: UTF-8 JSON object, padded with trailing spaces so that 16 + L is a
//                    multiple of 8 (the planes are then 8-byte aligned in the file)
//   16+L    ...      planes, row-major over rect, A = rect.w * rect.h pixels, RGB interleaved:
//                      count        u64 x A
//                      sum          f64 x 3A
//                      sum_sq       f64 x 3A
//                      batch_sum    f64 x 3A
//                      batch_sum_sq f64 x 3A
//                      splat        f64 x 3 * width * height   (only when has_splats)
//   end-32  32       SHA-256 of every byte before it
//
// Header keys: format ("rayfarm-sample-buffer"), scene_digest, seed, frame, integrator, settings,
// width, height, passes (PassSet::to_string), build_id, isa, core_seconds, rect {x0, y0, w, h},
// has_splats, light_paths, nonfinite_samples, rays. Unknown keys are ignored, so a later version
// may add keys without breaking this reader.
//
// Reading checks, in this order: magic, version, header length against the file size, the
// checksum, every header field's type and range, the rect inside the frame, and that the plane
// bytes are exactly what the rect and flags say. Nothing is allocated or read before the sizes
// agree, so a truncated or lying file costs an exception, never an out-of-bounds read.
#include "engine/film.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cassert>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <string_view>

#include "engine/digest.h"

namespace rf {

// ---------------------------------------------------------------------------------------------
// PassSet

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

}  // namespace

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

// ---------------------------------------------------------------------------------------------
// SampleBuffer

namespace {

std::string rect_string(const Rect& r) {
  return std::to_string(r.w) + "x" + std::to_string(r.h) + " at (" + std::to_string(r.x0) + "," +
         std::to_string(r.y0) + ")";
}

size_t frame_channels(const BufferHeader& h) { return 3 * size_t(h.width) * size_t(h.height); }

// True when every plane has the size the rect and the splat flag call for.
bool planes_match_rect(const SampleBuffer& b) {
  if (b.rect.w < 0 || b.rect.h < 0) return false;
  size_t a = size_t(b.rect.area());
  return b.count.size() == a && b.sum.size() == 3 * a && b.sum_sq.size() == 3 * a &&
         b.batch_sum.size() == 3 * a && b.batch_sum_sq.size() == 3 * a &&
         (b.splat.empty() || b.splat.size() == frame_channels(b.header));
}

using RGBd = std::array<double, 3>;

// Camera mean sum / count plus splat / light paths, in double.
RGBd estimate_at(const SampleBuffer& b, int x, int y) {
  size_t i = b.pixel_index(x, y);
  RGBd e{};
  uint64_t n = b.count[i];
  for (int c = 0; c < 3; ++c) e[c] = n ? b.sum[3 * i + c] / double(n) : 0.0;
  if (!b.splat.empty() && b.light_paths > 0) {
    size_t f = size_t(y) * size_t(b.header.width) + size_t(x);
    for (int c = 0; c < 3; ++c) e[c] += b.splat[3 * f + c] / double(b.light_paths);
  }
  return e;
}

// Batch means over n passes: m = S/n, s^2 = (Q - n m^2) / (n - 1) clamped at 0, Var(mean) = s^2/n.
RGBd variance_at(const SampleBuffer& b, int x, int y) {
  RGBd v{};
  double n = double(b.header.passes.count());
  if (n < 2) return v;
  size_t i = b.pixel_index(x, y);
  for (int c = 0; c < 3; ++c) {
    double m = b.batch_sum[3 * i + c] / n;
    double s2 = (b.batch_sum_sq[3 * i + c] - n * m * m) / (n - 1);
    v[c] = std::max(0.0, s2) / n;
  }
  return v;
}

RGB to_rgb(const RGBd& v) { return RGB(float(v[0]), float(v[1]), float(v[2])); }

}  // namespace

SampleBuffer::SampleBuffer(BufferHeader h, Rect r, bool with_splats)
    : header(std::move(h)), rect(r) {
  if (r.w < 0 || r.h < 0 || !Rect{0, 0, header.width, header.height}.contains(r)) {
    throw std::invalid_argument("sample buffer rect " + rect_string(r) + " is not inside the " +
                                std::to_string(header.width) + "x" + std::to_string(header.height) +
                                " frame");
  }
  size_t a = size_t(r.area());
  count.assign(a, 0);
  sum.assign(3 * a, 0.0);
  sum_sq.assign(3 * a, 0.0);
  batch_sum.assign(3 * a, 0.0);
  batch_sum_sq.assign(3 * a, 0.0);
  if (with_splats) splat.assign(frame_channels(header), 0.0);
}

// A filter footprint may reach past the frame border: those pixels are not stored. A non-finite
// splat is counted (once per call) and dropped.
void SampleBuffer::add_splat(int x, int y, RGB weighted_radiance) {
  assert(!splat.empty() && "add_splat on a buffer without a splat plane");
  if (!is_finite(weighted_radiance)) {
    ++nonfinite_samples;
    return;
  }
  if (splat.empty() || x < 0 || y < 0 || x >= header.width || y >= header.height) return;
  size_t f = size_t(y) * size_t(header.width) + size_t(x);
  for (int c = 0; c < 3; ++c) splat[3 * f + c] += double(weighted_radiance[c]);
}

void SampleBuffer::finish_pass() {
  if (header.passes.count() != 1) {
    throw std::logic_error("finish_pass needs a buffer of exactly one pass, this one holds \"" +
                           header.passes.to_string() + "\"");
  }
  for (int y = rect.y0; y < rect.y1(); ++y) {
    for (int x = rect.x0; x < rect.x1(); ++x) {
      size_t i = pixel_index(x, y);
      RGBd e = estimate_at(*this, x, y);
      for (int c = 0; c < 3; ++c) {
        batch_sum[3 * i + c] = e[c];
        batch_sum_sq[3 * i + c] = e[c] * e[c];
      }
    }
  }
}

RGB SampleBuffer::estimate(int x, int y) const { return to_rgb(estimate_at(*this, x, y)); }

RGB SampleBuffer::variance_of_mean(int x, int y) const { return to_rgb(variance_at(*this, x, y)); }

double SampleBuffer::rel_mse() const {
  if (rect.area() == 0) return 0.0;
  double total = 0.0;
  for (int y = rect.y0; y < rect.y1(); ++y) {
    for (int x = rect.x0; x < rect.x1(); ++x) {
      RGBd m = estimate_at(*this, x, y), v = variance_at(*this, x, y);
      for (int c = 0; c < 3; ++c) total += v[c] / (m[c] * m[c] + 0.01);
    }
  }
  return total / (3.0 * double(rect.area()));
}

RGB SampleBuffer::mean_estimate() const {
  if (rect.area() == 0) return RGB(0.0f);
  RGBd total{};
  for (int y = rect.y0; y < rect.y1(); ++y) {
    for (int x = rect.x0; x < rect.x1(); ++x) {
      RGBd e = estimate_at(*this, x, y);
      for (int c = 0; c < 3; ++c) total[c] += e[c];
    }
  }
  for (double& t : total) t /= double(rect.area());
  return to_rgb(total);
}

uint64_t SampleBuffer::total_samples() const {
  uint64_t n = 0;
  for (uint64_t c : count) n += c;
  return n;
}

// ---------------------------------------------------------------------------------------------
// Merging

namespace {

// Which identity field (everything that changes pixels) differs, or "".
std::string identity_difference(const BufferHeader& a, const BufferHeader& b) {
  auto str = [](const char* field, const std::string& x, const std::string& y) {
    return std::string(field) + " differs: \"" + x + "\" vs \"" + y + "\"";
  };
  auto num = [](const char* field, auto x, auto y) {
    return std::string(field) + " differs: " + std::to_string(x) + " vs " + std::to_string(y);
  };
  if (a.scene_digest != b.scene_digest) return str("scene_digest", a.scene_digest, b.scene_digest);
  if (a.seed != b.seed) return num("seed", a.seed, b.seed);
  if (a.frame != b.frame) return num("frame", a.frame, b.frame);
  if (a.integrator != b.integrator) return str("integrator", a.integrator, b.integrator);
  if (a.settings != b.settings) return str("settings", a.settings, b.settings);
  if (a.width != b.width) return num("width", a.width, b.width);
  if (a.height != b.height) return num("height", a.height, b.height);
  return "";
}

std::set<std::string> split_ids(const std::string& id) {
  std::set<std::string> ids;
  if (id.rfind("mixed:", 0) != 0) {
    if (!id.empty()) ids.insert(id);
    return ids;
  }
  for (size_t pos = 6; pos <= id.size();) {
    size_t comma = std::min(id.find(',', pos), id.size());
    if (comma > pos) ids.insert(id.substr(pos, comma - pos));
    pos = comma + 1;
  }
  return ids;
}

// Build ids (and ISAs) combine as sets: one id when all agree, else "mixed:" + the sorted distinct
// ids joined by ','. Set union makes this exactly associative and commutative; an empty id (a
// fresh accumulator) adds nothing. Warns once each time a new id joins, since pixels from
// different builds or CPU kinds agree statistically, not bitwise (DESIGN.md).
std::string combine_ids(const std::string& dst, const std::string& src, const char* what) {
  std::set<std::string> a = split_ids(dst), all = a;
  for (const std::string& s : split_ids(src)) all.insert(s);
  if (all.empty()) return "";
  if (all.size() == 1) return *all.begin();
  std::string out = "mixed:";
  for (const std::string& s : all) out += (out.size() > 6 ? "," : "") + s;
  if (all != a && !a.empty()) {
    spdlog::warn(
        "merging sample buffers made by different {} (\"{}\" and \"{}\"): the result agrees "
        "statistically, not bitwise, with a render made by one",
        what, dst, src);
  }
  return out;
}

void add_plane(std::vector<double>& dst, const std::vector<double>& src) {
  for (size_t i = 0; i < dst.size(); ++i) dst[i] += src[i];
}

void combine_provenance(BufferHeader& dst, const BufferHeader& src) {
  dst.build_id = combine_ids(dst.build_id, src.build_id, "builds");
  dst.isa = combine_ids(dst.isa, src.isa, "CPU kinds");
  dst.core_seconds += src.core_seconds;
}

}  // namespace

std::string merge_incompatibility(const BufferHeader& a, const BufferHeader& b) {
  if (std::string why = identity_difference(a, b); !why.empty()) return why;
  if (a.passes.overlaps(b.passes)) {
    return "pass sets overlap: \"" + a.passes.to_string() + "\" and \"" + b.passes.to_string() +
           "\" share passes " + intersection(a.passes, b.passes).to_string();
  }
  return "";
}

void merge_into(SampleBuffer& dst, const SampleBuffer& src) {
  auto fail = [](const std::string& why) {
    return MergeError("cannot merge sample buffers: " + why);
  };
  if (std::string why = merge_incompatibility(dst.header, src.header); !why.empty())
    throw fail(why);
  if (dst.rect != src.rect) {
    throw fail("rect differs: " + rect_string(dst.rect) + " vs " + rect_string(src.rect));
  }
  if (dst.splat.empty() != src.splat.empty()) {
    throw fail("one buffer has a splat plane and the other has none");
  }
  if (!planes_match_rect(dst) || !planes_match_rect(src)) {
    throw fail("plane sizes do not match the rect " + rect_string(dst.rect));
  }
  for (size_t i = 0; i < dst.count.size(); ++i) dst.count[i] += src.count[i];
  add_plane(dst.sum, src.sum);
  add_plane(dst.sum_sq, src.sum_sq);
  add_plane(dst.batch_sum, src.batch_sum);
  add_plane(dst.batch_sum_sq, src.batch_sum_sq);
  add_plane(dst.splat, src.splat);
  dst.light_paths += src.light_paths;
  dst.nonfinite_samples += src.nonfinite_samples;
  dst.rays += src.rays;
  combine_provenance(dst.header, src.header);
  dst.header.passes.add(src.header.passes);
}

// Copies rows without arithmetic, so an assembled pass is bit-identical to a whole-frame render.
// Assembling the same tile twice overwrites its pixels but counts its rays and time twice.
void assemble_tile(SampleBuffer& dst, const SampleBuffer& tile) {
  auto fail = [](const std::string& why) { return MergeError("cannot assemble tile: " + why); };
  if (std::string why = identity_difference(dst.header, tile.header); !why.empty()) throw fail(why);
  if (dst.header.passes != tile.header.passes) {
    throw fail("passes differ: \"" + dst.header.passes.to_string() + "\" vs \"" +
               tile.header.passes.to_string() + "\"");
  }
  if (!dst.splat.empty() || !tile.splat.empty()) {
    throw fail("splatting buffers cover the whole frame; merge them instead");
  }
  if (tile.rect.w < 0 || tile.rect.h < 0 || !dst.rect.contains(tile.rect)) {
    throw fail("tile " + rect_string(tile.rect) + " is not inside " + rect_string(dst.rect));
  }
  if (!planes_match_rect(dst) || !planes_match_rect(tile)) {
    throw fail("plane sizes do not match the rect");
  }
  size_t w = size_t(tile.rect.w);
  for (int y = tile.rect.y0; y < tile.rect.y1(); ++y) {
    size_t s = tile.pixel_index(tile.rect.x0, y), d = dst.pixel_index(tile.rect.x0, y);
    std::copy_n(tile.count.begin() + s, w, dst.count.begin() + d);
    std::copy_n(tile.sum.begin() + 3 * s, 3 * w, dst.sum.begin() + 3 * d);
    std::copy_n(tile.sum_sq.begin() + 3 * s, 3 * w, dst.sum_sq.begin() + 3 * d);
    std::copy_n(tile.batch_sum.begin() + 3 * s, 3 * w, dst.batch_sum.begin() + 3 * d);
    std::copy_n(tile.batch_sum_sq.begin() + 3 * s, 3 * w, dst.batch_sum_sq.begin() + 3 * d);
  }
  dst.rays += tile.rays;
  dst.nonfinite_samples += tile.nonfinite_samples;
  combine_provenance(dst.header, tile.header);
}

// ---------------------------------------------------------------------------------------------
// The .rfb encoding

namespace {

using nlohmann::json;

constexpr char kMagic[8] = {'\x89', 'R', 'F', 'B', '\r', '\n', '\x1a', '\n'};
constexpr uint32_t kFormatVersion = 1;
constexpr size_t kPreambleBytes = 16;  // magic, version, header length
constexpr size_t kChecksumBytes = 32;
constexpr uint64_t kMaxDimension = 1 << 20;  // larger frames are refused as implausible

void put_u32(std::string& out, uint32_t v) {
  for (int b = 0; b < 4; ++b) out.push_back(char((v >> (8 * b)) & 0xff));
}

uint32_t get_u32(const std::string& in, size_t at) {
  uint32_t v = 0;
  for (int b = 0; b < 4; ++b) v |= uint32_t(uint8_t(in[at + b])) << (8 * b);
  return v;
}

template <class T>
void append_plane(std::string& out, const std::vector<T>& v) {
  static_assert(sizeof(T) == 8);
  size_t at = out.size();
  out.resize(at + 8 * v.size());
  if constexpr (std::endian::native == std::endian::little) {
    if (!v.empty()) std::memcpy(out.data() + at, v.data(), 8 * v.size());
  } else {
    for (size_t i = 0; i < v.size(); ++i) {
      uint64_t bits;
      std::memcpy(&bits, &v[i], 8);
      for (int b = 0; b < 8; ++b) out[at + 8 * i + b] = char((bits >> (8 * b)) & 0xff);
    }
  }
}

// Reads v.size() elements at `at`; the caller has checked the bytes are there.
template <class T>
void read_plane(const std::string& in, size_t& at, std::vector<T>& v) {
  static_assert(sizeof(T) == 8);
  if constexpr (std::endian::native == std::endian::little) {
    if (!v.empty()) std::memcpy(v.data(), in.data() + at, 8 * v.size());
  } else {
    for (size_t i = 0; i < v.size(); ++i) {
      uint64_t bits = 0;
      for (int b = 0; b < 8; ++b) bits |= uint64_t(uint8_t(in[at + 8 * i + b])) << (8 * b);
      std::memcpy(&v[i], &bits, 8);
    }
  }
  at += 8 * v.size();
}

// Planes in file order; the splat plane only when present.
template <class Buf, class F>
void for_each_plane(Buf& b, F&& f) {
  f(b.count);
  f(b.sum);
  f(b.sum_sq);
  f(b.batch_sum);
  f(b.batch_sum_sq);
  if (!b.splat.empty()) f(b.splat);
}

std::string sha256_raw(std::string_view bytes) {
  std::string hex = sha256_hex(bytes), raw(hex.size() / 2, '\0');
  auto nib = [](char c) { return c <= '9' ? c - '0' : c - 'a' + 10; };
  for (size_t i = 0; i < raw.size(); ++i) raw[i] = char(nib(hex[2 * i]) << 4 | nib(hex[2 * i + 1]));
  return raw;
}

json header_json(const SampleBuffer& b) {
  const BufferHeader& h = b.header;
  return json{{"format", "rayfarm-sample-buffer"},
              {"scene_digest", h.scene_digest},
              {"seed", h.seed},
              {"frame", h.frame},
              {"integrator", h.integrator},
              {"settings", h.settings},
              {"width", h.width},
              {"height", h.height},
              {"passes", h.passes.to_string()},
              {"build_id", h.build_id},
              {"isa", h.isa},
              {"core_seconds", h.core_seconds},
              {"rect", {{"x0", b.rect.x0}, {"y0", b.rect.y0}, {"w", b.rect.w}, {"h", b.rect.h}}},
              {"has_splats", !b.splat.empty()},
              {"light_paths", b.light_paths},
              {"nonfinite_samples", b.nonfinite_samples},
              {"rays", b.rays}};
}

// Typed access to header fields; errors name the file and the field.
struct HeaderReader {
  const json& j;
  const std::string& what;

  [[noreturn]] void bad(const char* key, const std::string& expected) const {
    throw BufferFileError(what + ": header field \"" + key + "\" is missing or not " + expected);
  }
  const json& get(const char* key) const {
    static const json kNull;
    auto it = j.find(key);
    return it == j.end() ? kNull : *it;
  }
  std::string str(const char* key) const {
    const json& v = get(key);
    if (!v.is_string()) bad(key, "a string");
    return v.get<std::string>();
  }
  uint64_t uint(const char* key, uint64_t max = std::numeric_limits<uint64_t>::max()) const {
    const json& v = get(key);
    if (!v.is_number_unsigned() || v.get<uint64_t>() > max) {
      bad(key, "an unsigned integer <= " + std::to_string(max));
    }
    return v.get<uint64_t>();
  }
  double number(const char* key) const {
    const json& v = get(key);
    if (!v.is_number()) bad(key, "a number");
    return v.get<double>();
  }
  bool boolean(const char* key) const {
    const json& v = get(key);
    if (!v.is_boolean()) bad(key, "true or false");
    return v.get<bool>();
  }
};

BufferHeader read_header(const HeaderReader& r) {
  BufferHeader h;
  h.scene_digest = r.str("scene_digest");
  h.seed = r.uint("seed");
  h.frame = uint32_t(r.uint("frame", std::numeric_limits<uint32_t>::max()));
  h.integrator = r.str("integrator");
  h.settings = r.str("settings");
  h.width = int(r.uint("width", kMaxDimension));
  h.height = int(r.uint("height", kMaxDimension));
  try {
    h.passes = PassSet::parse(r.str("passes"));
  } catch (const std::invalid_argument& e) {
    throw BufferFileError(r.what + ": header field \"passes\": " + e.what());
  }
  h.build_id = r.str("build_id");
  h.isa = r.str("isa");
  h.core_seconds = r.number("core_seconds");
  return h;
}

Rect read_rect(const HeaderReader& r, const BufferHeader& h) {
  const json& jr = r.get("rect");
  if (!jr.is_object()) r.bad("rect", "an object");
  HeaderReader rr{jr, r.what};
  Rect rect{int(rr.uint("x0", kMaxDimension)), int(rr.uint("y0", kMaxDimension)),
            int(rr.uint("w", kMaxDimension)), int(rr.uint("h", kMaxDimension))};
  if (!Rect{0, 0, h.width, h.height}.contains(rect)) {
    throw BufferFileError(r.what + ": rect " + rect_string(rect) + " is not inside the " +
                          std::to_string(h.width) + "x" + std::to_string(h.height) + " frame");
  }
  return rect;
}

// Checks everything before the JSON header is parsed; returns the header length.
size_t check_preamble(const std::string& bytes, const std::string& what) {
  auto fail = [&](const std::string& why) { return BufferFileError(what + ": " + why); };
  size_t n = bytes.size();
  if (std::memcmp(bytes.data(), kMagic, std::min<size_t>(n, 8)) != 0) {
    throw fail("not a rayfarm sample buffer (bad magic)");
  }
  if (n < kPreambleBytes + kChecksumBytes) {
    throw fail("truncated (" + std::to_string(n) + " bytes; the smallest buffer file has " +
               std::to_string(kPreambleBytes + kChecksumBytes) + ")");
  }
  uint32_t version = get_u32(bytes, 8);
  if (version != kFormatVersion) {
    throw fail("unsupported format version " + std::to_string(version) + " (this build reads " +
               std::to_string(kFormatVersion) + ")");
  }
  size_t header_len = get_u32(bytes, 12);
  if (header_len > n - kPreambleBytes - kChecksumBytes) {
    throw fail("header length " + std::to_string(header_len) +
               " runs past the end of the file (file is corrupt or truncated)");
  }
  std::string_view body(bytes.data(), n - kChecksumBytes);
  if (sha256_raw(body) != std::string_view(bytes).substr(n - kChecksumBytes)) {
    throw fail("checksum mismatch (file is corrupt or truncated)");
  }
  return header_len;
}

}  // namespace

std::string encode_buffer(const SampleBuffer& buf) {
  if (!planes_match_rect(buf)) {
    throw std::invalid_argument("encode_buffer: plane sizes do not match the rect " +
                                rect_string(buf.rect));
  }
  std::string header = header_json(buf).dump();
  header.append((8 - (kPreambleBytes + header.size()) % 8) % 8, ' ');
  size_t plane_bytes = 8 * (13 * buf.count.size() + buf.splat.size());
  std::string out;
  out.reserve(kPreambleBytes + header.size() + plane_bytes + kChecksumBytes);
  out.append(kMagic, sizeof kMagic);
  put_u32(out, kFormatVersion);
  put_u32(out, uint32_t(header.size()));
  out += header;
  for_each_plane(buf, [&](const auto& plane) { append_plane(out, plane); });
  out += sha256_raw(out);
  return out;
}

SampleBuffer decode_buffer(const std::string& bytes, const std::string& what_for_errors) {
  const std::string& what = what_for_errors;
  size_t header_len = check_preamble(bytes, what);
  json j = json::parse(bytes.begin() + kPreambleBytes,
                       bytes.begin() + std::ptrdiff_t(kPreambleBytes + header_len), nullptr,
                       /*allow_exceptions=*/false);
  if (!j.is_object()) throw BufferFileError(what + ": header is not a JSON object");
  HeaderReader r{j, what};
  BufferHeader h = read_header(r);
  Rect rect = read_rect(r, h);
  bool has_splats = r.boolean("has_splats");

  // Sizes are bounded by kMaxDimension, so these products cannot overflow.
  uint64_t expected = 8 * (13 * uint64_t(rect.area()) +
                           (has_splats ? 3 * uint64_t(h.width) * uint64_t(h.height) : 0));
  uint64_t actual = bytes.size() - kPreambleBytes - header_len - kChecksumBytes;
  if (expected != actual) {
    throw BufferFileError(what + ": header describes " + std::to_string(expected) +
                          " bytes of planes (rect " + rect_string(rect) +
                          (has_splats ? ", with splats" : "") + ") but the file holds " +
                          std::to_string(actual));
  }
  SampleBuffer buf(std::move(h), rect, has_splats);
  buf.light_paths = r.uint("light_paths");
  buf.nonfinite_samples = r.uint("nonfinite_samples");
  buf.rays = r.uint("rays");
  size_t at = kPreambleBytes + header_len;
  for_each_plane(buf, [&](auto& plane) { read_plane(bytes, at, plane); });
  return buf;
}

void write_buffer_file(const std::string& path, const SampleBuffer& buf) {
  std::string bytes = encode_buffer(buf);
  try {
    write_file_atomic(path, bytes);
  } catch (const std::runtime_error& e) {
    throw BufferFileError(e.what());  // already names the path
  }
}

SampleBuffer read_buffer_file(const std::string& path) {
  std::string bytes;
  try {
    bytes = read_file_bytes(path);
  } catch (const std::runtime_error& e) {
    throw BufferFileError(e.what());  // already names the path
  }
  return decode_buffer(bytes, path);
}

}  // namespace rf
