// BSDF dispatch over the closed set of material kinds (a tag and a switch, CONVENTIONS.md): a
// std::variant of plain lobe structs, one file each in engine/bsdfs/, no virtual calls and no
// heap. Bsdf takes and returns world-space directions, both pointing away from the surface; the
// lobes work in the local shading frame.
//
// Two-sided rule.
// - Diffuse, conductors (smooth and rough), plastic and the thin dielectric are two-sided: they
//   are evaluated with both directions mirrored to wo's side of the shading normal, so a surface
//   looks the same from either side whatever its winding.
// - Dielectrics (smooth and rough) are oriented: the geometric normal ng's side is the outside
//   (IOR 1), the other side the inside (IOR = ior). The shading normal is first turned to ng's
//   side, so vertex normals that disagree with the winding cannot swap inside and outside.
// Geometric consistency (against light leaks through shading normals): a reflection is valid
// only when wo and wi lie on the same side of ng, a transmission only when they lie on opposite
// sides, where "reflection" and "transmission" are decided by the shading normal. Otherwise
// eval() and pdf() return 0 and sample() fails.
//
// Roughness alpha below kSmoothAlpha (1e-3) turns rough conductors and dielectrics into their
// smooth (delta) counterparts and a plastic's coat into a smooth one.
// Non-symmetric BSDFs: only refraction depends on TransportMode (engine/bsdfs/common.h). The
// adjoint correction for shading normals (Veach 1997, section 5.3) is the integrator's business.
#pragma once

#include <variant>

#include "engine/bsdfs/common.h"
#include "engine/bsdfs/conductor.h"
#include "engine/bsdfs/dielectric.h"
#include "engine/bsdfs/diffuse.h"
#include "engine/bsdfs/plastic.h"
#include "engine/bsdfs/rough_conductor.h"
#include "engine/bsdfs/rough_dielectric.h"
#include "engine/bsdfs/thin_dielectric.h"
#include "engine/math.h"
#include "engine/microfacet.h"
#include "engine/scene.h"

