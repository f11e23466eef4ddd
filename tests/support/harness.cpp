#include "tests/support/harness.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>

#include "engine/render.h"
#include <gtest/gtest.h>
#include <cstdio>

namespace rf::test {

namespace {

// Continued fraction of I_x(a, b) (Numerical Recipes' betacf, modified Lentz). Converges in
// O(sqrt(max(a, b))) terms for x < (a+1)/(a+b+2).
double beta_continued_fraction(double a, double b, double x) {
  const double tiny = 1e-300, eps = 1e-15;
  const int max_terms = 1000000;
  double qab = a + b, qap = a + 1, qam = a - 1;
  double c = 1, d = 1 - qab * x / qap;
  if (std::fabs(d) < tiny) d = tiny;
  d = 1 / d;
  double h = d;
  for (int m = 1; m <= max_terms; ++m) {
    double m2 = 2.0 * m;
    double aa = m * (b - m) * x / ((qam + m2) * (a + m2));  // even step
    d = 1 + aa * d;
    if (std::fabs(d) < tiny) d = tiny;
    c = 1 + aa / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1 / d;
    h *= d * c;
    aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));  // odd step
    d = 1 + aa * d;
    if (std::fabs(d) < tiny) d = tiny;
    c = 1 + aa / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1 / d;
    double del = d * c;
    h *= del;
    if (std::fabs(del - 1) < eps) return h;
  }
  throw std::runtime_error("incomplete_beta: continued fraction did not converge");
}

// Stirling's remainder lgamma(x) - [(x - 1/2) log x - x + log(2 pi) / 2], by its asymptotic
// series for x >= 10 (next term < 1e-14 relative there).
double stirling_remainder(double x) {
  if (x < 10) return std::lgamma(x) - ((x - 0.5) * std::log(x) - x + 0.5 * std::log(2 * M_PI));
  double r = 1 / x, r2 = r * r;
  return r * (1.0 / 12 - r2 * (1.0 / 360 - r2 * (1.0 / 1260 - r2 * (1.0 / 1680 - r2 / 1188))));
}

// lgamma(a + b) - lgamma(a) without the cancellation of two large lgammas when a is large:
// (a - 1/2) log1p(b/a) + b log(a + b) - b plus the difference of Stirling remainders.
double log_gamma_ratio(double a, double b) {
  if (a < 10) return std::lgamma(a + b) - std::lgamma(a);
  return (a - 0.5) * std::log1p(b / a) + b * std::log(a + b) - b + stirling_remainder(a + b) -
         stirling_remainder(a);
}

// I_x(a, b) given x and xc = 1 - x (both in [0, 1]).
double incomplete_beta_xc(double a, double b, double x, double xc) {
  if (x <= 0) return 0;
  if (xc <= 0) return 1;
  // Prefactor x^a (1-x)^b / B(a, b) in log space; lgamma(a+b) - lgamma(a) - lgamma(b) taken as
  // a ratio from the larger argument (the t test has a = dof/2 up to ~1e7 and b = 1/2).
  double big = std::max(a, b), small = std::min(a, b);
  double log_x = x > 0.5 ? std::log1p(-xc) : std::log(x);
  double log_xc = xc > 0.5 ? std::log1p(-x) : std::log(xc);
  double front =
      std::exp(log_gamma_ratio(big, small) - std::lgamma(small) + a * log_x + b * log_xc);
  if (x < (a + 1) / (a + b + 2)) return front * beta_continued_fraction(a, b, x) / a;
  return 1 - front * beta_continued_fraction(b, a, xc) / b;
}

constexpr double kOutlierLevel = 0.001;     // two-sided p below this: an outlier cell
constexpr double kCountQuantile = 0.999;    // allowed outliers: this quantile of the binomial
constexpr double kMeanRelTolerance = 0.01;  // image means agree within 1% ...
constexpr double kMeanAbsFloor = 1e-6;      // ... or this much (black images)
constexpr double kUnderpoweredSe = 0.003;   // combined SE of the image-mean difference, relative

bool equal_within_merge_tolerance(double a, double b) {  // DESIGN.md's merge tolerance
  return std::fabs(a - b) <= 1e-6 * std::max(std::fabs(a), std::fabs(b)) + 1e-12;
}

}  // namespace

