// Chi-square goodness-of-fit of a sampling routine against its density, for tests (header-only:
// tests/CMakeLists.txt builds only test_support.cpp into the shared test library).
//
// Method (as pbrt-v4's and Mitsuba 3's chi2 tests): histogram the sampled directions on a
// (theta, phi) grid of the sphere, integrate the claimed pdf over every cell (nested adaptive
// Simpson in double precision), pool cells whose expected count is below 5, and compare with
// Pearson's statistic. With a family of N tests, each test uses the Sidak-corrected level
// 1 - (1 - alpha)^(1/N), so a correct implementation fails the family with probability alpha.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

namespace rf::test {

// Regularised upper incomplete gamma function Q(a, x) = Gamma(a, x) / Gamma(a) (Numerical
// Recipes' series and continued fraction, to ~1e-14 relative).
inline double gamma_q(double a, double x) {
  if (x <= 0) return 1.0;
  double gln = std::lgamma(a);
  if (x < a + 1) {  // series for P(a, x)
    double ap = a, sum = 1.0 / a, del = sum;
    for (int n = 0; n < 100000; ++n) {
      ap += 1;
      del *= x / ap;
      sum += del;
      if (std::fabs(del) < std::fabs(sum) * 1e-15) break;
    }
    return 1.0 - sum * std::exp(-x + a * std::log(x) - gln);
  }
  // Continued fraction for Q(a, x) (modified Lentz).
  const double tiny = 1e-300;
  double b = x + 1 - a, c = 1 / tiny, d = 1 / b, h = d;
  for (int i = 1; i < 100000; ++i) {
    double an = -i * (i - a);
    b += 2;
    d = an * d + b;
    if (std::fabs(d) < tiny) d = tiny;
    c = b + an / c;
    if (std::fabs(c) < tiny) c = tiny;
    d = 1 / d;
    double del = d * c;
    h *= del;
    if (std::fabs(del - 1) < 1e-15) break;
  }
  return std::exp(-x + a * std::log(x) - gln) * h;
}

// P(X >= x) for X chi-square distributed with dof degrees of freedom.
inline double chi2_upper_tail(double x, int dof) { return gamma_q(0.5 * dof, 0.5 * x); }

// The per-test significance level that keeps a family of n tests at family_alpha (Sidak).
inline double sidak_alpha(double family_alpha, int n) {
  return 1.0 - std::pow(1.0 - family_alpha, 1.0 / n);
}

struct ChiSquareResult {
  bool passed = false;
  double statistic = 0, p_value = 0;
  int dof = 0;
  int cells = 0, pooled_cells = 0;
  std::string message;  // why it failed, or a summary
};

// Pearson's test of observed against expected counts (same total up to sampling noise). Cells
// with expected < min_expected are pooled, smallest first, until each pool reaches it. A cell
// with zero expected count but observed samples fails outright (pdf says impossible).
inline ChiSquareResult chi_square_test(const std::vector<double>& observed,
                                       const std::vector<double>& expected, double significance,
                                       double min_expected = 5.0) {
  ChiSquareResult r;
  std::vector<size_t> order(observed.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return expected[a] < expected[b]; });
  double pool_o = 0, pool_e = 0;
  std::vector<std::pair<double, double>> cells;  // (observed, expected)
  for (size_t i : order) {
    if (expected[i] <= 0) {
      if (observed[i] > 0) {
        std::ostringstream m;
        m << "cell " << i << " has " << observed[i] << " samples where the pdf integrates to "
          << expected[i];
        r.message = m.str();
        return r;
      }
      continue;
    }
    if (expected[i] < min_expected || (pool_e > 0 && pool_e < min_expected)) {
      pool_o += observed[i];
      pool_e += expected[i];
      ++r.pooled_cells;
      if (pool_e >= min_expected) {
        cells.push_back({pool_o, pool_e});
        pool_o = pool_e = 0;
      }
      continue;
    }
    cells.push_back({observed[i], expected[i]});
  }
  if (pool_e > 0) {  // a remainder below min_expected joins the smallest regular cell
    if (cells.empty()) {
      cells.push_back({pool_o, pool_e});
    } else {
      cells.front().first += pool_o;
      cells.front().second += pool_e;
    }
  }
  for (auto [o, e] : cells) r.statistic += (o - e) * (o - e) / e;
  r.cells = int(cells.size());
  r.dof = r.cells - 1;
  if (r.dof < 1) {
    r.passed = true;
    r.p_value = 1;
    r.message = "fewer than two cells: nothing to test";
    return r;
  }
  r.p_value = chi2_upper_tail(r.statistic, r.dof);
  r.passed = r.p_value >= significance;
  std::ostringstream m;
  m << "chi2 = " << r.statistic << ", dof = " << r.dof << ", p = " << r.p_value << " (level "
    << significance << "), " << r.pooled_cells << " cells pooled";
  r.message = m.str();
  return r;
}

