// Merging sample buffers (DESIGN.md "Sample buffers and variance"): the one implementation shared
// by the local renderer, the coordinator and `rayfarm merge`. Buffers of one image (same scene,
// seed, frame, integrator, settings, resolution) with disjoint passes add up plane by plane.
#pragma once

#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/sample_buffer.h"

namespace rf {

struct MergeError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Why two headers cannot be merged, or "" when they can (everything but passes, build id, ISA
// and core-seconds equal; pass sets disjoint).
std::string merge_incompatibility(const BufferHeader& a, const BufferHeader& b);

// dst += src: same rect, compatible headers, disjoint passes. Throws MergeError saying which
// field differs or which passes overlap. Associative and commutative up to summation order.
void merge_into(SampleBuffer& dst, const BufferView& src);

// dst += tile over the tile's rect (inside dst's rect; a splat plane is the whole frame's and is
// added whole), with its counters, build, CPU kind and core-seconds, but not its passes: the
// frame accumulator adds a pass's tiles one by one and its pass once. Per pixel the same sums as
// assembling the pass and merging it. The caller has checked merge_incompatibility; this checks
// the rect and planes and throws MergeError.
void add_tile(SampleBuffer& dst, const BufferView& tile);

// Adds src's provenance to dst: build ids and CPU kinds as sets (one id, or "mixed:..." with a
// warning when a new one joins), core-seconds summed.
void combine_provenance(BufferHeader& dst, const BufferHeader& src);

// Copies the pixels of `r` (inside both rects) from src to dst, every per-pixel plane (count,
// sums, batch sums, AOVs), without arithmetic; no header, counter or splat. The caller checks the
// rects and planes.
void copy_pixels(const SampleBuffer& src, SampleBuffer& dst, const Rect& r);

// Copies a tile's buffer into a larger buffer of the same pass set (assembling one pass of a
// frame from its tiles). Throws MergeError if the tile is outside dst.rect or headers differ.
void assemble_tile(SampleBuffer& dst, const SampleBuffer& tile);

// Buffers merged a band of rows at a time (FrameBands): each input read a band at a time (an .rfb
// file through BufferFileBands) and the bands merged in the inputs' order, so no input is ever
// whole in memory; per pixel the same sums in the same order as merging the inputs whole
// (merge_into). The inputs' headers are checked at construction (MergeError naming the input by
// `names`); each band of each input is checked with buffer_problem as it is read
// (std::runtime_error "merge: NAME: refused: ...").
class MergedBands final : public FrameBands {
 public:
  MergedBands(std::vector<std::unique_ptr<FrameBands>> inputs, std::vector<std::string> names);
  const SampleBuffer& info() const override { return info_; }
  int band_height() const override { return in_[0]->band_height(); }
  const SampleBuffer& band(int y0) const override;
  uint64_t total_samples() const override { return samples_; }
  double rel_mse() const override;  // the first call reads every band

 private:
  const SampleBuffer& checked(size_t i, int y0) const;

  std::vector<std::unique_ptr<FrameBands>> in_;
  std::vector<std::string> names_;
  SampleBuffer info_;
  uint64_t samples_ = 0;
  mutable SampleBuffer band_;
  mutable std::optional<double> rel_mse_;
};

}  // namespace rf
