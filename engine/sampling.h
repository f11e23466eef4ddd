// Warping functions from the unit square, each with its pdf.
#pragma once

#include "engine/math.h"

namespace rf {

// sin and cos of x for |x| <= pi/4 (+ a little): their Taylor polynomials to x^9 and x^10, whose
// truncation errors (below 2e-9 and 1.2e-10 there) are far under a float's rounding, evaluated
// in Horner form. No branch and no library call, so loops over lanes vectorise with it, and every
// SIMD level gives the same bits (multiplies and adds only, no contraction).
inline void sin_cos_quarter_pi(float x, float& s, float& c) {
  const float z = x * x;
  s = x + x * z * (-1.0f / 6 + z * (1.0f / 120 + z * (-1.0f / 5040 + z * (1.0f / 362880))));
  c = 1.0f + z * (-0.5f +
                  z * (1.0f / 24 + z * (-1.0f / 720 + z * (1.0f / 40320 + z * (-1.0f / 3628800)))));
}

// The cosine and sine of 2 pi u, a turn's fraction u in [0, 1], by sin_cos_quarter_pi: u's
// nearest quarter turn k = round(4 u), the rest x = (4 u - k) pi/2 in [-pi/4, pi/4] (4 u - k
// exact, one rounding in the multiply), then the quarter turns as swaps and signs. No branch and
// no library call (the path tracer's lanes compute it in their loops); within 1.2e-7 of the
// exact values (tests/sampler_test.cpp).
inline void cos_sin_turn(float u, float& c, float& s) {
  const float q = 4.0f * u;
  const int k = int(q + 0.5f);  // q >= 0: the conversion rounds down
  float sx, cx;
  sin_cos_quarter_pi((q - float(k)) * (kPi / 2), sx, cx);
  const int m = k & 3;  // cos, sin of m pi/2 + x: (cx, sx), (-sx, cx), (-cx, -sx), (sx, -cx)
  const bool swap = (m & 1) != 0;
  const float cc = swap ? sx : cx, ss = swap ? cx : sx;
  c = (m == 1) | (m == 2) ? -cc : cc;
  s = m >= 2 ? -ss : ss;
}

// Uniform point on the unit disk (Shirley-Chiu concentric mapping: low distortion, so
// stratification of u survives). The point is (r cos theta, r sin theta) with theta = phi on the
// wedges where |x| leads and pi/2 - phi elsewhere, phi = pi/4 t, |t| <= 1: so the cosine and sine
// of phi are all it needs (sin_cos_quarter_pi), swapped on the second kind of wedge. (0, 0) for
// the centre.
inline Vec2 sample_concentric_disk(Vec2 u) {
  const float ox = 2.0f * u.x - 1.0f, oy = 2.0f * u.y - 1.0f;
  const bool x_major = std::fabs(ox) > std::fabs(oy);
  const bool centre = (ox == 0) & (oy == 0);
  const float r = x_major ? ox : oy;
  const float t = x_major ? oy / ox : ox / oy;  // 0 / 0 only at the centre
  float s, c;
  sin_cos_quarter_pi((kPi / 4) * (centre ? 0.0f : t), s, c);
  const float x = r * (x_major ? c : s), y = r * (x_major ? s : c);
  return {centre ? 0.0f : x, centre ? 0.0f : y};
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