// Adaptive Simpson quadrature of f on [a, b] to absolute tolerance eps; always subdivides at
// least min_depth times (so narrow peaks between the first nodes are seen) and at most
// max_depth times.
template <class F>
double adaptive_simpson(const F& f, double a, double b, double eps, int min_depth = 3,
                        int max_depth = 12) {
  struct Rec {
    const F& f;
    int min_depth, max_depth;
    double run(double a, double b, double fa, double fm, double fb, double whole, double eps,
               int depth) const {
      double m = 0.5 * (a + b), lm = 0.5 * (a + m), rm = 0.5 * (m + b);
      double flm = f(lm), frm = f(rm);
      double left = (m - a) / 6 * (fa + 4 * flm + fm), right = (b - m) / 6 * (fm + 4 * frm + fb);
      double delta = left + right - whole;
      if (depth >= max_depth || (depth >= min_depth && std::fabs(delta) <= 15 * eps))
        return left + right + delta / 15;
      return run(a, m, fa, flm, fm, left, 0.5 * eps, depth + 1) +
             run(m, b, fm, frm, fb, right, 0.5 * eps, depth + 1);
    }
  };
  Rec rec{f, min_depth, max_depth};
  double fa = f(a), fm = f(0.5 * (a + b)), fb = f(b);
  return rec.run(a, b, fa, fm, fb, (b - a) / 6 * (fa + 4 * fm + fb), eps, 0);
}

// A (theta, phi) grid over the sphere: theta in [0, pi] from +z, phi in [0, 2pi) from +x.
struct SphereGrid {
  int n_theta = 10, n_phi = 20;

  int cells() const { return n_theta * n_phi; }
  int cell_of(double x, double y, double z) const {
    double theta = std::acos(std::clamp(z, -1.0, 1.0));
    double phi = std::atan2(y, x);
    if (phi < 0) phi += 2 * M_PI;
    int i = std::min(n_theta - 1, int(theta / M_PI * n_theta));
    int j = std::min(n_phi - 1, int(phi / (2 * M_PI) * n_phi));
    return i * n_phi + j;
  }
  // Integral of pdf(x, y, z) over each cell (solid angle measure), eps absolute per cell.
  template <class Pdf>
  std::vector<double> integrate(const Pdf& pdf, double eps = 1e-8) const {
    std::vector<double> out(static_cast<size_t>(cells()), 0.0);
    for (int i = 0; i < n_theta; ++i)
      for (int j = 0; j < n_phi; ++j) {
        double t0 = M_PI * i / n_theta, t1 = M_PI * (i + 1) / n_theta;
        double p0 = 2 * M_PI * j / n_phi, p1 = 2 * M_PI * (j + 1) / n_phi;
        auto over_phi = [&](double theta) {
          double st = std::sin(theta), ct = std::cos(theta);
          auto f = [&](double phi) { return pdf(st * std::cos(phi), st * std::sin(phi), ct) * st; };
          return adaptive_simpson(f, p0, p1, eps / (t1 - t0));
        };
        out[size_t(i * n_phi + j)] = adaptive_simpson(over_phi, t0, t1, eps);
      }
    return out;
  }
};

}  // namespace rf::test
