// Pixel reconstruction filters by filter importance sampling (pbrt-v4): a camera sample's offset
// from the pixel centre is drawn from the filter, and its weight is filter/pdf, so a sample
// belongs to exactly one pixel and tiles stay independent. Every filter here is separable,
// f(x, y) = f1(x) f1(y) on the square [-r, r]^2, and is sampled exactly (each axis by inverting
// its CDF), so every weight is 1:
// - box:      f1 = 1.
// - triangle: f1 = r - |x| (tent); CDF inverted in closed form.
// - gaussian: f1 = exp(-x^2 / (2 sigma^2)), truncated at r (not shifted to reach zero there, unlike
//   pbrt-v4's); CDF (erf(x / (sigma sqrt2)) + E) / 2E with E = erf(r / (sigma sqrt2)) inverted
//   with std::erf and erf_inv below (an approximation refined by Newton steps in double to
//   ~1e-15), no table.
// filter_weight is f normalised to integrate to 1 over its support: the weight a splat at that
// offset from a pixel centre gives the pixel (DESIGN.md "Pixels, filters and splats").
#pragma once

#include <cassert>
#include <cmath>

#include "engine/math.h"
#include "engine/scene.h"

namespace rf {

struct FilterSample {
  Vec2 offset;   // from the pixel centre, in pixels
  float weight;  // f(offset) / pdf(offset)
};

// Inverse error function on (-1, 1) (+-inf at +-1): Giles 2010's single-precision approximation
// ("Approximating the erfinv function", GPU Computing Gems), then two Newton steps on std::erf.
inline double erf_inv(double y) {
  if (!(std::fabs(y) < 1.0)) return std::copysign(HUGE_VAL, y);
  double w = -std::log((1.0 - y) * (1.0 + y)), x;
  if (w < 5.0) {
    w -= 2.5;
    x = 2.81022636e-08;
    for (double c : {3.43273939e-07, -3.5233877e-06, -4.39150654e-06, 0.00021858087, -0.00125372503,
                     -0.00417768164, 0.246640727, 1.50140941})
      x = c + x * w;
  } else {
    w = std::sqrt(w) - 3.0;
    x = -0.000200214257;
    for (double c : {0.000100950558, 0.00134934322, -0.00367342844, 0.00573950773, -0.0076224613,
                     0.00943887047, 1.00167406, 2.83297682})
      x = c + x * w;
  }
  x *= y;
  const double two_over_sqrt_pi = 1.1283791670955126;
  for (int i = 0; i < 2; ++i) {
    double slope = two_over_sqrt_pi * std::exp(-x * x);
    if (!(slope > 0)) break;  // far tail: the approximation is all double can resolve
    x -= (std::erf(x) - y) / slope;
  }
  return x;
}

// The tent of radius r, pdf (r - |x|) / r^2, by its inverse CDF.
inline float sample_tent(float u, float r) {
  float x = u < 0.5f ? r * (std::sqrt(2.0f * u) - 1.0f) : r * (1.0f - std::sqrt(2.0f - 2.0f * u));
  return std::clamp(x, -r, r);
}

// The Gaussian of standard deviation sigma truncated to [-r, r], by its inverse CDF.
inline float sample_truncated_gaussian(float u, float sigma, float r) {
  double s = double(sigma) * 1.4142135623730951;
  double e = std::erf(double(r) / s);
  return std::clamp(float(s * erf_inv((2.0 * double(u) - 1.0) * e)), -r, r);
}

inline FilterSample sample_filter(const FilterSettings& f, Vec2 u) {
  assert(f.radius > 0 && (f.type != FilterType::Gaussian || f.sigma > 0));
  switch (f.type) {
    case FilterType::Box:
      return {{(2.0f * u.x - 1.0f) * f.radius, (2.0f * u.y - 1.0f) * f.radius}, 1.0f};
    case FilterType::Triangle:
      return {{sample_tent(u.x, f.radius), sample_tent(u.y, f.radius)}, 1.0f};
    case FilterType::Gaussian:
      return {{sample_truncated_gaussian(u.x, f.sigma, f.radius),
               sample_truncated_gaussian(u.y, f.sigma, f.radius)},
              1.0f};
  }
  return {{0, 0}, 1.0f};
}

// The filter's 1D factor normalised to integrate to 1 over [-r, r] (0 outside).
inline double filter_weight_1d(const FilterSettings& f, double x) {
  double r = f.radius, ax = std::fabs(x);
  if (ax > r) return 0.0;
  switch (f.type) {
    case FilterType::Box:
      return 0.5 / r;
    case FilterType::Triangle:
      return (r - ax) / (r * r);
    case FilterType::Gaussian: {
      double s = double(f.sigma);
      double z = s * 2.5066282746310002 * std::erf(r / (s * 1.4142135623730951));
      return std::exp(-0.5 * x * x / (s * s)) / z;
    }
  }
  return 0.0;
}

// f(offset) normalised to integrate to 1 over the filter's support (0 outside it).
inline float filter_weight(const FilterSettings& f, Vec2 offset) {
  return float(filter_weight_1d(f, offset.x) * filter_weight_1d(f, offset.y));
}

}  // namespace rf
