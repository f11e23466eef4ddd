// Sample buffers (DESIGN.md "Sample buffers and variance"): what a task returns for its rect and
// pass, and what a frame accumulates. Per pixel: sample count, sums and squared sums of radiance
// (camera plane), each pass's estimate summed and squared (batch-means plane); per frame, the
// splat plane of light-path contributions and its light-path count. Merging is in
// buffer_merge.h, the .rfb encoding in buffer_file.h.
#pragma once

#include <algorithm>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "engine/aov.h"
#include "engine/frame.h"
#include "engine/math.h"
#include "engine/pass_set.h"

namespace rf {

struct FilterSettings;
struct Splat;

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
std::string to_string(const Rect& r);  // "WxH at (X,Y)"

// How a frame is split into tasks' rects (work_units): tiles of `tile` pixels in rows from the
// top left, the last column and row clipped at the border, numbered row-major; or, with tile 0,
// the whole frame as one. Three numbers however many tiles: a 16384x16384 frame in 8-pixel tiles
// (4 million rects) is described, indexed and looked up in O(1).
class TileGrid {
 public:
  TileGrid() = default;
  // tile <= 0, or a tile covering the frame: one rect.
  TileGrid(int width, int height, int tile)
      : width_(width),
        height_(height),
        tile_(tile <= 0 || (tile >= width && tile >= height) ? 0 : tile) {}
  size_t columns() const { return tile_ ? size_t((width_ + tile_ - 1) / tile_) : 1; }
  size_t rows() const { return tile_ ? size_t((height_ + tile_ - 1) / tile_) : 1; }
  size_t size() const { return columns() * rows(); }
  Rect operator[](size_t i) const {
    if (!tile_) return {0, 0, width_, height_};
    int x = int(i % columns()) * tile_, y = int(i / columns()) * tile_;
    return {x, y, std::min(tile_, width_ - x), std::min(tile_, height_ - y)};
  }
  // The index of rect r, if r is one of the grid's rects (exactly).
  std::optional<size_t> index_of(const Rect& r) const {
    if (!tile_) return r == Rect{0, 0, width_, height_} ? std::optional<size_t>(0) : std::nullopt;
    if (r.x0 < 0 || r.y0 < 0 || r.x0 % tile_ || r.y0 % tile_ || r.x0 >= width_ || r.y0 >= height_)
      return std::nullopt;
    size_t i = size_t(r.y0 / tile_) * columns() + size_t(r.x0 / tile_);
    return (*this)[i] == r ? std::optional<size_t>(i) : std::nullopt;
  }
  int width() const { return width_; }
  int height() const { return height_; }
  int tile() const { return tile_; }  // 0: one rect
  bool operator==(const TileGrid&) const = default;

  // The rects in index order (range-for; each made on the fly).
  class Iterator {
   public:
    Iterator(const TileGrid* grid, size_t i) : grid_(grid), i_(i) {}
    Rect operator*() const { return (*grid_)[i_]; }
    Iterator& operator++() {
      ++i_;
      return *this;
    }
    bool operator==(const Iterator& o) const { return i_ == o.i_; }

   private:
    const TileGrid* grid_;
    size_t i_;
  };
  Iterator begin() const { return {this, 0}; }
  Iterator end() const { return {this, size()}; }

 private:
  int width_ = 0, height_ = 0, tile_ = 0;
};

// pbrt-v4's relative squared error, the noise figure's convention everywhere (relMSE of a render,
// `rayfarm compare`): a squared error (or variance) over reference^2 + 0.01.
inline double relative_error(double squared_error, double reference) {
  return squared_error / (reference * reference + 0.01);
}

// What identifies the image a buffer belongs to. Buffers merge only when every field but
// `passes`, `build_id`, `isa` and `core_seconds` is equal.
struct BufferHeader {
  std::string scene_digest;  // SHA-256 hex of the scene bundle
  uint64_t seed = 0;
  FrameNumber frame = 0;
  std::string integrator;     // e.g. "path"
  std::string settings;       // canonical text of the other settings that change pixels
                              // (max depth, spp per pass, filter, ...)
  int width = 0, height = 0;  // full frame resolution
  AovSet aovs;                // the AOV planes the buffer carries (engine/aov.h)
  PassSet passes;
  std::string build_id;
  std::string isa;          // Embree's ISA / CPU kind that made it
  double core_seconds = 0;  // summed over all merged buffers
  bool operator==(const BufferHeader&) const = default;
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

  // AOV plane (engine/aov.h), per pixel of rect: header.aovs.channels() doubles; empty when no
  // AOV is on.
  std::vector<double> aov;

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
  // Adds one AOV sample to pixel (x, y), frame coordinates (the buffer must carry AOVs).
  // Non-finite values are dropped (the sample still counts).
  void add_aov_sample(int x, int y, const AovSample& s);
  // The AOV values of frame pixel (x, y): mean albedo and normal over the AOV samples, mean depth
  // over those that hit and the hit fraction; zeros where no sample (or no hit) was taken.
  AovSample aov_mean(int x, int y, float* coverage) const;

  // Adds a splat at frame pixel (x, y) (the caller applies the filter weight).
  void add_splat(int x, int y, RGB weighted_radiance);
  // Adds a list of splats (splat_to_film's output) in its order.
  void add_splats(const std::vector<Splat>& splats);

  // On a buffer holding exactly one pass: sets the batch plane to that pass's pixel estimate
  // (camera mean plus splats / light paths) and its square.
  void finish_pass();