double incomplete_beta(double a, double b, double x) {
  if (!(a > 0 && b > 0) || x < 0 || x > 1) {
    throw std::invalid_argument("incomplete_beta: needs a, b > 0 and x in [0, 1]");
  }
  return incomplete_beta_xc(a, b, x, 1 - x);
}

double student_t_two_sided_p(double t, double dof) {
  if (!(dof > 0) || std::isnan(t)) return 1;
  if (std::isinf(t)) return 0;
  double t2 = t * t;
  // x = dof / (dof + t^2) and 1 - x = t^2 / (dof + t^2), each computed without cancellation.
  return incomplete_beta_xc(0.5 * dof, 0.5, dof / (dof + t2), t2 / (dof + t2));
}

size_t binomial_quantile(size_t n, double p, double q) {
  if (p <= 0 || n == 0) return 0;
  if (p >= 1) return n;
  double log_p = std::log(p), log_1mp = std::log1p(-p), lg_n1 = std::lgamma(double(n) + 1);
  double target = q * (1 - 1e-12), cdf = 0;
  for (size_t k = 0; k < n; ++k) {
    double dk = double(k);
    cdf += std::exp(lg_n1 - std::lgamma(dk + 1) - std::lgamma(double(n - k) + 1) + dk * log_p +
                    double(n - k) * log_1mp);
    if (cdf >= target) return k;
  }
  return n;
}

// ---------------------------------------------------------------------------------------------

ImageStats::ImageStats(int width, int height, int block)
    : width_(width), height_(height), block_(block) {
  if (width <= 0 || height <= 0 || block <= 0) {
    throw std::invalid_argument("ImageStats: width, height and block must be positive");
  }
  blocks_x_ = (width + block - 1) / block;
  blocks_y_ = (height + block - 1) / block;
  size_t cells = 3 * blocks();
  shift_.assign(cells, 0.0);
  sum_.assign(cells, 0.0);
  sum_sq_.assign(cells, 0.0);
  min_.assign(cells, std::numeric_limits<double>::infinity());
  max_.assign(cells, -std::numeric_limits<double>::infinity());
  block_pixels_.assign(blocks(), 0.0);
  for (int by = 0; by < blocks_y_; ++by)
    for (int bx = 0; bx < blocks_x_; ++bx) {
      int w = std::min(block, width - bx * block), h = std::min(block, height - by * block);
      block_pixels_[size_t(by) * size_t(blocks_x_) + size_t(bx)] = double(w) * h;
    }
}

void ImageStats::add_pass(const SampleBuffer& buf) {
  if (buf.rect != Rect{0, 0, width_, height_} || buf.header.width != width_ ||
      buf.header.height != height_) {
    throw std::invalid_argument("ImageStats::add_pass: the buffer is not the whole " +
                                std::to_string(width_) + "x" + std::to_string(height_) + " frame");
  }
  if (buf.header.passes.count() != 1) {
    throw std::invalid_argument("ImageStats::add_pass: the buffer holds passes \"" +
                                buf.header.passes.to_string() + "\", not exactly one");
  }
  std::vector<double> rgb(size_t(width_) * size_t(height_) * 3);
  for (int y = 0; y < height_; ++y)
    for (int x = 0; x < width_; ++x) {
      RGB e = buf.estimate(x, y);
      size_t i = 3 * (size_t(y) * size_t(width_) + size_t(x));
      for (int c = 0; c < 3; ++c) rgb[i + size_t(c)] = double(e[c]);
    }
  add_pass_image(rgb);
}

