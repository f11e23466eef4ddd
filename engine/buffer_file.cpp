// .rfb format, version 3 (docs/sample-buffer-format.md). All integers and floats little-endian.
// Version 3 replaced the SHA-256 at the end with XXH3-128 (16 bytes), which a coordinator checks
// at memory speed; version 2 added the AOV plane and the "aovs" header key. Versions 1 and 2
// (SHA-256, 32 bytes) are still read.
//
//   offset  size     content
//   0       8        magic 89 52 46 42 0D 0A 1A 0A ("\x89RFB\r\n\x1a\n"; PNG-style, so 7-bit
//                    transfers and line-ending conversion are caught at the first bytes)
//   8       4        u32 format version = 3 (1 and 2 are read too)
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
//   end-16  16       XXH3-128 of every byte before it, canonical (big-endian) byte order, as
//                    xxh128sum prints it (versions 1 and 2: end-32, 32 bytes of SHA-256)
//
// Header keys: format ("rayfarm-sample-buffer"), scene_digest, seed, frame, integrator, settings,
// width, height, aovs (version 2: engine/aov.h's canonical list, "" for none), passes
// (PassSet::to_string), build_id, isa, core_seconds, rect {x0, y0, w, h}, has_splats, light_paths,
// nonfinite_samples, rays. Unknown keys are ignored, so a later version may add keys without
// breaking this reader.
//
// Reading checks, in this order: magic, version, header length against the file size, the
// checksum, every header field's type and range, the rect inside the frame, and that the plane
// bytes are exactly what the rect and flags say. Nothing is allocated or read before the sizes
// agree, so a truncated or lying file costs an exception, never an out-of-bounds read.
#include "engine/buffer_file.h"

#include <fcntl.h>
#include <malloc.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <cstring>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <string_view>

#include "engine/digest.h"

#define XXH_INLINE_ALL  // header-only: inlined, and no library for the runtime image
#include <xxhash.h>

