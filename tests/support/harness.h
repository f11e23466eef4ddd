// The statistics harness: the one image comparison every agreement test uses (issue 4).
//
// Two renders agree when they estimate the same image. Each render is summarised by ImageStats,
// the batch means of at least 32 independent passes (DESIGN.md "Passes, seeds and the
// determinism contract": passes are independent estimates of the whole image), per block and
// channel. compare() then asks, per cell (block x channel), whether the two batch means differ
// by more than their noise explains (Welch's t test, two-sided, level 0.001), and passes when
//   - the number of outlier cells is at most the 0.999 quantile of Binomial(cells, 0.001), so a
//     correct renderer fails by outlier count in fewer than one run in a thousand,
//   - every channel's image mean agrees within 1% (relative to the larger; absolute floor 1e-6),
//   - cells with zero variance in both renders (e.g. pixels that see only an emitter of zero
//     albedo) have equal means.
// Camera-path integrators are compared per pixel (block 1). Splatting integrators are compared
// on 4x4 block means: within a pass their pixels share light paths and are correlated, so the
// per-pixel cells would not be independent; blocks of 4x4 mostly are.
//
// The image-mean check is only meaningful when the renders' image means are known to much better
// than 1%: the message reports each render's batch-means standard error of the image mean and
// flags a comparison whose combined error exceeds 0.3% (then a correct render may fail it).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "engine/sample_buffer.h"
#include "engine/scene.h"

namespace rf::test {

// Regularised incomplete beta function I_x(a, b) (Numerical Recipes' continued fraction, modified
// Lentz). For the t test's arguments (a = dof/2, b = 1/2) the relative error is below 1e-9 up
// to dof 1e7, measured against closed forms and the large-dof expansion; Welch's dof never
// exceeds na + nb - 2 anyway.
double incomplete_beta(double a, double b, double x);

// Two-sided p-value of Student's t: P(|T| >= |t|) = I_{dof/(dof+t^2)}(dof/2, 1/2). dof may be
// fractional (Welch); dof <= 0 gives 1 (no evidence).
double student_t_two_sided_p(double t, double dof);

// The q-quantile of Binomial(n, p): the smallest k with P(X <= k) >= q, the pmf summed in log
// space (exact up to rounding; q compared with a 1e-12 relative allowance).
size_t binomial_quantile(size_t n, double p, double q);

class ImageStats {
 public:
  // width x height pixels in blocks of block x block (block 1: per pixel); the last row and
  // column of blocks are partial when block does not divide the size.
  ImageStats(int width, int height, int block);

  // Adds one pass: the buffer must hold exactly one pass of the whole frame. Each block's value
  // is the mean over its pixels of SampleBuffer::estimate().
  void add_pass(const SampleBuffer& one_pass_whole_frame);
  // The same from a plain image, width*height*3 values (RGB, row-major): for synthetic tests.
  void add_pass_image(const std::vector<double>& rgb);

  int width() const { return width_; }
  int height() const { return height_; }
  int block() const { return block_; }
  int blocks_x() const { return blocks_x_; }
  int blocks_y() const { return blocks_y_; }
  size_t blocks() const { return size_t(blocks_x_) * size_t(blocks_y_); }
  uint32_t passes() const { return passes_; }

  // Batch mean of block (bx, by), channel c: S / n (S, Q: sums of the per-pass values and their
  // squares, kept shifted by the first pass's value).
  double mean(int bx, int by, int c) const;
  // Batch-means variance of that mean: s^2 / n with s^2 = (Q - S^2/n) / (n - 1), clamped at 0;
  // exactly 0 when every pass gave the same value (tracked as min == max, not by the rounding
  // of Q - S^2/n) or when fewer than 2 passes were added.
  double variance_of_mean(int bx, int by, int c) const;
  bool zero_variance(int bx, int by, int c) const;
  // Mean over the pixels of channel c, averaged over passes (pixel-weighted: partial blocks
  // count for the pixels they hold).
  double image_mean(int c) const;
  // Batch-means standard error of image_mean(c), from the per-pass image means (valid however
  // the pixels are correlated within a pass).
  double image_mean_std_error(int c) const;