void ImageStats::add_pass_image(const std::vector<double>& rgb) {
  if (rgb.size() != size_t(width_) * size_t(height_) * 3) {
    throw std::invalid_argument("ImageStats::add_pass_image: expected " +
                                std::to_string(size_t(width_) * size_t(height_) * 3) +
                                " values, got " + std::to_string(rgb.size()));
  }
  std::vector<double> block_sum(3 * blocks(), 0.0);
  double image[3] = {0, 0, 0};
  for (int y = 0; y < height_; ++y)
    for (int x = 0; x < width_; ++x) {
      size_t b = cell(x / block_, y / block_, 0);
      for (int c = 0; c < 3; ++c) {
        double v = rgb[3 * (size_t(y) * size_t(width_) + size_t(x)) + size_t(c)];
        block_sum[b + size_t(c)] += v;
        image[c] += v;
      }
    }
  for (size_t i = 0; i < block_sum.size(); ++i) {
    double v = block_sum[i] / block_pixels_[i / 3];
    if (passes_ == 0) shift_[i] = v;
    double d = v - shift_[i];
    sum_[i] += d;
    sum_sq_[i] += d * d;
    min_[i] = std::min(min_[i], v);
    max_[i] = std::max(max_[i], v);
  }
  for (int c = 0; c < 3; ++c) {
    double m = image[c] / (double(width_) * height_);
    image_sum_[c] += m;
    image_sum_sq_[c] += m * m;
  }
  ++passes_;
}

double ImageStats::mean(int bx, int by, int c) const {
  size_t i = cell(bx, by, c);
  return passes_ ? shift_[i] + sum_[i] / passes_ : 0.0;
}

bool ImageStats::zero_variance(int bx, int by, int c) const {
  size_t i = cell(bx, by, c);
  return passes_ < 2 || min_[i] == max_[i];
}

double ImageStats::variance_of_mean(int bx, int by, int c) const {
  if (zero_variance(bx, by, c)) return 0.0;
  size_t i = cell(bx, by, c);
  double n = passes_, s = sum_[i];
  double sample_var = std::max(0.0, (sum_sq_[i] - s * s / n) / (n - 1));
  return sample_var / n;
}

double ImageStats::image_mean(int c) const { return passes_ ? image_sum_[c] / passes_ : 0.0; }

double ImageStats::image_mean_std_error(int c) const {
  if (passes_ < 2) return 0.0;
  double n = passes_, s = image_sum_[c];
  return std::sqrt(std::max(0.0, (image_sum_sq_[c] - s * s / n) / (n - 1)) / n);
}

// ---------------------------------------------------------------------------------------------

ImageStats render_stats(const Scene& scene, uint32_t passes, int block) {
  if (passes < kMinPasses) {
    throw std::invalid_argument("render_stats: " + std::to_string(passes) + " passes; at least " +
                                std::to_string(kMinPasses) +
                                " are needed for trustworthy batch-means variances");
  }
  Renderer renderer(scene);
  if (block <= 0) block = renderer.splats() ? 4 : 1;
  ImageStats stats(scene.film.width, scene.film.height, block);
  Rect frame{0, 0, scene.film.width, scene.film.height};
  for (uint32_t pass = 0; pass < passes; ++pass) {
    stats.add_pass(renderer.render(TaskKey{0, frame, pass}, /*parallel=*/true));
  }
  return stats;
}

ImageStats mean_of_renders(const std::vector<const Scene*>& scenes, uint32_t passes, int block) {
  if (scenes.empty()) throw std::invalid_argument("mean_of_renders: no scenes");
  std::vector<std::unique_ptr<Renderer>> renderers;
  for (const Scene* s : scenes) renderers.push_back(std::make_unique<Renderer>(*s));
  if (block <= 0) block = renderers.front()->splats() ? 4 : 1;
  const int w = scenes.front()->film.width, h = scenes.front()->film.height;
  ImageStats stats(w, h, block);
  for (uint32_t pass = 0; pass < passes; ++pass) {
    std::vector<double> rgb(size_t(w) * size_t(h) * 3, 0.0);
    for (const auto& r : renderers) {
      const SampleBuffer b = r->render(TaskKey{0, Rect{0, 0, w, h}, pass}, true);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          for (int c = 0; c < 3; ++c)
            rgb[3 * (size_t(y) * size_t(w) + size_t(x)) + size_t(c)] +=
                double(b.estimate(x, y)[c]) / double(renderers.size());
    }
    stats.add_pass_image(rgb);
  }
  return stats;
}

