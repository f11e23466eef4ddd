// Warping functions from the unit square, each with its pdf.
#pragma once

#include "engine/math.h"

namespace rf {

// Uniform point on the unit disk (Shirley-Chiu concentric mapping: low distortion, so
// stratification of u survives).
inline Vec2 sample_concentric_disk(Vec2 u) {
  float ox = 2.0f * u.x - 1.0f, oy = 2.0f * u.y - 1.0f;
  if (ox == 0 && oy == 0) return {0, 0};
  float r, theta;
  if (std::fabs(ox) > std::fabs(oy)) {
    r = ox;
    theta = (kPi / 4) * (oy / ox);
  } else {
    r = oy;
    theta = (kPi / 2) - (kPi / 4) * (ox / oy);
  }
  return {r * std::cos(theta), r * std::sin(theta)};
}

// Cosine-weighted direction about +z (Malley's method on the concentric disk); pdf = cos/pi.
inline Vec3 sample_cosine_hemisphere(Vec2 u) {
  Vec2 d = sample_concentric_disk(u);
  return {d.x, d.y, safe_sqrt(1.0f - d.x * d.x - d.y * d.y)};
}
inline float cosine_hemisphere_pdf(float cos_theta) { return cos_theta * kInvPi; }

// Uniform direction on the unit sphere (z = 1 - 2 u.x); pdf 1 / (4 pi).
inline Vec3 sample_uniform_sphere(Vec2 u) {
  float z = 1.0f - 2.0f * u.x, r = safe_sqrt(1.0f - z * z), phi = 2 * kPi * u.y;
  return {r * std::cos(phi), r * std::sin(phi), z};
}

// Uniform point on a triangle as barycentrics (b0, b1) (Heitz 2019, area-preserving).
inline Vec2 sample_uniform_triangle(Vec2 u) {
  float b0, b1;
  if (u.x < u.y) {
    b0 = u.x / 2;
    b1 = u.y - b0;
  } else {
    b1 = u.y / 2;
    b0 = u.x - b1;
  }
  return {b0, b1};
}

// MIS power heuristic with beta = 2 for one sample from each of two strategies.
inline float power_heuristic(float pdf_a, float pdf_b) {
  float a = pdf_a * pdf_a, b = pdf_b * pdf_b;
  if (std::isinf(a)) return 1.0f;
  return a + b > 0 ? a / (a + b) : 0.0f;
}

}  // namespace rf