 private:
  size_t cell(int bx, int by, int c) const {
    return 3 * (size_t(by) * size_t(blocks_x_) + size_t(bx)) + size_t(c);
  }
  int width_, height_, block_, blocks_x_, blocks_y_;
  uint32_t passes_ = 0;
  // Per cell (block, channel): sums of (value - shift) and its square, shift = the first pass's
  // value (so Q - S^2/n does not cancel when the spread is small against the mean), min, max.
  std::vector<double> shift_, sum_, sum_sq_, min_, max_;
  std::vector<double> block_pixels_;                               // pixels per block
  double image_sum_[3] = {0, 0, 0}, image_sum_sq_[3] = {0, 0, 0};  // per-pass image means
};

// Renders passes 0..passes-1 of the whole frame (Renderer::render, parallel) and collects
// them. block <= 0 picks the default: 4 for splatting integrators, 1 otherwise. Throws
// std::invalid_argument for fewer than 32 passes (batch-means variances from fewer passes are
// too noisy for the t test's tails).
ImageStats render_stats(const Scene& scene, uint32_t passes, int block);

inline constexpr uint32_t kMinPasses = 32;

// The same passes of several scenes of one film size (stills at times across a shutter), each
// pass the mean of the scenes' renders of that pass: the time integral a motion-blurred render
// estimates, by the midpoint rule when the scenes stand at the midpoints of equal slices.
ImageStats mean_of_renders(const std::vector<const Scene*>& scenes, uint32_t passes, int block);
// The scene with its geometry frozen at `time` (seconds): every moving instance placed where it
// is then, every deforming mesh given its vertices then (the stills mean_of_stills averages).
Scene geometry_still_at(const Scene& moving, double time);
// That for the scenes still_at(t) at the midpoints t of `slices` equal slices of [open, close]
// (seconds).
ImageStats mean_of_stills(const std::function<Scene(double)>& still_at, double open, double close,
                          int slices, uint32_t passes, int block);

// A render's per-channel image mean and the standard error of that mean.
struct ImageMeans {
  double mean[3] = {0, 0, 0}, std_error[3] = {0, 0, 0};
};
// From batch means over passes (valid however pixels correlate within a pass).
ImageMeans image_means(const ImageStats& stats);
// From a merged camera-path frame whose pixels are independent: Var(image mean) = the sum of the
// pixels' variances of the mean / N^2.
ImageMeans image_means(const SampleBuffer& frame);

// The Cornell box's converged image means at max depth 64 (R, G, B), on which other renderers'
// converged renders of Bitterli's scene agree (Tungsten's reference too): every format's Cornell
// box is held to them.
inline constexpr double kCornellMeans[3] = {0.1963, 0.1275, 0.0361};
// Expects each channel's mean within 1% of kCornellMeans, and the render's own standard error
// below max_rel_std_error of the reference so that the 1% check means something (the reference
// is itself good to a few 0.1%). Prints the figures under `label`.
void expect_cornell_means(const ImageMeans& m, double max_rel_std_error, const std::string& label);

struct Agreement {
  bool passed = false;
  size_t cells = 0;  // cells t-tested (block x channel, with nonzero variance in either)
  size_t outliers = 0, allowed_outliers = 0;
  double mean_rel_diff[3] = {0, 0, 0};  // |ma - mb| / max(|ma|, |mb|) per channel (0 if both 0)
  size_t zero_variance_mismatches = 0;
  size_t zero_variance_cells = 0;  // cells with zero variance in both: compared for equality
                                   // (|a-b| <= 1e-6 max(|a|,|b|) + 1e-12, DESIGN.md's merge
                                   // tolerance), not t-tested
  double max_abs_t = 0;            // largest |t| over the tested cells
  double min_p = 1;                // its smallest p-value
  std::string message;             // every figure above, and why it failed
};

// Compares two renders of the same frame (same size and block; pass counts may differ).
// Throws std::invalid_argument on mismatched sizes or blocks, or fewer than 2 passes.
Agreement compare(const ImageStats& a, const ImageStats& b);

}  // namespace rf::test