namespace rf {

namespace {

using nlohmann::json;

constexpr char kMagic[8] = {'\x89', 'R', 'F', 'B', '\r', '\n', '\x1a', '\n'};
constexpr uint32_t kFormatVersion = 3;
constexpr uint32_t kOldestReadableVersion = 1;
constexpr size_t kPreambleBytes = 16;  // magic, version, header length
constexpr size_t kChecksumBytes = 16;  // XXH3-128 (version 3)
constexpr size_t kSha256Bytes = 32;    // versions 1 and 2

size_t checksum_bytes(uint32_t version) { return version >= 3 ? kChecksumBytes : kSha256Bytes; }

std::string xxh3_raw(std::string_view bytes) {
  XXH128_canonical_t c;
  XXH128_canonicalFromHash(&c, XXH3_128bits(bytes.data(), bytes.size()));
  return std::string(reinterpret_cast<const char*>(c.digest), sizeof c.digest);
}
constexpr uint64_t kMaxDimension = 1 << 20;  // larger frames are refused as implausible

void put_u32(std::string& out, uint32_t v) {
  for (int b = 0; b < 4; ++b) out.push_back(char((v >> (8 * b)) & 0xff));
}

uint32_t get_u32(std::string_view in, size_t at) {
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

std::string raw_of_hex(const std::string& hex) {
  std::string raw(hex.size() / 2, '\0');
  auto nib = [](char c) { return c <= '9' ? c - '0' : c - 'a' + 10; };
  for (size_t i = 0; i < raw.size(); ++i) raw[i] = char(nib(hex[2 * i]) << 4 | nib(hex[2 * i + 1]));
  return raw;
}

std::string sha256_raw(std::string_view bytes) { return raw_of_hex(sha256_hex(bytes)); }

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

// Checks the preamble of a buffer of n bytes whose first bytes are `head` (at least 16 of them
// when n allows): magic, size, version, header length. Returns the header length and sets the
// format version.
size_t check_preamble(std::string_view head, uint64_t n, const std::string& what,
                      uint32_t& version) {
  auto fail = [&](const std::string& why) { return BufferFileError(what + ": " + why); };
  if (std::memcmp(head.data(), kMagic, size_t(std::min<uint64_t>(n, 8))) != 0) {
    throw fail("not a rayfarm sample buffer (bad magic)");
  }
  auto truncated = [&](size_t smallest) {
    return fail("truncated (" + std::to_string(n) + " bytes; the smallest buffer file has " +
                std::to_string(smallest) + ")");
  };
  if (n < kPreambleBytes + kChecksumBytes) throw truncated(kPreambleBytes + kChecksumBytes);
  version = get_u32(head, 8);
  if (version < kOldestReadableVersion || version > kFormatVersion) {
    throw fail("unsupported format version " + std::to_string(version) + " (this build reads " +
               std::to_string(kOldestReadableVersion) + " to " + std::to_string(kFormatVersion) + ")");
  }
  const size_t sum_bytes = checksum_bytes(version);
  if (n < kPreambleBytes + sum_bytes) throw truncated(kPreambleBytes + sum_bytes);
  size_t header_len = get_u32(head, 12);
  if (header_len > n - kPreambleBytes - sum_bytes) {
    throw fail("header length " + std::to_string(header_len) +
               " runs past the end of the file (file is corrupt or truncated)");
  }
  return header_len;
}

[[noreturn]] void checksum_mismatch(const std::string& what) {
  throw BufferFileError(what + ": checksum mismatch (file is corrupt or truncated)");
}

// What decoding learns before reading the planes: everything checked, sizes matched.
struct Parsed {
  BufferHeader header;
  Rect rect;
  bool has_splats = false;
  uint64_t light_paths = 0, nonfinite_samples = 0, rays = 0;
  size_t planes_at = 0;
};

// The JSON header of a buffer of n bytes, checked against the sizes.
Parsed parse_header(std::string_view header_bytes, uint32_t version, uint64_t n,
                    const std::string& what) {
  const size_t header_len = header_bytes.size();
  json j = json::parse(header_bytes.begin(), header_bytes.end(), nullptr,
                       /*allow_exceptions=*/false);
  if (!j.is_object()) throw BufferFileError(what + ": header is not a JSON object");
  HeaderReader r{j, what};
  Parsed p;
  p.header = read_header(r, version);
  const BufferHeader& h = p.header;
  p.rect = read_rect(r, h);
  p.has_splats = r.boolean("has_splats");

  // Sizes are bounded by kMaxDimension, so these products cannot overflow.
  uint64_t expected = 8 * ((13 + uint64_t(h.aovs.channels())) * uint64_t(p.rect.area()) +
                           (p.has_splats ? 3 * uint64_t(h.width) * uint64_t(h.height) : 0));
  uint64_t actual = n - kPreambleBytes - header_len - checksum_bytes(version);
  if (expected != actual) {
    throw BufferFileError(what + ": header describes " + std::to_string(expected) +
                          " bytes of planes (rect " + to_string(p.rect) +
                          (p.has_splats ? ", with splats" : "") +
                          (h.aovs.any() ? ", AOVs " + to_string(h.aovs) : "") +
                          ") but the file holds " + std::to_string(actual));
  }
  p.light_paths = r.uint("light_paths");
  p.nonfinite_samples = r.uint("nonfinite_samples");
  p.rays = r.uint("rays");
  p.planes_at = kPreambleBytes + header_len;
  return p;
}

Parsed parse(std::string_view bytes, const std::string& what) {
  uint32_t version = 0;
  size_t header_len = check_preamble(bytes, bytes.size(), what, version);
  const size_t sum_bytes = checksum_bytes(version);
  std::string_view body = bytes.substr(0, bytes.size() - sum_bytes);
  std::string expected = version >= 3 ? xxh3_raw(body) : sha256_raw(body);
  if (expected != bytes.substr(bytes.size() - sum_bytes)) checksum_mismatch(what);
  return parse_header(bytes.substr(kPreambleBytes, header_len), version, bytes.size(), what);
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
  out += xxh3_raw(out);
  return out;
}

SampleBuffer decode_buffer(const std::string& bytes, const std::string& what_for_errors) {
  Parsed p = parse(bytes, what_for_errors);
  SampleBuffer buf(std::move(p.header), p.rect, p.has_splats);
  buf.light_paths = p.light_paths;
  buf.nonfinite_samples = p.nonfinite_samples;
  buf.rays = p.rays;
  size_t at = p.planes_at;
  for_each_plane(buf, [&](auto& plane) { read_plane(bytes, at, plane); });
  return buf;
}

EncodedBuffer::EncodedBuffer(std::string bytes, const std::string& what_for_errors) {
  static_assert(std::endian::native == std::endian::little,
                "EncodedBuffer reads the little-endian planes in place");
  Parsed p = parse(bytes, what_for_errors);
  bytes_ = std::move(bytes);
  header_ = std::move(p.header);
  rect_ = p.rect;
  has_splats_ = p.has_splats;
  light_paths_ = p.light_paths;
  nonfinite_samples_ = p.nonfinite_samples;
  rays_ = p.rays;
  planes_at_ = p.planes_at;
}

BufferView EncodedBuffer::view() const {
  BufferView v;
  v.header = &header_;
  v.rect = rect_;
  v.light_paths = light_paths_;
  v.nonfinite_samples = nonfinite_samples_;
  v.rays = rays_;
  if (bytes_.empty()) return v;  // default-constructed: no planes
  // The format puts the planes 8-byte aligned after the header, and the string's storage is
  // aligned for any scalar: the doubles are read where they lie.
  const char* at = bytes_.data() + planes_at_;
  const size_t a = size_t(rect_.area());
  v.count = {reinterpret_cast<const uint64_t*>(at), a};
  at += 8 * a;
  auto next = [&](size_t n) {
    std::span<const double> s(reinterpret_cast<const double*>(at), n);
    at += 8 * n;
    return s;
  };
  v.sum = next(3 * a);
  v.sum_sq = next(3 * a);
  v.batch_sum = next(3 * a);
  v.batch_sum_sq = next(3 * a);
  v.aov = next(size_t(header_.aovs.channels()) * a);
  if (has_splats_) v.splat = next(3 * size_t(header_.width) * size_t(header_.height));
  return v;
}

void write_buffer_file(const std::string& path, const SampleBuffer& buf) {
  std::string bytes = encode_buffer(buf);
  try {
    write_file_atomic(path, bytes);
  } catch (const std::runtime_error& e) {
    throw BufferFileError(e.what());  // already names the path
  }
}

void write_buffer_file(const std::string& path, const FrameBands& frame) {
  const SampleBuffer& info = frame.info();
  if (frame.band_height() >= info.rect.h) {  // one band: the buffer itself
    write_buffer_file(path, frame.band(info.rect.y0));
    return;
  }
  // Band by band: each band's rows of each plane written where they lie in the file (a plane is
  // row-major over the whole rect), then the checksum over the file as written.
  if (!info.splat.empty() || info.light_paths)
    throw std::invalid_argument("write_buffer_file: a splatting frame comes in one band");
  std::string head(kMagic, sizeof kMagic);
  std::string header = header_json(info).dump();
  header.append((8 - (kPreambleBytes + header.size()) % 8) % 8, ' ');
  put_u32(head, kFormatVersion);
  put_u32(head, uint32_t(header.size()));
  head += header;
  const uint64_t area = uint64_t(info.rect.area());
  const uint64_t na = uint64_t(info.header.aovs.channels());
  const uint64_t per_pixel[7] = {1, 3, 3, 3, 3, na, 0};  // per pixel, in file order
  auto put = [&](int fd, const void* p, size_t n, uint64_t at) {
    if (!pwrite_full(fd, p, n, at))
      throw BufferFileError(path + ": write failed: " + std::strerror(errno));
  };
  try {
    write_file_atomic(path, [&](int fd) {
      put(fd, head.data(), head.size(), 0);
      for (int y0 = info.rect.y0; y0 < info.rect.y1(); y0 += frame.band_height()) {
        const SampleBuffer& band = frame.band(y0);
        if (band.rect.x0 != info.rect.x0 || band.rect.w != info.rect.w || band.rect.y0 != y0 ||
            !band.planes_match_rect())
          throw std::invalid_argument("write_buffer_file: a band is not the frame's rows");
        const uint64_t first = uint64_t(y0 - info.rect.y0) * uint64_t(info.rect.w);
        uint64_t plane_at = head.size();
        int p = 0;
        for_each_plane(band, [&](const auto& plane) {
          put(fd, plane.data(), 8 * plane.size(), plane_at + 8 * per_pixel[p] * first);
          plane_at += 8 * per_pixel[p] * area;
          ++p;
        });
      }
      // The checksum of everything before it, read back in 8 MiB pieces.
      XXH3_state_t* state = XXH3_createState();
      if (!state) throw std::bad_alloc();
      std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> owner(state, XXH3_freeState);
      XXH3_128bits_reset(state);
      const uint64_t end = head.size() + 8 * area * (13 + na);
      std::string piece(size_t(8) << 20, '\0');
      for (uint64_t at = 0; at < end;) {
        size_t n = size_t(std::min<uint64_t>(piece.size(), end - at));
        ssize_t r = ::pread(fd, piece.data(), n, off_t(at));
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) throw BufferFileError(path + ": cannot read back: " + std::strerror(errno));
        XXH3_128bits_update(state, piece.data(), size_t(r));
        at += uint64_t(r);
      }
      XXH128_canonical_t c;
      XXH128_canonicalFromHash(&c, XXH3_128bits_digest(state));
      put(fd, &c, sizeof c, end);
    });
  } catch (const std::runtime_error& e) {
    if (dynamic_cast<const BufferFileError*>(&e)) throw;
    throw BufferFileError(e.what());  // already names the path
  }
}

namespace {

void pread_all(int fd, void* p, size_t n, uint64_t at, const std::string& path) {
  if (!pread_full(fd, p, n, at))
    throw BufferFileError(
        path + ": cannot read: " +
        (errno == EIO ? std::string("file shrank while read") : std::strerror(errno)));
}

}  // namespace

BufferFileBands::BufferFileBands(const std::string& path, uint64_t band_bytes) : path_(path) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw BufferFileError(path + ": cannot open: " + std::strerror(errno));
  try {
    struct stat st {};
    if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode))
      throw BufferFileError(path + ": not a regular file");
    const uint64_t n = uint64_t(st.st_size);
    std::string head(size_t(std::min<uint64_t>(n, kPreambleBytes)), '\0');
    pread_all(fd_, head.data(), head.size(), 0, path);
    uint32_t version = 0;
    const size_t header_len = check_preamble(head, n, path, version);
    const size_t sum_bytes = checksum_bytes(version);
    std::string header(header_len, '\0');
    pread_all(fd_, header.data(), header_len, kPreambleBytes, path);
    // The checksum over everything before it (and the count plane summed on the way), before
    // the header is believed.
    const uint64_t body = n - sum_bytes;
    const uint64_t count_at = kPreambleBytes + header_len;
    std::unique_ptr<XXH3_state_t, decltype(&XXH3_freeState)> state(XXH3_createState(),
                                                                   XXH3_freeState);
    if (!state) throw std::bad_alloc();
    XXH3_128bits_reset(state.get());
    std::string piece(size_t(8) << 20, '\0');
    Sha256 sha;              // versions 1 and 2
    uint64_t count_end = 0;  // set once the header is parsed; the sum is taken after
    for (uint64_t at = 0; at < body;) {
      size_t len = size_t(std::min<uint64_t>(piece.size(), body - at));
      pread_all(fd_, piece.data(), len, at, path);
      if (version >= 3)
        XXH3_128bits_update(state.get(), piece.data(), len);
      else
        sha.update(std::string_view(piece.data(), len));
      at += len;
    }
    std::string stored(sum_bytes, '\0');
    pread_all(fd_, stored.data(), sum_bytes, body, path);
    std::string expected;
    if (version >= 3) {
      XXH128_canonical_t c;
      XXH128_canonicalFromHash(&c, XXH3_128bits_digest(state.get()));
      expected.assign(reinterpret_cast<const char*>(c.digest), sizeof c.digest);
    } else {
      expected = raw_of_hex(sha.hex_digest());
    }
    if (expected != stored) checksum_mismatch(path);
    Parsed p = parse_header(header, version, n, path);
    planes_at_ = p.planes_at;
    const uint64_t area = uint64_t(p.rect.area());
    count_end = count_at + 8 * area;
    if (p.has_splats) {  // the splat plane is the whole frame's: read whole
      info_ = read_buffer_file(path);
      band_height_ = std::max(info_.rect.h, 1);
      total_samples_ = info_.total_samples();
      band_ = info_;
    } else {
      info_.header = std::move(p.header);
      info_.rect = p.rect;
      info_.light_paths = p.light_paths;
      info_.nonfinite_samples = p.nonfinite_samples;
      info_.rays = p.rays;
      const uint64_t row = uint64_t(p.rect.w) * 8 * (13 + uint64_t(info_.header.aovs.channels()));
      band_height_ = int(std::clamp<uint64_t>(band_bytes / std::max<uint64_t>(row, 1), 1,
                                              uint64_t(std::max(p.rect.h, 1))));
      // Samples: the count plane, read again in pieces (it is the first plane).
      for (uint64_t at = count_at; at < count_end;) {
        size_t len = size_t(std::min<uint64_t>(piece.size(), count_end - at));
        pread_all(fd_, piece.data(), len, at, path);
        for (size_t i = 0; i + 8 <= len; i += 8) {
          uint64_t v;
          std::memcpy(&v, piece.data() + i, 8);
          total_samples_ += v;
        }
        at += len;
      }
    }
  } catch (...) {
    ::close(fd_);
    throw;
  }
}

