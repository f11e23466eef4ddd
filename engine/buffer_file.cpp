// .rfb format, version 2 (docs/sample-buffer-format.md). All integers and floats little-endian.
// Version 2 added the AOV plane and the "aovs" header key; version 1 files (no AOVs) are still
// read.
//
//   offset  size     content
//   0       8        magic 89 52 46 42 0D 0A 1A 0A ("\x89RFB\r\n\x1a\n"; PNG-style, so 7-bit
//                    transfers and line-ending conversion are caught at the first bytes)
//   8       4        u32 format version = 2 (1 is read too)
//   12      4        u32 header length L
//   16      L        header: UTF-8 JSON object, padded with trailing spaces so that 16 + L is a
//                    multiple of 8 (the planes are then 8-byte aligned in the file)
//   16+L    ...      planes, row-major over rect, A = rect.w * rect.h pixels, RGB interleaved:
//                      count        u64 x A
//                      sum          f64 x 3A
//                      sum_sq       f64 x 3A
//                      batch_sum    f64 x 3A
//                      batch_sum_sq f64 x 3A
//                      aov          f64 x C * A   (C = channels of the "aovs" set, engine/aov.h)
//                      splat        f64 x 3 * width * height   (only when has_splats)
//   end-32  32       SHA-256 of every byte before it
//
// Header keys: format ("rayfarm-sample-buffer"), scene_digest, seed, frame, integrator, settings,
// width, height, aovs (version 2: engine/aov.h's canonical list, "" for none), passes (PassSet::to_string), build_id, isa, core_seconds, rect {x0, y0, w, h},
// has_splats, light_paths, nonfinite_samples, rays. Unknown keys are ignored, so a later version
// may add keys without breaking this reader.
//
// Reading checks, in this order: magic, version, header length against the file size, the
// checksum, every header field's type and range, the rect inside the frame, and that the plane
// bytes are exactly what the rect and flags say. Nothing is allocated or read before the sizes
// agree, so a truncated or lying file costs an exception, never an out-of-bounds read.
#include "engine/buffer_file.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <string_view>

#include "engine/digest.h"

namespace rf {

namespace {

using nlohmann::json;

constexpr char kMagic[8] = {'\x89', 'R', 'F', 'B', '\r', '\n', '\x1a', '\n'};
constexpr uint32_t kFormatVersion = 2;
constexpr uint32_t kOldestReadableVersion = 1;
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
  f(b.aov);  // empty without AOVs (always in version 1)
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
              {"aovs", to_string(h.aovs)},
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
  int64_t integer(const char* key, int64_t min, int64_t max) const {
    const json& v = get(key);
    if (!v.is_number_integer() || (v.is_number_unsigned() && v.get<uint64_t>() > uint64_t(max)) ||
        (!v.is_number_unsigned() && (v.get<int64_t>() < min || v.get<int64_t>() > max)))
      bad(key, "an integer from " + std::to_string(min) + " to " + std::to_string(max));
    return v.get<int64_t>();
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

BufferHeader read_header(const HeaderReader& r, uint32_t version) {
  BufferHeader h;
  h.scene_digest = r.str("scene_digest");
  h.seed = r.uint("seed");
  h.frame = FrameNumber(r.integer("frame", std::numeric_limits<FrameNumber>::min(),
                                  std::numeric_limits<FrameNumber>::max()));
  h.integrator = r.str("integrator");
  h.settings = r.str("settings");
  h.width = int(r.uint("width", kMaxDimension));
  h.height = int(r.uint("height", kMaxDimension));
  if (version >= 2) {
    try {
      h.aovs = parse_aovs(r.str("aovs"));
    } catch (const std::invalid_argument& e) {
      throw BufferFileError(r.what + ": header field \"aovs\": " + e.what());
    }
  }
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
    throw BufferFileError(r.what + ": rect " + to_string(rect) + " is not inside the " +
                          std::to_string(h.width) + "x" + std::to_string(h.height) + " frame");
  }
  return rect;
}

// Checks everything before the JSON header is parsed; returns the header length and sets the
// format version.
size_t check_preamble(const std::string& bytes, const std::string& what, uint32_t& version) {
  auto fail = [&](const std::string& why) { return BufferFileError(what + ": " + why); };
  size_t n = bytes.size();
  if (std::memcmp(bytes.data(), kMagic, std::min<size_t>(n, 8)) != 0) {
    throw fail("not a rayfarm sample buffer (bad magic)");
  }
  if (n < kPreambleBytes + kChecksumBytes) {
    throw fail("truncated (" + std::to_string(n) + " bytes; the smallest buffer file has " +
               std::to_string(kPreambleBytes + kChecksumBytes) + ")");
  }
  version = get_u32(bytes, 8);
  if (version < kOldestReadableVersion || version > kFormatVersion) {
    throw fail("unsupported format version " + std::to_string(version) + " (this build reads " +
               std::to_string(kOldestReadableVersion) + " to " + std::to_string(kFormatVersion) + ")");
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
  if (!buf.planes_match_rect()) {
    throw std::invalid_argument("encode_buffer: plane sizes do not match the rect " +
                                to_string(buf.rect));
  }
  std::string header = header_json(buf).dump();
  header.append((8 - (kPreambleBytes + header.size()) % 8) % 8, ' ');
  size_t plane_bytes = 8 * (13 * buf.count.size() + buf.aov.size() + buf.splat.size());
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
  uint32_t version = 0;
  size_t header_len = check_preamble(bytes, what, version);
  json j = json::parse(bytes.begin() + kPreambleBytes,
                       bytes.begin() + std::ptrdiff_t(kPreambleBytes + header_len), nullptr,
                       /*allow_exceptions=*/false);
  if (!j.is_object()) throw BufferFileError(what + ": header is not a JSON object");
  HeaderReader r{j, what};
  BufferHeader h = read_header(r, version);
  Rect rect = read_rect(r, h);
  bool has_splats = r.boolean("has_splats");

  // Sizes are bounded by kMaxDimension, so these products cannot overflow.
  uint64_t expected = 8 * ((13 + uint64_t(h.aovs.channels())) * uint64_t(rect.area()) +
                           (has_splats ? 3 * uint64_t(h.width) * uint64_t(h.height) : 0));
  uint64_t actual = bytes.size() - kPreambleBytes - header_len - kChecksumBytes;
  if (expected != actual) {
    throw BufferFileError(what + ": header describes " + std::to_string(expected) +
                          " bytes of planes (rect " + to_string(rect) +
                          (has_splats ? ", with splats" : "") +
                          (h.aovs.any() ? ", AOVs " + to_string(h.aovs) : "") + ") but the file holds " +
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
