// Piecewise-constant distributions on [0,1) and [0,1)^2 (pbrt-v3 Distribution1D/2D): sampling
// by inverting the tabulated cdf, and the matching density. Used to importance-sample the
// environment map; small enough to reuse for light selection or textured emitters.
#pragma once

#include <algorithm>
#include <cstdint>
#include <utility>
#include <vector>

#include "engine/check.h"

namespace rf {

// Density on [0,1) proportional to f[i] on [i/n, (i+1)/n). f must be >= 0; an all-zero f
// samples uniformly but reports density 0 (nothing there to importance-sample).
class Distribution1D {
 public:
  Distribution1D() = default;
  explicit Distribution1D(std::vector<float> f) : func_(std::move(f)) {
    size_t n = func_.size();
    RF_CHECK(n > 0, "a distribution over no cells");
    cdf_.assign(n + 1, 0.0f);
    double sum = 0;
    for (float v : func_) sum += double(v);
    integral_ = float(sum / double(n));
    double acc = 0;
    for (size_t i = 0; i < n; ++i) {
      acc += double(func_[i]);
      cdf_[i + 1] = sum > 0 ? float(acc / sum) : float(double(i + 1) / double(n));
    }
    cdf_[n] = 1.0f;
  }

  size_t size() const { return func_.size(); }
  float func(size_t i) const { return func_[i]; }
  // Integral of the piecewise-constant function over [0,1): the mean of f.
  float integral() const { return integral_; }

  // Continuous sample x in [0,1) from u in [0,1); *pdf = f[cell] / integral, *cell = index.
  float sample(float u, float* pdf, size_t* cell) const {
    size_t n = func_.size();
    // Interval [cdf_[i], cdf_[i+1]) that holds u; it has positive width since cdf_[i+1] > u.
    size_t i = size_t(std::upper_bound(cdf_.begin() + 1, cdf_.end(), u) - (cdf_.begin() + 1));
    i = std::min(i, n - 1);
    float width = cdf_[i + 1] - cdf_[i];
    float du = width > 0 ? (u - cdf_[i]) / width : 0.5f;
    if (pdf) *pdf = integral_ > 0 ? func_[i] / integral_ : 0.0f;
    if (cell) *cell = i;
    return std::min((float(i) + du) / float(n), 0x1.fffffep-1f);
  }
  float pdf(float x) const {
    if (!(integral_ > 0)) return 0.0f;
    return func_[cell_of(x)] / integral_;
  }
  size_t cell_of(float x) const {
    size_t n = func_.size();
    float fi = x * float(n);
    return fi <= 0 ? 0 : std::min(size_t(fi), n - 1);
  }

 private:
  std::vector<float> func_;
  std::vector<float> cdf_;  // size n+1, cdf_[0] = 0, cdf_[n] = 1
  float integral_ = 0;
};

// Density on [0,1)^2 proportional to f[v * nu + u] (row v, column u): the marginal picks a row,
// that row's conditional picks a column. pdf(u, v) = f(u, v) / integral of f.
class Distribution2D {
 public:
  Distribution2D() = default;
  Distribution2D(const std::vector<float>& f, size_t nu, size_t nv) {
    rows_.reserve(nv);
    std::vector<float> marginal(nv);
    for (size_t v = 0; v < nv; ++v) {
      rows_.emplace_back(std::vector<float>(f.begin() + v * nu, f.begin() + (v + 1) * nu));
      marginal[v] = rows_.back().integral();
    }
    marginal_ = Distribution1D(std::move(marginal));
  }

  size_t width() const { return rows_.empty() ? 0 : rows_[0].size(); }
  size_t height() const { return rows_.size(); }
  float integral() const { return marginal_.integral(); }

  // Sample (u, v) in [0,1)^2 with density *pdf.
  void sample(float u0, float u1, float* u, float* v, float* pdf) const {
    float pdf_v = 0, pdf_u = 0;
    size_t row = 0;
    *v = marginal_.sample(u1, &pdf_v, &row);
    *u = rows_[row].sample(u0, &pdf_u, nullptr);
    *pdf = pdf_v * pdf_u;
  }
  float pdf(float u, float v) const {
    if (!(marginal_.integral() > 0)) return 0.0f;
    const Distribution1D& row = rows_[marginal_.cell_of(v)];
    return row.func(row.cell_of(u)) / marginal_.integral();
  }

 private:
  std::vector<Distribution1D> rows_;
  Distribution1D marginal_;
};

}  // namespace rf
