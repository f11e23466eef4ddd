// Fresnel reflectance of smooth interfaces, and the reflect / refract helpers every BSDF shares.
//
// Conventions (pbrt-v4, "Specular Reflection and Transmission"): cos_theta_i is measured against
// the normal on the side of the *outside* medium; eta = eta_inside / eta_outside. A negative
// cos_theta_i means the light arrives from inside, and the relative IOR is then 1 / eta.
// All reflectances are for unpolarised light: the mean of the parallel and perpendicular terms.
//
// References: pbrt-v4 (Pharr, Jakob, Humphreys 2023) sections 9.3 and 9.4; Schlick 1994, "An
// Inexpensive BRDF Model for Physically-based Rendering".
#pragma once

#include <cmath>

#include "engine/math.h"

namespace rf {

// Exact dielectric Fresnel reflectance. Returns 1 under total internal reflection.
inline float fresnel_dielectric(float cos_theta_i, float eta) {
  cos_theta_i = std::clamp(cos_theta_i, -1.0f, 1.0f);
  if (cos_theta_i < 0) {
    eta = 1 / eta;
    cos_theta_i = -cos_theta_i;
  }
  float sin2_t = (1 - cos_theta_i * cos_theta_i) / (eta * eta);
  if (sin2_t >= 1) return 1.0f;
  float cos_t = safe_sqrt(1 - sin2_t);
  float r_parl = (eta * cos_theta_i - cos_t) / (eta * cos_theta_i + cos_t);
  float r_perp = (cos_theta_i - eta * cos_t) / (cos_theta_i + eta * cos_t);
  return 0.5f * (r_parl * r_parl + r_perp * r_perp);
}

// Conductor Fresnel reflectance for the complex IOR eta + i k (light arrives from the
// dielectric outside; cos_theta_i is clamped to [0, 1]), in real arithmetic: with
// n^2 - sin^2(theta_i) = (a + i b)^2, s = a^2 + b^2 = |eta^2 - k^2 - sin^2 + 2 i eta k| and
// a^2 = (s + t0) / 2 (Born and Wolf, "Principles of Optics", 14.2), the two reflectances are
//   R_perp = (s + cos^2 - 2 a cos) / (s + cos^2 + 2 a cos),
//   R_parl = R_perp (cos^2 s + sin^4 - 2 a cos sin^2) / (cos^2 s + sin^4 + 2 a cos sin^2).
// It equals |r|^2 of the complex Fresnel equations (tests/bsdf_test.cpp checks it against them
// in double precision) without complex square roots and divisions.
inline float fresnel_complex(float cos_theta_i, float eta, float k) {
  float c = std::clamp(cos_theta_i, 0.0f, 1.0f);
  float c2 = c * c, sin2 = 1 - c2;
  float eta2 = eta * eta, k2 = k * k;
  float t0 = eta2 - k2 - sin2;
  float s = std::sqrt(t0 * t0 + 4 * eta2 * k2);
  // a^2 = (s + t0) / 2 cancels when t0 < 0 (k > eta, as for silver); (s + t0)(s - t0) = 4 eta^2
  // k^2 gives the same value without the cancellation.
  float a2 = t0 >= 0 ? 0.5f * (s + t0) : (s - t0 > 0 ? 2 * eta2 * k2 / (s - t0) : 0.0f);
  float two_a_c = 2 * std::sqrt(a2) * c;
  float t1 = s + c2;
  float r_perp = (t1 - two_a_c) / (t1 + two_a_c);
  float t3 = c2 * s + sin2 * sin2, t4 = two_a_c * sin2;
  float r_parl = t3 + t4 > 0 ? r_perp * (t3 - t4) / (t3 + t4) : r_perp;
  // 1 for grazing light on a vacuum-like interface; a select, not a return (the path tracer's
  // lanes vectorise it).
  return !(t1 + two_a_c > 0) ? 1.0f : 0.5f * (r_parl + r_perp);
}

inline RGB fresnel_complex(float cos_theta_i, RGB eta, RGB k) {
  return {fresnel_complex(cos_theta_i, eta.x, k.x), fresnel_complex(cos_theta_i, eta.y, k.y),
          fresnel_complex(cos_theta_i, eta.z, k.z)};
}

// Schlick's approximation F0 + (1 - F0) (1 - cos)^5, per channel (cos clamped to [0, 1]).
inline RGB fresnel_schlick(RGB f0, float cos_theta_i) {
  float m = 1 - std::clamp(cos_theta_i, 0.0f, 1.0f);
  float m5 = (m * m) * (m * m) * m;
  return f0 + (RGB(1.0f) - f0) * m5;
}

// Cosine-weighted hemispherical reflectance of a smooth dielectric seen from the outside,
// F_dr,ext = int_0^1 F(mu, eta) 2 mu dmu, for eta >= 1 (no total internal reflection, so the
// integrand is smooth and 16-point Gauss-Legendre is accurate to ~1e-6; tests/bsdf_test.cpp).
inline float fresnel_diffuse_reflectance_exterior(float eta) {
  // Gauss-Legendre nodes and weights on [-1, 1], positive half (the rule is symmetric).
  static constexpr double kX[8] = {0.0950125098376374, 0.2816035507792589, 0.4580167776572274,
                                   0.6178762444026438, 0.7554044083550030, 0.8656312023878318,
                                   0.9445750230732326, 0.9894009349916499};
  static constexpr double kW[8] = {0.1894506104550685, 0.1826034150449236, 0.1691565193950025,
                                   0.1495959888165767, 0.1246289712555339, 0.0951585116824928,
                                   0.0622535239386479, 0.0271524594117541};
  double sum = 0;
  for (int i = 0; i < 8; ++i)
    for (double sign : {-1.0, 1.0}) {
      double mu = 0.5 * (1 + sign * kX[i]);  // map [-1, 1] to [0, 1]
      sum += kW[i] * 0.5 * fresnel_dielectric(float(mu), eta) * 2 * mu;
    }
  return float(sum);
}

// The same seen from the inside (eta >= 1): by reciprocity the hemispherical transmittances
// satisfy T_int = T_ext / eta^2, so F_dr,int = 1 - (1 - F_dr,ext) / eta^2 (includes the total
// internal reflection beyond the critical angle).
inline float fresnel_diffuse_reflectance_interior(float eta) {
  return 1 - (1 - fresnel_diffuse_reflectance_exterior(eta)) / (eta * eta);
}

// Mirror reflection of wo about the unit normal n (both pointing away from the surface).
inline Vec3 reflect(Vec3 wo, Vec3 n) { return -wo + 2 * dot(wo, n) * n; }

// Refraction of wi (pointing away from the surface) through an interface with unit normal n,
// where eta = IOR on the side opposite n / IOR on n's side (pbrt-v4's Refract). wi may lie on
// either side. On success writes the transmitted direction and etap = eta_transmitted /
// eta_incident; returns false on total internal reflection.
inline bool refract(Vec3 wi, Vec3 n, float eta, float* etap, Vec3* wt) {
  float cos_i = dot(n, wi);
  if (cos_i < 0) {
    eta = 1 / eta;
    cos_i = -cos_i;
    n = -n;
  }
  float sin2_t = std::max(0.0f, 1 - cos_i * cos_i) / (eta * eta);
  if (sin2_t >= 1) return false;
  float cos_t = safe_sqrt(1 - sin2_t);
  *wt = -wi / eta + (cos_i / eta - cos_t) * n;
  if (etap) *etap = eta;
  return true;
}

}  // namespace rf
