// BSDF dispatch over a closed set of kinds (a tag and a switch; CONVENTIONS.md). Directions are
// in the local shading frame, z = shading normal, oriented to the side of wo.
//
// Two-sided rule: every BSDF here is two-sided. The shading frame is flipped to the side wo
// arrives from, and a reflection is only valid when wi and wo lie on the same side of the
// *geometric* normal too, so shading normals cannot leak light through a surface.
#pragma once

#include "engine/math.h"
#include "engine/sampling.h"
#include "engine/scene.h"

namespace rf {

struct BsdfSample {
  Vec3 wi;            // local
  RGB f;              // BSDF value
  float pdf_solid_angle = 0;
  bool is_delta = false;
};

// The diffuse (Lambertian) BSDF: f = R / pi, sampled cosine-weighted.
struct DiffuseBsdf {
  RGB reflectance;
  RGB eval(Vec3 wo, Vec3 wi) const {
    if (wo.z <= 0 || wi.z <= 0) return RGB(0.0f);
    return reflectance * kInvPi;
  }
  float pdf(Vec3 wo, Vec3 wi) const {
    if (wo.z <= 0 || wi.z <= 0) return 0.0f;
    return cosine_hemisphere_pdf(wi.z);
  }
  bool sample(Vec3 wo, Vec2 u, BsdfSample& s) const {
    if (wo.z <= 0) return false;
    s.wi = sample_cosine_hemisphere(u);
    s.pdf_solid_angle = cosine_hemisphere_pdf(s.wi.z);
    if (s.pdf_solid_angle <= 0) return false;
    s.f = reflectance * kInvPi;
    s.is_delta = false;
    return true;
  }
};

// A BSDF at a surface point: the material's lobe plus the shading frame.
struct Bsdf {
  MaterialType type = MaterialType::Diffuse;
  DiffuseBsdf diffuse;
  Frame frame;  // shading frame, n on the side of wo
  Vec3 ng;      // geometric normal, flipped to the side of wo

  static Bsdf at(const Material& m, Vec3 ns, Vec3 ng, Vec3 wo_world) {
    Bsdf b;
    b.type = m.type;
    b.diffuse.reflectance = m.reflectance.value;
    bool flip = dot(wo_world, ng) < 0;
    b.ng = flip ? -ng : ng;
    b.frame = Frame::from_normal(flip ? -ns : ns);
    return b;
  }
  // Same side of the geometric surface (reflection only, for now).
  bool geometric_reflection(Vec3 wo_world, Vec3 wi_world) const {
    return dot(wo_world, ng) > 0 && dot(wi_world, ng) > 0;
  }
  RGB eval(Vec3 wo_world, Vec3 wi_world) const {
    if (!geometric_reflection(wo_world, wi_world)) return RGB(0.0f);
    return diffuse.eval(frame.to_local(wo_world), frame.to_local(wi_world));
  }
  float pdf(Vec3 wo_world, Vec3 wi_world) const {
    if (!geometric_reflection(wo_world, wi_world)) return 0.0f;
    return diffuse.pdf(frame.to_local(wo_world), frame.to_local(wi_world));
  }
  // Samples wi (returned in world space in s.wi).
  bool sample(Vec3 wo_world, Vec2 u, BsdfSample& s) const {
    if (!diffuse.sample(frame.to_local(wo_world), u, s)) return false;
    s.wi = frame.to_world(s.wi);
    return geometric_reflection(wo_world, s.wi);
  }
};

}  // namespace rf
