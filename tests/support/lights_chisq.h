// Pearson's chi-square goodness-of-fit test for light sampling (lights_test.cpp): observed counts
// per cell against expected counts, cells of small expectation pooled (pbrt-v4 and Mitsuba 3 do
// the same), the p-value from the regularised upper incomplete gamma function, and the Sidak
// correction for a family of tests. Header-only so it needs no build change.
#pragma once

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

namespace rf::test::lights {

// Q(a, x) = Gamma(a, x) / Gamma(a): series for x < a + 1, Lentz's continued fraction otherwise
// (Numerical Recipes 6.2), in double; relative accuracy ~1e-12, ample for p-values.
inline double gamma_q(double a, double x) {
  if (x <= 0) return 1.0;
  const double gln = std::lgamma(a);
  if (x < a + 1) {
    double ap = a, sum = 1.0 / a, del = sum;
    for (int n = 0; n < 100000; ++n) {
      ap += 1;
      del *= x / ap;
      sum += del;
      if (std::fabs(del) < std::fabs(sum) * 1e-15) break;
    }
    return 1.0 - sum * std::exp(-x + a * std::log(x) - gln);
  }
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

// P(X >= chi2) for X chi-square distributed with dof degrees of freedom.
inline double chi_square_sf(double chi2, double dof) { return gamma_q(0.5 * dof, 0.5 * chi2); }

// Per-test significance so that `tests` independent tests at that level together reject a
// correct implementation with probability family_alpha (Sidak).
inline double sidak_alpha(double family_alpha, int tests) {
  return 1.0 - std::pow(1.0 - family_alpha, 1.0 / tests);
}

struct ChiSquareResult {
  double chi2 = 0;
  int dof = 0;
  double p_value = 0;
  std::string message;  // what was tested, for the assertion's output
};

// observed[i] vs expected[i]. Cells with expected < min_expected are pooled, smallest first,
// until the pool's expectation reaches min_expected (a leftover pool joins the last big cell's
// statistic as one more cell). Any count in a cell of expectation 0 is an outright failure.
inline ChiSquareResult chi_square_test(const std::vector<double>& observed,
                                       const std::vector<double>& expected,
                                       double min_expected = 5.0) {
  ChiSquareResult r;
  std::vector<size_t> order(expected.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return expected[a] < expected[b]; });
  double pool_obs = 0, pool_exp = 0, zero_obs = 0;
  int cells = 0;
  for (size_t k : order) {
    if (expected[k] <= 0) {
      zero_obs += observed[k];
      continue;
    }
    if (expected[k] < min_expected) {
      pool_obs += observed[k];
      pool_exp += expected[k];
      if (pool_exp >= min_expected) {
        r.chi2 += (pool_obs - pool_exp) * (pool_obs - pool_exp) / pool_exp;
        ++cells;
        pool_obs = pool_exp = 0;
      }
      continue;
    }
    r.chi2 += (observed[k] - expected[k]) * (observed[k] - expected[k]) / expected[k];
    ++cells;
  }
  if (pool_exp > 0) {
    r.chi2 += (pool_obs - pool_exp) * (pool_obs - pool_exp) / pool_exp;
    ++cells;
  }
  std::ostringstream os;
  if (zero_obs > 0) {
    r.p_value = 0;
    os << zero_obs << " samples fell in cells of expected count 0";
  } else {
    r.dof = std::max(cells - 1, 1);
    r.p_value = chi_square_sf(r.chi2, r.dof);
    os << "chi2 = " << r.chi2 << " with " << r.dof << " dof, p = " << r.p_value;
  }
  r.message = os.str();
  return r;
}

}  // namespace rf::test::lights