Scene geometry_still_at(const Scene& moving, double time) {
  Scene s = moving;
  for (Instance& i : s.instances)
    if (i.moves()) i.to_world = i.motion.at(time), i.motion = AnimatedTransform();
  for (Mesh& m : s.meshes)
    if (m.deforms()) {
      deformed_vertices(m, time, m.positions, m.normals);
      m.deform.clear();
    }
  return s;
}

ImageStats mean_of_stills(const std::function<Scene(double)>& still_at, double open, double close,
                          int slices, uint32_t passes, int block) {
  std::vector<Scene> stills;
  for (int i = 0; i < slices; ++i)
    stills.push_back(still_at(open + (close - open) * (i + 0.5) / slices));
  std::vector<const Scene*> views;
  for (const Scene& s : stills) views.push_back(&s);
  return mean_of_renders(views, passes, block);
}

namespace {

struct CellTally {
  size_t cells = 0, outliers = 0, zero_cells = 0, zero_mismatches = 0;
  double max_abs_t = 0, min_p = 1, worst_dof = 0;
  int worst_x = -1, worst_y = -1, worst_c = -1;
  int mismatch_x = -1, mismatch_y = -1, mismatch_c = -1;
};

// Welch's t per cell: t = (ma - mb) / sqrt(va + vb) with va, vb the variances of the means, and
// Welch-Satterthwaite dof = (va + vb)^2 / (va^2 / (na - 1) + vb^2 / (nb - 1)).
CellTally tally_cells(const ImageStats& a, const ImageStats& b) {
  CellTally t;
  double na = a.passes(), nb = b.passes();
  for (int by = 0; by < a.blocks_y(); ++by)
    for (int bx = 0; bx < a.blocks_x(); ++bx)
      for (int c = 0; c < 3; ++c) {
        double ma = a.mean(bx, by, c), mb = b.mean(bx, by, c);
        double va = a.variance_of_mean(bx, by, c), vb = b.variance_of_mean(bx, by, c);
        double v = va + vb;
        // No spread in either (or one below rounding): the means must be equal.
        if (!(v > 0)) {
          ++t.zero_cells;
          if (!equal_within_merge_tolerance(ma, mb)) {
            if (t.zero_mismatches++ == 0) t.mismatch_x = bx, t.mismatch_y = by, t.mismatch_c = c;
          }
          continue;
        }
        double tstat = (ma - mb) / std::sqrt(v);
        double dof = v * v / (va * va / (na - 1) + vb * vb / (nb - 1));
        double p = student_t_two_sided_p(tstat, dof);
        ++t.cells;
        if (p < kOutlierLevel) ++t.outliers;
        if (std::fabs(tstat) > t.max_abs_t) {
          t.max_abs_t = std::fabs(tstat);
          t.min_p = p;
          t.worst_dof = dof;
          t.worst_x = bx, t.worst_y = by, t.worst_c = c;
        }
      }
  return t;
}

}  // namespace