namespace rf {

// A material's parameters at one surface point, textures already resolved.
struct BsdfParams {
  MaterialType type = MaterialType::Diffuse;
  RGB reflectance{0.5f};  // diffuse albedo (diffuse, plastic base)
  RGB specular{1.0f};     // conductor F0 in tint mode; dielectric and coat tint
  float alpha = 0;        // GGX roughness (rough conductor / dielectric, plastic coat)
  float ior = 1.5f;       // dielectrics and plastic coat: IOR inside / IOR outside
  RGB eta{1.0f};          // conductor complex IOR, real part
  RGB k{0.0f};            // conductor complex IOR, imaginary part
  bool conductor_tint = false;
  bool separable_masking = false;  // Smith G2 = G1 G1 (microfacet.h)
};

// The material's constant values (ignores its textures).
inline BsdfParams constant_params(const Material& m) {
  return {m.type, m.reflectance.value, m.specular.value,   m.roughness.value, m.ior, m.eta,
          m.k,    m.conductor_tint,    m.separable_masking};
}

class Bsdf {
 public:
  // ns and ng are unit world normals; ng's side is the outside for dielectrics.
  static Bsdf make(const BsdfParams& p, Vec3 ns, Vec3 ng) {
    Bsdf b;
    b.ng_ = ng;
    b.frame_ = shading_frame(ns, ng);
    ConductorFresnel fr{p.eta, p.k, p.specular, p.conductor_tint};
    TrowbridgeReitz tr{p.alpha, p.alpha, p.separable_masking};
    bool smooth = TrowbridgeReitz::effectively_smooth(p.alpha);
    switch (p.type) {
      case MaterialType::Diffuse:
        b.lobe_ = DiffuseBxdf{p.reflectance};
        break;
      case MaterialType::Conductor:
        b.lobe_ = ConductorBxdf{fr};
        break;
      case MaterialType::Dielectric:
        b.lobe_ = DielectricBxdf{p.ior, p.specular};
        break;
      case MaterialType::ThinDielectric:
        b.lobe_ = ThinDielectricBxdf{p.ior, p.specular};
        break;
      case MaterialType::RoughConductor:
        if (smooth)
          b.lobe_ = ConductorBxdf{fr};
        else
          b.lobe_ = RoughConductorBxdf{tr, fr};
        break;
      case MaterialType::RoughDielectric:
        if (smooth)
          b.lobe_ = DielectricBxdf{p.ior, p.specular};
        else
          b.lobe_ = RoughDielectricBxdf{tr, p.ior, p.specular};
        break;
      case MaterialType::Plastic:
        b.lobe_ = PlasticBxdf::make(p.reflectance, p.specular, p.ior, p.alpha);
        break;
    }
    return b;
  }
  RGB eval(Vec3 wo, Vec3 wi, TransportMode mode = TransportMode::Radiance) const {
    Vec3 lo, li;
    if (!to_lobe(wo, wi, lo, li)) return RGB(0.0f);
    return std::visit([&](const auto& l) { return l.eval(lo, li, mode); }, lobe_);
  }
  float pdf(Vec3 wo, Vec3 wi, TransportMode mode = TransportMode::Radiance) const {
    Vec3 lo, li;
    if (!to_lobe(wo, wi, lo, li)) return 0.0f;
    return std::visit([&](const auto& l) { return l.pdf(lo, li, mode); }, lobe_);
  }
  // eval() and pdf() of one pair, the pair moved to the lobe's frame once (next-event
  // estimation needs both); the same values as the two calls.
  RGB eval_pdf(Vec3 wo, Vec3 wi, float& pdf_out,
               TransportMode mode = TransportMode::Radiance) const {
    Vec3 lo, li;
    pdf_out = 0.0f;
    if (!to_lobe(wo, wi, lo, li)) return RGB(0.0f);
    return std::visit(
        [&](const auto& l) {
          pdf_out = l.pdf(lo, li, mode);
          return l.eval(lo, li, mode);
        },
        lobe_);
  }
  // Samples wi given wo; on success s holds wi (world), f, pdf and the lobe's kind.
  bool sample(Vec3 wo, float uc, Vec2 u, TransportMode mode, BsdfSample& s) const {
    Vec3 lo = frame_.to_local(wo);
    if (lo.z == 0) return false;
    bool mirror = two_sided() && lo.z < 0;
    if (mirror) lo.z = -lo.z;
    bool ok = std::visit([&](const auto& l) { return l.sample(lo, uc, u, mode, s); }, lobe_);
    return ok && sample_to_world(frame_, ng_, wo, mirror, s);
  }
  // The pieces of a Bsdf for code that keeps a lobe's frame itself (the path tracer's lanes,
  // whose loops over a packet's diffuse vertices vectorise): the frame make() builds; the end of
  // sample(), which takes the lobe's sample (wo mirrored when `mirror`) to the world and applies
  // the geometric consistency rule; to_lobe().
  static Frame shading_frame(Vec3 ns, Vec3 ng) {
    return Frame::from_normal(dot(ns, ng) < 0 ? -ns : ns);
  }
  static bool sample_to_world(const Frame& frame, Vec3 ng, Vec3 wo, bool mirror, BsdfSample& s) {
    if (mirror) s.wi.z = -s.wi.z;
    s.wi = frame.to_world(s.wi);
    float go = dot(wo, ng), gi = dot(s.wi, ng);
    return s.is_transmission ? go * gi < 0 : go * gi > 0;
  }
  static bool to_lobe(const Frame& frame, Vec3 ng, bool two_sided, Vec3 wo, Vec3 wi, Vec3& lo,
                      Vec3& li) {
    // Selects rather than early returns, so that the lanes' loops vectorise; lo and li are
    // meaningless when it returns false.
    float go = dot(wo, ng), gi = dot(wi, ng);
    lo = frame.to_local(wo);
    li = frame.to_local(wi);
    float g = go * gi, l = lo.z * li.z;
    bool ok = (g != 0) & (l != 0) & ((g > 0) == (l > 0));
    bool mirror = two_sided && lo.z < 0;
    lo.z = mirror ? -lo.z : lo.z;
    li.z = mirror ? -li.z : li.z;
    return ok;
  }
  // Whether sample() reads uc (a lobe choice) and u (a direction); a caller may then skip drawing
  // the one it does not read (Sampler::skip_1d / skip_2d), which leaves every value unchanged.
  bool sample_uses_choice() const {
    return std::visit([](const auto& l) { return std::decay_t<decltype(l)>::kUsesChoice; }, lobe_);
  }
  bool sample_uses_direction() const {
    return std::visit([](const auto& l) { return std::decay_t<decltype(l)>::kUsesDirection; },
                      lobe_);
  }
  // Only delta lobes (smooth conductor, dielectric, thin dielectric): light sampling is useless.
  bool is_delta() const {
    return std::visit([](const auto& l) { return std::decay_t<decltype(l)>::kDelta; }, lobe_);
  }
  // Whether the lobe is Lambertian (the path tracer ends a path at such a vertex of the last depth
  // after its light sample: path/path.cpp).
  bool is_diffuse() const { return std::holds_alternative<DiffuseBxdf>(lobe_); }
  // Whether the lobe can transmit (light from below the surface can leave above it).
  bool transmits() const {
    return std::holds_alternative<DielectricBxdf>(lobe_) ||
           std::holds_alternative<ThinDielectricBxdf>(lobe_) ||
           std::holds_alternative<RoughDielectricBxdf>(lobe_);
  }
  // The geometric normal.
  Vec3 geometric_normal() const { return ng_; }
  // The shading normal, turned to ng's side (for the cosine |dot(wi, ns)|).
  Vec3 shading_normal() const { return frame_.n; }

 private:
  using Lobe = std::variant<DiffuseBxdf, ConductorBxdf, DielectricBxdf, ThinDielectricBxdf,
                            RoughConductorBxdf, RoughDielectricBxdf, PlasticBxdf>;

  bool two_sided() const {
    return std::visit([](const auto& l) { return std::decay_t<decltype(l)>::kTwoSided; }, lobe_);
  }
  // World pair to the lobe's local pair (mirrored for two-sided lobes); false when the pair
  // fails the geometric consistency rule.
  bool to_lobe(Vec3 wo, Vec3 wi, Vec3& lo, Vec3& li) const {
    return to_lobe(frame_, ng_, two_sided(), wo, wi, lo, li);
  }

  Frame frame_;
  Vec3 ng_;
  Lobe lobe_;
};

}  // namespace rf
