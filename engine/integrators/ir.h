// Instant radiosity with a clamped geometry term and its compensation (`ir`).
//
// Estimator (Keller 1997; Kollig & Keller 2004, "Illumination in the presence of weak
// singularities"). Per pass, N light paths (light by power, importance-mode BSDFs, shading
// normals corrected as in light.cpp) leave a virtual point light (VPL) at every non-delta surface
// vertex y: its BSDF, the direction the light arrived from, its throughput / N and its depth k
// (scattering events on the light path up to and including y). The camera path follows delta
// BSDFs to a non-delta vertex x; there
//   L(x) = Le(x) + direct(x) [next-event estimation, MIS with the BSDF sample, as path/path.cpp]
//        + sum_j f_x f_yj Phi_j V min(G, b)     G = |w.ns_x| |w.ng_y| / |x - y|^2
//        + compensation.
// The VPL sum is estimated from M VPLs (vpl_samples) picked by resampled importance sampling
// (Talbot et al. 2005): per pick, K candidates (vpl_candidates) are drawn by weight (power x
// albedo) from the pass's alias table, one is kept with probability proportional to the target
// g = min(b, G) with both cosines at x (0 when either side faces away), and its term is weighted
// by W sum_k g_k / (K weight_y g_y) (W: total weight). The picks' candidates stratify the table
// together, so the mean of the M picks is unbiased given the VPLs. Cost per camera vertex: M K
// table reads and M shadow rays, whatever the number of VPLs (vpl_samples 0: the full sum, a
// shadow ray per VPL, kept as the reference the picks are tested against).
// The VPLs estimate the indirect light with G clamped at b = 1 / d_c^2, which removes the bright
// splotches near VPLs (the weak singularity). The clamped part, the integral of f_x (G - b)^+ V
// Ls(y), is recovered by the BSDF sample of x: it is traced to y, and y's non-delta terms (its
// direct light, its VPL gather, its own continuation) are weighted by (1 - b / G(x, y))^+, which
// is 0 for most samples, so the continuation usually ends there. Light that y scatters by a delta
// lobe, and anything seen through delta vertices, is not covered by the VPLs and is followed with
// full weight. Hence the estimator is unbiased and converges to path's image at the same max
// depth: a VPL of depth k gathered at a camera vertex with d scattering events before it makes a
// path of d + 1 + k events, and it is used only when that is at most max_depth (Russian roulette
// as the path tracer on the continuation).
// Compensation off: the (G - b)^+ part is dropped, i.e. the clamped light is lost. The image is
// then biased: darker, in concave corners and wherever surfaces see each other from closer than
// d_c. Measured on the Cornell box (box 2 wide, tests/ir_ppm_test.cpp): image means 0.6% / 0.5% /
// 0.3% (R, G, B) darker at the default d_c (0.17), 5.3% / 4.0% / 2.3% at d_c = 1.
// Parameters: max_depth, rr_min_depth, vpl_paths (N, light paths per pass; default 4096),
// vpl_samples (M, VPLs per camera vertex; default 1; 0: every VPL), vpl_candidates (K, per pick;
// default 32), clamp_distance (d_c; 0 picks 0.1 x the scene's bounding radius), compensation
// (default true).
// Per-pass state: the VPL list of pass p and its alias table, a pure function of (scene, settings,
// p): light path i is keyed by (seed, frame, p, i) and paths are traced in fixed chunks
// concatenated in order. It is shared read-only by the tiles of the pass; each pass is an
// independent estimate. On the Cornell box it is far faster per sample than the full sum over the
// VPLs, and at equal time it reaches path's MSE with a lower relMSE (docs/integrators.md,
// "Instant radiosity: what was measured and changed (issue 12)").
// Strengths: smooth, low-noise indirect light in diffuse scenes; thousands of VPLs per pass at a
// cost per pixel independent of their number, of the light's size and of its visibility.
// Limits: VPL noise is correlated across the image within a pass (low-frequency blotches, not
// pixel noise): error bars need batch means over passes, not per-pixel variances summed; the
// target ignores visibility and BSDF lobes (glossy VPLs and receivers are picked as if diffuse)
// and max_depth (a VPL too deep for the path is picked and adds 0); glossy receivers are poorly
// served by VPLs and rely on the compensation path.
// Environment and directional lights start their VPL paths on a disk outside the scene facing the
// light (LightSet::sample_emission, as pbrt-v4); their direct light is next-event estimation's, and
// a camera path that leaves the scene takes the environment's radiance (MIS-weighted).
#pragma once

#include <string>

#include "engine/integrators/module.h"

namespace rf {

struct IrIntegrator : IntegratorDefaults {
  static constexpr const char* kName = "ir";
  static constexpr bool kMovingGeometry = false;  // see IntegratorDefaults
  static constexpr bool kSplats = false;
  static constexpr const char* kKeys[] = {"type",           "max_depth",   "rr_min_depth",
                                          "vpl_paths",      "vpl_samples", "vpl_candidates",
                                          "clamp_distance", "compensation"};
  // Bounds of the two parameters that size the estimator's stack arrays.
  static constexpr int kMaxVplSamples = 64;
  static constexpr int kMaxVplCandidates = 256;

  int vpl_paths = 4096;      // light paths per pass depositing virtual point lights
  float clamp_distance = 0;  // G is clamped at 1 / d^2; 0: 0.1 x LightSet::scene_radius()
  bool compensation = true;  // recover the clamped part (unbiased) or drop it (biased)
  int vpl_samples = 1;       // VPLs picked per camera vertex (resampled); 0: all of them
  int vpl_candidates = 32;   // candidates drawn by weight per pick

  void parse(const JsonReader& r, const Json& j, const std::string& path);
  std::string settings_text() const;
  void check(const Scene& scene) const;

  SampleBuffer render(const RenderContext& ctx, const TaskKey& task, bool parallel) const;
  bool operator==(const IrIntegrator&) const = default;
};

}  // namespace rf