  // Per-pixel estimate (camera mean + splat / light paths), RGB, for frame pixel (x, y).
  RGB estimate(int x, int y) const;
  // Variance of the mean at (x, y) from batch means across passes (needs >= 2 passes; else 0).
  RGB variance_of_mean(int x, int y) const;
  // relMSE = mean over pixels and RGB of Var / (mean^2 + 0.01) (pbrt-v4's convention,
  // relative_error), with the batch-means variance of the mean. 0 when fewer than 2 passes.
  double rel_mse() const;
  // Mean over the rect's pixels per channel of estimate().
  RGB mean_estimate() const;
  uint64_t total_samples() const;  // sum of count over the rect
  // Every plane has the size the rect and the splat flag call for.
  bool planes_match_rect() const;
};

// A sample buffer's header, rect, planes and counters, not owned: a SampleBuffer's, or the
// planes inside an encoded buffer's bytes (buffer_file.h's EncodedBuffer), so that checks and
// merges read a received result where it lies.
struct BufferView {
  const BufferHeader* header = nullptr;
  Rect rect;
  std::span<const uint64_t> count;
  std::span<const double> sum, sum_sq, batch_sum, batch_sum_sq, splat, aov;
  uint64_t light_paths = 0, nonfinite_samples = 0, rays = 0;

  BufferView() = default;
  BufferView(const SampleBuffer& b);  // NOLINT(google-explicit-constructor): a view of it
  size_t pixel_index(int x, int y) const {
    return size_t(y - rect.y0) * size_t(rect.w) + size_t(x - rect.x0);
  }
  uint64_t total_samples() const;
  bool planes_match_rect() const;
  SampleBuffer copy() const;  // an owning copy
};

// A merged frame read a band of rows at a time, so that the writers (EXR, PNG, .rfb) need not hold
// it whole: a SampleBuffer (WholeFrame), or a frame accumulator that keeps its frame in tiles on
// disk (frame_accumulator.h).
class FrameBands {
 public:
  virtual ~FrameBands() = default;
  // The frame's header and counters (passes, provenance, light paths, rays, non-finite samples);
  // its rect is the whole frame, its planes may be empty.
  virtual const SampleBuffer& info() const = 0;
  virtual int band_height() const = 0;  // rows per band, 1 to the frame's height
  // Rows [y0, min(y0 + band_height(), rect.y1())) of info().rect, y0 = rect.y0 + k *
  // band_height(): a buffer whose rect is those rows over the rect's width (with a splat plane,
  // the whole frame's). Valid until the next call.
  virtual const SampleBuffer& band(int y0) const = 0;
  virtual uint64_t total_samples() const = 0;  // camera samples over the frame
  virtual double rel_mse() const = 0;          // the frame's noise figure (SampleBuffer::rel_mse)
};

// The frame's relMSE read band by band, summed in the order of the frame read whole (the same
// bits as SampleBuffer::rel_mse of it).
double rel_mse_of_bands(const FrameBands& frame);

// A SampleBuffer as one band.
class WholeFrame final : public FrameBands {
 public:
  explicit WholeFrame(const SampleBuffer& frame) : frame_(frame) {}
  const SampleBuffer& info() const override { return frame_; }
  int band_height() const override { return std::max(frame_.rect.h, 1); }
  const SampleBuffer& band(int) const override { return frame_; }
  uint64_t total_samples() const override { return frame_.total_samples(); }
  double rel_mse() const override { return frame_.rel_mse(); }

 private:
  const SampleBuffer& frame_;
};

// The sum over `region`'s pixels (inside b's rect) and RGB of relative_error(variance of the mean,
// estimate): rel_mse() is this over the rect, divided by 3 x its area. Row-major over the region,
// added onto `total` (so a frame read in bands sums in the order of the frame read whole).
double rel_mse_sum(const SampleBuffer& b, const Rect& region, double total = 0.0);

// Splats (DESIGN.md "Pixels, filters and splats"): light-path contributions that reach the
// camera, recorded per chunk of paths and added to the splat plane in chunk order, so the sums do
// not depend on which thread traced which chunk.
struct Splat {
  uint32_t pixel;  // y * width + x
  RGB value;       // already weighted by the filter and the pixel count
};
struct SplatTarget {
  std::vector<Splat>* out;
  int width, height;
  const FilterSettings* filter;
};
// Records a contribution arriving at `raster` whose camera importance W_e is normalised over the
// whole film: times the pixel count (a pixel's importance), weighted by the pixel filter, for
// every pixel within the filter's radius (the box half-open, so a point on a pixel border lands
// in one pixel). Non-finite and black contributions are dropped.
void splat_to_film(SplatTarget& target, Vec2 raster, RGB value);

// Why a one-pass task buffer cannot be what one pass of spp_per_pass samples per pixel made
// ("" when it could): sample counts other than the pass's (spp_per_pass in every pixel, and
// spp_per_pass light paths per pixel of its rect with splats; a light tracer's pass leaves the
// camera plane empty and traces spp_per_pass light paths per pixel of the frame), a non-finite
// sum, a negative sum of radiance or of squares, or diagnostics out of range (core_seconds over
// 1e7 for one task). The coordinator refuses such uploads before they are merged.
std::string task_buffer_problem(const BufferView& b, uint64_t spp_per_pass);
// The same for a buffer of any number of passes (a partial result, a merged frame): the samples
// per pass come from its header's settings, and every pixel must hold passes x that many;
// core_seconds at most 1e12. `rayfarm merge` refuses inputs that fail it.
std::string buffer_problem(const BufferView& b);

// Whether two buffers hold the same samples, bit for bit: every plane and count, ignoring the
// provenance that may differ between honest renders (core_seconds, isa). The determinism
// contract makes two renders of one task by one build equal in this sense.
bool same_samples(const BufferView& a, const BufferView& b);

}  // namespace rf