Agreement compare(const ImageStats& a, const ImageStats& b) {
  if (a.width() != b.width() || a.height() != b.height() || a.block() != b.block()) {
    throw std::invalid_argument("compare: images differ in size or block (" +
                                std::to_string(a.width()) + "x" + std::to_string(a.height()) +
                                " block " + std::to_string(a.block()) + " vs " +
                                std::to_string(b.width()) + "x" + std::to_string(b.height()) +
                                " block " + std::to_string(b.block()) + ")");
  }
  if (a.passes() < 2 || b.passes() < 2) {
    throw std::invalid_argument("compare: each image needs at least 2 passes (has " +
                                std::to_string(a.passes()) + " and " + std::to_string(b.passes()) +
                                ")");
  }
  CellTally t = tally_cells(a, b);
  Agreement r;
  r.cells = t.cells;
  r.outliers = t.outliers;
  r.allowed_outliers = binomial_quantile(t.cells, kOutlierLevel, kCountQuantile);
  r.zero_variance_cells = t.zero_cells;
  r.zero_variance_mismatches = t.zero_mismatches;
  r.max_abs_t = t.max_abs_t;
  r.min_p = t.min_p;

  const char* names = "RGB";
  std::ostringstream m;
  m << std::setprecision(4);
  bool means_ok = true, underpowered = false;
  m << "image means:";
  for (int c = 0; c < 3; ++c) {
    double ma = a.image_mean(c), mb = b.image_mean(c);
    double larger = std::max(std::fabs(ma), std::fabs(mb)), diff = std::fabs(ma - mb);
    r.mean_rel_diff[c] = larger > 0 ? diff / larger : 0.0;
    bool ok = diff <= std::max(kMeanRelTolerance * larger, kMeanAbsFloor);
    means_ok = means_ok && ok;
    double se = std::hypot(a.image_mean_std_error(c), b.image_mean_std_error(c));
    if (se > kUnderpoweredSe * larger) underpowered = true;
    m << " " << names[c] << " " << ma << " (se " << a.image_mean_std_error(c) << ") vs " << mb
      << " (se " << b.image_mean_std_error(c) << "), rel diff " << 100 * r.mean_rel_diff[c]
      << "% (z " << (se > 0 ? (ma - mb) / se : 0.0) << ")" << (ok ? "" : " > 1%") << ";";
  }
  bool outliers_ok = r.outliers <= r.allowed_outliers;
  r.passed = outliers_ok && means_ok && r.zero_variance_mismatches == 0;

  std::ostringstream head;
  head << std::setprecision(4) << (r.passed ? "AGREE" : "DISAGREE") << ": " << a.blocks_x() << "x"
       << a.blocks_y() << " blocks of " << a.block() << "x" << a.block() << ", " << a.passes()
       << " vs " << b.passes() << " passes; " << r.cells << " cells t-tested, " << r.outliers
       << " with p < " << kOutlierLevel << " (allowed " << r.allowed_outliers << ")"
       << (outliers_ok ? "" : " TOO MANY") << "; max |t| " << r.max_abs_t;
  if (t.worst_x >= 0) {
    head << " at block (" << t.worst_x << "," << t.worst_y << ") " << names[t.worst_c] << " (dof "
         << t.worst_dof << ", p " << r.min_p << ")";
  }
  head << "; " << r.zero_variance_cells << " zero-variance cells, " << r.zero_variance_mismatches
       << " unequal";
  if (t.mismatch_x >= 0) {
    head << " (first at block (" << t.mismatch_x << "," << t.mismatch_y << ") "
         << names[t.mismatch_c] << ": " << a.mean(t.mismatch_x, t.mismatch_y, t.mismatch_c)
         << " vs " << b.mean(t.mismatch_x, t.mismatch_y, t.mismatch_c) << ")";
  }
  head << "; " << m.str();
  if (underpowered) {
    head << " WARNING: the image means' combined standard error exceeds " << 100 * kUnderpoweredSe
         << "% of the mean, so the 1% check may fail on a correct render: render more samples";
  }
  r.message = head.str();
  return r;
}

ImageMeans image_means(const ImageStats& stats) {
  ImageMeans m;
  for (int c = 0; c < 3; ++c) m.mean[c] = stats.image_mean(c), m.std_error[c] = stats.image_mean_std_error(c);
  return m;
}

ImageMeans image_means(const SampleBuffer& frame) {
  ImageMeans m;
  RGB mean = frame.mean_estimate();
  const double n = double(frame.rect.area());
  for (int c = 0; c < 3; ++c) {
    double var = 0;
    for (int y = frame.rect.y0; y < frame.rect.y1(); ++y)
      for (int x = frame.rect.x0; x < frame.rect.x1(); ++x) var += frame.variance_of_mean(x, y)[c];
    m.mean[c] = mean[c];
    m.std_error[c] = std::sqrt(var) / n;
  }
  return m;
}

void expect_cornell_means(const ImageMeans& m, double max_rel_std_error, const std::string& label) {
  for (int c = 0; c < 3; ++c) {
    SCOPED_TRACE(label + ", channel " + std::to_string(c));
    std::printf("%s image mean, channel %d: %.5f (reference %.4f, standard error %.5f)\n",
                label.c_str(), c, m.mean[c], kCornellMeans[c], m.std_error[c]);
    EXPECT_LT(m.std_error[c], max_rel_std_error * kCornellMeans[c]);
    EXPECT_NEAR(m.mean[c], kCornellMeans[c], 0.01 * kCornellMeans[c]);
  }
}

}  // namespace rf::test