BufferFileBands::~BufferFileBands() { ::close(fd_); }

const SampleBuffer& BufferFileBands::band(int y0) const {
  if (!info_.splat.empty() || band_height_ >= info_.rect.h) {
    if (band_.count.empty() && info_.rect.area() > 0) band_ = read_buffer_file(path_);
    return band_;
  }
  const Rect& r = info_.rect;
  const int h = std::min(band_height_, r.y1() - y0);
  const Rect rows{r.x0, y0, r.w, h};
  if (!(band_.rect == rows)) band_ = SampleBuffer(info_.header, rows, false);
  band_.header = info_.header;
  band_.light_paths = info_.light_paths;
  band_.nonfinite_samples = info_.nonfinite_samples;
  band_.rays = info_.rays;
  const uint64_t area = uint64_t(r.area()), first = uint64_t(y0 - r.y0) * uint64_t(r.w);
  const uint64_t n = uint64_t(rows.area());
  uint64_t plane_at = planes_at_;
  auto plane = [&](void* dst, uint64_t k) {  // k values per pixel
    pread_all(fd_, dst, size_t(8 * k * n), plane_at + 8 * k * first, path_);
    plane_at += 8 * k * area;
  };
  plane(band_.count.data(), 1);
  plane(band_.sum.data(), 3);
  plane(band_.sum_sq.data(), 3);
  plane(band_.batch_sum.data(), 3);
  plane(band_.batch_sum_sq.data(), 3);
  if (!band_.aov.empty()) plane(band_.aov.data(), uint64_t(info_.header.aovs.channels()));
  return band_;
}

double BufferFileBands::rel_mse() const {
  if (!rel_mse_) rel_mse_ = rel_mse_of_bands(*this);
  return *rel_mse_;
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

void keep_heap_for_sample_buffers() {
  ::mallopt(M_MMAP_THRESHOLD, 32 << 20);
  ::mallopt(M_TRIM_THRESHOLD, 128 << 20);
}

}  // namespace rf
