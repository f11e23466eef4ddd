// Bidirectional path tracing with multiple importance sampling (`bdpt`).
//
// Estimator (Veach 1997, ch. 10; Veach & Guibas 1995; pbrt-v3 section 16.3): each camera sample
// traces a camera subpath z_0 (the lens) ... z_{t-1} and a light subpath y_0 (on a light) ...
// y_{s-1}, then joins every prefix pair into a full path of s + t vertices:
//   s = 0        the camera subpath itself hit an emitter (area light, or escaped into the
//                environment);
//   s = 1        a light point is sampled afresh from z_{t-1} by LightSet::sample (next-event
//                estimation, the only way to reach directional lights and the environment);
//   t = 1        y_{s-1} is joined to a lens point (PerspectiveCamera::connect) and the result
//                is a splat at the raster point it reaches, weighted by the pixel filter and
//                carrying W_e's pixel-count factor (as light tracing);
//   s, t >= 2    a shadow ray joins y_{s-1} and z_{t-1}.
// Every strategy with s + t - 2 <= max_depth (pbrt-v4's depth, DESIGN.md) contributes, except
// (s, t) = (1, 1): a light seen directly is the (0, 2) strategy alone. The contributions of one
// path length are combined with the power heuristic (beta = 2) over every strategy that could
// have produced the path, computed by pbrt-v3's MISWeight: each vertex stores the area densities
// pdf_fwd (how its own subpath sampled it) and pdf_rev (how the other direction would), the
// connection vertices' pdf_rev are recomputed per strategy, and the weight is
// 1 / (1 + sum over other strategies of (p_other / p_this)^2), the ratios accumulated one vertex
// at a time. Delta BSDF vertices (mirror, glass, a smooth plastic coat's sampled lobe) have pdfs
// 0: strategies that would connect at them are skipped in the sum and never evaluated. Delta
// lights (point, spot, directional) cannot be hit: s = 0 does not exist for them.
// Lights at infinity (environment, directional) start no light subpaths here (light, ir and ppm
// start theirs on a disk outside the scene; BDPT asks sample_emission without, so a pick of one
// gives an empty light subpath), so their paths have only the s = 0 (environment
// only) and s = 1 strategies; the MIS sums treat s >= 2 as impossible for such paths, so the
// weights of the strategies that exist still sum to 1 (for the environment this is exactly the
// path tracer's light/BSDF MIS).
// The light subpath belongs to its camera sample: its random numbers come from the same Sampler
// after the camera subpath's (then the connections' own: light selection and point for s = 1,
// lens point for t = 1), so a pass renders the same anywhere. Shading normals are corrected in
// the light subpath's BSDFs (Veach 1997, 5.3) as in light tracing.
// Russian roulette (after rr_min_depth bounces, on throughput relative to the subpath's start;
// camera subpaths also undo refraction's radiance scaling, as path) ends subpaths early; the MIS
// weights use the sampling densities without the survival probabilities, which keeps every
// strategy unbiased (the weights still sum to 1 over the strategies of each path) at a small
// cost in variance.
// Memory: subpaths live in two per-thread vertex arrays that grow to the longest subpath the
// thread has seen (at most max_depth + 2 camera and max_depth + 1 light vertices) and are reused:
// no allocation per path once a thread has traced its longest one, and no cap on max_depth.
// Parameters: max_depth D, rr_min_depth. Per-strategy images (weighted and unweighted, Veach's
// figures): BdptStrategyRecorder below (tests/support/bdpt_strategies.h renders them).
// Strengths: caustics seen directly or on diffuse surfaces (light -> specular -> diffuse ->
// camera, via t = 1 and s >= 2), light arriving through small openings or from hidden lights
// (light subpaths find the lit regions, connections do the rest), everything the path tracer
// does well it does as well (its strategies are among BDPT's).
// Cannot do: paths whose only non-delta vertex pair is missing, e.g. a caustic from a point light
// seen through a mirror (light -> specular -> diffuse -> specular -> camera: no strategy can
// connect), and reflected caustics of small lights remain noisy (that needs photon mapping or
// vertex merging). Infinite lights get only the path tracer's two strategies. A camera sample
// costs several path-tracer samples (two subpaths plus O(s t) shadow rays): on the Cornell box
// (directly lit, the path tracer's home ground) BDPT's lower relMSE per sample does not pay for
// that, so at equal time path wins (docs/performance.md, "What was tried and not taken"); in a
// room lit indirectly by a point light with glass and a mirror BDPT wins by far at equal time
// (tests/bdpt_test.cpp prints both).
#pragma once

#include <string>

#include "engine/frame.h"
#include "engine/integrators/module.h"
#include "engine/math.h"

namespace rf {

struct BdptIntegrator : IntegratorDefaults {
  static constexpr const char* kName = "bdpt";
  static constexpr bool kSplats = true;
  static constexpr const char* kKeys[] = {"type", "max_depth", "rr_min_depth"};
  static constexpr const char* kPbrtTypes = "bdpt";
  static constexpr const char* kMitsubaTypes = "bdpt";

  SampleBuffer render(const RenderContext& ctx, const TaskKey& task, bool parallel) const;
  bool operator==(const BdptIntegrator&) const = default;
};

class Sampler;
struct Ray;
struct SplatTarget;
struct TraceCounters;

// Receives every strategy's contribution of one camera sample, for per-strategy images (Veach
// 1997, figures 10.3-10.4). `s` light and `t` camera subpath vertices: path depth s + t - 2.
class BdptStrategyRecorder {
 public:
  virtual ~BdptStrategyRecorder() = default;
  // A t >= 2 strategy's contribution to the sample's own pixel: MIS-weighted, and alone.
  virtual void camera(int s, int t, RGB weighted, RGB unweighted) = 0;
  // A t = 1 strategy's contribution arriving at `raster` (as given to splat_to_film).
  virtual void splat(int s, int t, Vec2 raster, RGB weighted, RGB unweighted) = 0;
};

// One BDPT camera sample through `ray` (the sampler started for it, filter and lens dimensions
// drawn): returns what lands in the sample's own pixel (strategies t >= 2) and splats the t = 1
// strategies into `splats`, with a moving camera placed at the ray's time in frame `frame`. A
// recorder, when given, sees every strategy's contribution.
RGB bdpt_camera_sample(const RenderContext& ctx, Ray ray, Sampler& sampler, SplatTarget& splats,
                       TraceCounters& counters, FrameNumber frame,
                       BdptStrategyRecorder* recorder = nullptr);

}  // namespace rf
