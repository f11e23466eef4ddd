// Types shared by the BSDF lobes in engine/bsdfs/ and the dispatch in engine/bsdf.h.
//
// Every lobe works in the local shading frame: z is the shading normal, which engine/bsdf.h
// orients to the outside (the geometric normal's side). Two-sided lobes (diffuse, conductors,
// plastic, thin dielectric) are only ever called with wo.z > 0: the dispatch mirrors both
// directions to wo's side first. Oriented lobes (dielectrics) see wo on either side.
// A lobe's sample() fills BsdfSample in local coordinates; the dispatch turns wi to world.
#pragma once

#include <cstdint>

#include "engine/math.h"

namespace rf {

// Which quantity a path carries: radiance (camera paths) or importance (light paths). Only
// refraction differs: radiance is compressed by (eta_i / eta_t)^2 crossing an interface,
// importance is not (Veach 1997, section 5.2), so the importance-mode BTDF is the adjoint.
enum class TransportMode : uint8_t { Radiance, Importance };

struct BsdfSample {
  Vec3 wi;  // world space (local inside engine/bsdfs/)
  RGB f;    // BSDF value f(wo, wi) (for delta lobes: the factor of the delta in solid angle)
  float pdf_solid_angle = 0;  // for delta lobes: the discrete probability of choosing the lobe
  bool is_delta = false;
  bool is_transmission = false;
  // Relative IOR crossed, eta_t / eta_i (the IOR on wi's side over the IOR on wo's side) for a
  // refraction, 1 otherwise. Radiance-mode refraction divides f by eta^2; pbrt-v4's Russian
  // roulette multiplies its etaScale by eta^2 to undo that in the survival probability.
  float eta = 1;
};

inline float abs_cos_theta(Vec3 w) { return std::fabs(w.z); }
inline bool same_hemisphere(Vec3 a, Vec3 b) { return a.z * b.z > 0; }

}  // namespace rf
