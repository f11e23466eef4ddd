// The GGX / Trowbridge-Reitz microfacet distribution shared by the rough BSDFs.
//
// Model: normal distribution D(wm) = 1 / (pi ax ay (x^2/ax^2 + y^2/ay^2 + z^2)^2) in the local
// shading frame (z = macro normal), normalised so that int D(wm) cos(theta_m) dwm = 1.
// Smith masking Lambda(w) = (sqrt(1 + (ax^2 x^2 + ay^2 y^2) / z^2) - 1) / 2, G1 = 1 / (1 + Lambda),
// and the height-correlated masking-shadowing G2 = 1 / (1 + Lambda(wo) + Lambda(wi)), as pbrt-v4;
// or, with `separable`, Smith's separable G2 = G1(wo) G1(wi), as Mitsuba 3 (never larger: up to a
// few percent darker at high roughness and grazing angles; the Mitsuba importer asks for it so
// that an imported scene renders as Mitsuba renders it).
// Sampling: the distribution of visible normals D_w(wm) = G1(w) / |cos w| D(wm) max(0, w.wm)
// (Heitz 2018, "Sampling the GGX Distribution of Visible Normals"), for w on either side (it is
// mirrored to the upper hemisphere; sampled normals always have z > 0).
// Parameters: alpha_x, alpha_y (isotropic materials use alpha_x = alpha_y = roughness). Below
// kSmoothAlpha a surface is treated as smooth (delta lobes) because D is no longer representable
// in float precision.
// References: Walter et al. 2007, "Microfacet Models for Refraction through Rough Surfaces";
// Heitz 2014, "Understanding the Masking-Shadowing Function"; pbrt-v4 section 9.6.
// Limits: single scattering only, so energy is lost at high roughness (measured in
// tests/bsdf_test.cpp, RoughConductor.EnergyLoss).
#pragma once

#include <cmath>

#include "engine/math.h"
#include "engine/sampling.h"

namespace rf {

inline constexpr float kSmoothAlpha = 1e-3f;

struct TrowbridgeReitz {
  float alpha_x = 0.1f, alpha_y = 0.1f;
  bool separable = false;  // G2 = G1 G1 instead of height-correlated

  static bool effectively_smooth(float alpha) { return alpha < kSmoothAlpha; }

  // Selects rather than early returns in what the path tracer's lanes call (their loops then
  // vectorise): the same values.
  // Microfacet normal density per unit solid angle; 0 for wm in the lower hemisphere.
  float D(Vec3 wm) const {
    float e = sqr(wm.x / alpha_x) + sqr(wm.y / alpha_y) + sqr(wm.z);
    return wm.z <= 0 ? 0.0f : 1.0f / (kPi * alpha_x * alpha_y * e * e);
  }
  // Smith's auxiliary function (depends on |w.z| only through tan^2(theta)).
  float lambda(Vec3 w) const {
    float a2tan2 = (sqr(alpha_x * w.x) + sqr(alpha_y * w.y)) / sqr(w.z);
    return w.z == 0 ? kInf : 0.5f * (std::sqrt(1 + a2tan2) - 1);
  }
  float G1(Vec3 w) const { return 1 / (1 + lambda(w)); }
  float G2(Vec3 wo, Vec3 wi) const {
    const float g_separable = G1(wo) * G1(wi), g_correlated = 1 / (1 + lambda(wo) + lambda(wi));
    return separable ? g_separable : g_correlated;
  }

  // G1(w) / |cos w| written without the division, so it stays finite at grazing angles.
  float G1_over_cos(Vec3 w) const {
    float c = std::fabs(w.z);
    return 2 / (c + std::sqrt(sqr(w.z) + sqr(alpha_x * w.x) + sqr(alpha_y * w.y)));
  }
  // Density of normals visible from w, per unit solid angle of wm: integrates to 1 over wm.
  float D_visible(Vec3 w, Vec3 wm) const {
    float c = w.z < 0 ? -dot(w, wm) : dot(w, wm);
    return c <= 0 ? 0.0f : G1_over_cos(w) * D(wm) * c;
  }

  // Samples a normal from D_visible(w, .) (Heitz 2018, listing 1).
  Vec3 sample_visible_normal(Vec3 w, Vec2 u) const {
    float cos_phi, sin_phi;
    visible_normal_phi(u, cos_phi, sin_phi);
    return sample_visible_normal(w, u.x, cos_phi, sin_phi);
  }
  // The pieces of it for the path tracer's lanes, which run them in vectorised loops (selects, no
  // branches, no library calls): the cosine and sine of the sample's phi = 2 pi u.y, then the rest.
  static void visible_normal_phi(Vec2 u, float& cos_phi, float& sin_phi) {
    cos_sin_turn(u.y, cos_phi, sin_phi);
  }
  Vec3 sample_visible_normal(Vec3 w, float ux, float cos_phi, float sin_phi) const {
    w = vselect(w.z < 0, -w, w);
    Vec3 vh = normalize(Vec3(alpha_x * w.x, alpha_y * w.y, w.z));  // stretch to alpha = 1
    float lensq = vh.x * vh.x + vh.y * vh.y;
    Vec3 t1 = vselect(lensq > 0, Vec3(-vh.y, vh.x, 0) / std::sqrt(lensq), Vec3(1, 0, 0));
    Vec3 t2 = cross(vh, t1);
    // Uniform point on the unit disk, then warp its lower half onto the projected hemisphere.
    float r = std::sqrt(ux);
    float p1 = r * cos_phi, p2 = r * sin_phi;
    float s = 0.5f * (1 + vh.z);
    p2 = (1 - s) * safe_sqrt(1 - p1 * p1) + s * p2;
    Vec3 nh = p1 * t1 + p2 * t2 + safe_sqrt(1 - p1 * p1 - p2 * p2) * vh;
    return normalize(Vec3(alpha_x * nh.x, alpha_y * nh.y, std::max(1e-6f, nh.z)));  // unstretch
  }
};

}  // namespace rf
