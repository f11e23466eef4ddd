// Sample buffers (DESIGN.md "Sample buffers and variance"): what a task returns for its rect and
// passes, the on-disk partial-result format, and the frame accumulator, all one type. Merging is
// the one implementation shared by the local renderer, the coordinator and `rayfarm merge`.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "engine/math.h"

namespace rf {

struct Rect {
  int x0 = 0, y0 = 0, w = 0, h = 0;
  int x1() const { return x0 + w; }
  int y1() const { return y0 + h; }
  int64_t area() const { return int64_t(w) * h; }
  bool contains(const Rect& r) const {
    return r.x0 >= x0 && r.y0 >= y0 && r.x1() <= x1() && r.y1() <= y1();
  }
  bool operator==(const Rect&) const = default;
};

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

// What identifies the image a buffer belongs to. Buffers merge only when every field but
// `passes`, `build_id`, `isa` and `core_seconds` is equal.
struct BufferHeader {
  std::string scene_digest;   // SHA-256 hex of the scene bundle
  uint64_t seed = 0;
  uint32_t frame = 0;
  std::string integrator;     // e.g. "path"
  std::string settings;       // canonical text of the other settings that change pixels
                              // (max depth, spp per pass, filter, ...)
  int width = 0, height = 0;  // full frame resolution
  PassSet passes;
  std::string build_id;
  std::string isa;            // Embree's ISA / CPU kind that made it
  double core_seconds = 0;    // summed over all merged buffers
  bool operator==(const BufferHeader&) const = default;
};

struct MergeError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct BufferFileError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

struct SampleBuffer {
  BufferHeader header;
  Rect rect;  // the pixels of the camera plane and batch plane, within the frame

  // Camera plane, per pixel of rect (row-major); RGB sums in double from the first sample on.
  std::vector<uint64_t> count;
  std::vector<double> sum;     // 3 per pixel: sum of filter-weighted radiance
  std::vector<double> sum_sq;  // 3 per pixel: sum of squared radiance

  // Batch-means plane, per pixel of rect: sums over passes of each pass's pixel estimate and of
  // its square. Filled by finish_pass() on a one-pass buffer, then added up by merges.
  std::vector<double> batch_sum;     // 3 per pixel
  std::vector<double> batch_sum_sq;  // 3 per pixel

  // Splat plane (splatting integrators only; whole frame, width*height*3, empty otherwise) and
  // the number of light paths it was made from.
  std::vector<double> splat;
  uint64_t light_paths = 0;

  // Diagnostics that travel with the buffer.
  uint64_t nonfinite_samples = 0;  // NaN/Inf samples counted and dropped (contributed zero)
  uint64_t rays = 0;               // rays traced to make this buffer

  SampleBuffer() = default;
  SampleBuffer(BufferHeader h, Rect r, bool with_splats);

  size_t pixel_index(int x, int y) const {  // x, y in frame coordinates
    return size_t(y - rect.y0) * size_t(rect.w) + size_t(x - rect.x0);
  }
  // Adds one camera sample (radiance times filter weight) to pixel (x, y), frame coordinates.
  // A non-finite sample is counted as a sample with zero radiance and tallied in nonfinite_samples.
  void add_sample(int x, int y, RGB weighted_radiance) {
    add_sample(x, y, weighted_radiance, nonfinite_samples);
  }
  // The same, tallying non-finite samples in a caller's counter (threads filling disjoint
  // pixels of one buffer each keep their own and add them up after).
  void add_sample(int x, int y, RGB weighted_radiance, uint64_t& nonfinite) {
    size_t i = pixel_index(x, y);
    ++count[i];
    if (!is_finite(weighted_radiance)) {
      ++nonfinite;
      return;
    }
    for (int c = 0; c < 3; ++c) {
      double v = weighted_radiance[c];
      sum[3 * i + c] += v;
      sum_sq[3 * i + c] += v * v;
    }
  }
  // Adds a splat at frame pixel (x, y) (the caller applies the filter weight).
  void add_splat(int x, int y, RGB weighted_radiance);

  // On a buffer holding exactly one pass: sets the batch plane to that pass's pixel estimate
  // (camera mean plus splats / light paths) and its square.
  void finish_pass();

  // Per-pixel estimate (camera mean + splat / light paths), RGB, for frame pixel (x, y).
  RGB estimate(int x, int y) const;
  // Variance of the mean at (x, y) from batch means across passes (needs >= 2 passes; else 0).
  RGB variance_of_mean(int x, int y) const;
  // relMSE = mean over pixels and RGB of Var / (mean^2 + 0.01) (pbrt-v4's convention), with the
  // batch-means variance of the mean. 0 when fewer than 2 passes.
  double rel_mse() const;
  // Mean over the rect's pixels per channel of estimate().
  RGB mean_estimate() const;
  uint64_t total_samples() const;  // sum of count over the rect
};

// Why two headers cannot be merged, or "" when they can (everything but passes, build id, ISA
// and core-seconds equal; pass sets disjoint).
std::string merge_incompatibility(const BufferHeader& a, const BufferHeader& b);

// dst += src: same rect, compatible headers, disjoint passes. Throws MergeError saying which
// field differs or which passes overlap. Associative and commutative up to summation order.
void merge_into(SampleBuffer& dst, const SampleBuffer& src);

// Copies a tile's buffer into a larger buffer of the same pass set (assembling one pass of a
// frame from its tiles). Throws MergeError if the tile is outside dst.rect or headers differ.
void assemble_tile(SampleBuffer& dst, const SampleBuffer& tile);

// The partial-result file (.rfb): magic, version, header, planes, checksum. Written atomically
// (temporary file, fsync, rename); reading verifies the checksum and every size, and throws
// BufferFileError naming the file and what is wrong.
void write_buffer_file(const std::string& path, const SampleBuffer& buf);
SampleBuffer read_buffer_file(const std::string& path);

// The same encoding in memory (for the wire and for checkpoints).
std::string encode_buffer(const SampleBuffer& buf);
SampleBuffer decode_buffer(const std::string& bytes, const std::string& what_for_errors);

}  // namespace rf
