// Warping functions from the unit square, each with its pdf.
#pragma once

#include "engine/math.h"

namespace rf {

// Uniform point on the unit disk (Shirley-Chiu concentric mapping: low distortion, so
// stratification of u survives), in polar form: the point is (r cos theta, r sin theta). Apart
// from the cosine and sine so that a loop over lanes can vectorise the rest (the path tracer's
// lanes); (0, 0) for the centre, whose r cos 0 and r sin 0 are +0.
inline void concentric_disk_polar(Vec2 u, float& r, float& theta) {
  float ox = 2.0f * u.x - 1.0f, oy = 2.0f * u.y - 1.0f;
  bool x_major = std::fabs(ox) > std::fabs(oy);
  r = x_major ? ox : oy;
  theta = x_major ? (kPi / 4) * (oy / ox) : (kPi / 2) - (kPi / 4) * (ox / oy);
  if (ox == 0 && oy == 0) r = 0, theta = 0;
}
inline Vec2 sample_concentric_disk(Vec2 u) {
  float r, theta;
  concentric_disk_polar(u, r, theta);
  return {r * std::cos(theta), r * std::sin(theta)};
}

// Cosine-weighted direction about +z (Malley's method on the concentric disk); pdf = cos/pi.
inline Vec3 cosine_hemisphere_from_disk(Vec2 d) {
  return {d.x, d.y, safe_sqrt(1.0f - d.x * d.x - d.y * d.y)};
}
inline Vec3 sample_cosine_hemisphere(Vec2 u) {
  return cosine_hemisphere_from_disk(sample_concentric_disk(u));
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
