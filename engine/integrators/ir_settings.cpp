// The ir integrator's settings (scene layer, rayfarm_scene): its keys under render.integrator
// and its part of the settings text. Its estimator is ir.cpp (renderer).
#include <cstdio>
#include <string>

#include "engine/integrators/ir.h"
#include "engine/json_reader.h"
#include "engine/scene.h"

namespace rf {

void IrIntegrator::parse(const JsonReader& r, const Json& j, const std::string& p) {
  if (const Json* v = r.find(j, "vpl_paths"))
    vpl_paths = int(r.integer(*v, p + ".vpl_paths", 1, 1 << 24));
  if (const Json* v = r.find(j, "vpl_samples"))
    vpl_samples = int(r.integer(*v, p + ".vpl_samples", 0, kMaxVplSamples));
  if (const Json* v = r.find(j, "vpl_candidates"))
    vpl_candidates = int(r.integer(*v, p + ".vpl_candidates", 1, kMaxVplCandidates));
  if (const Json* v = r.find(j, "clamp_distance")) {
    clamp_distance = r.number(*v, p + ".clamp_distance");
    if (clamp_distance < 0)
      r.fail(p + ".clamp_distance", "must be >= 0 (0: automatic), got " + v->dump());
  }
  if (const Json* v = r.find(j, "compensation")) compensation = r.boolean(*v, p + ".compensation");
}

// "v2": the estimator of issue 12 (resampled VPL picks); buffers of older builds, whose settings
// text had no version, never merge with these.
std::string IrIntegrator::settings_text() const {
  char buf[160];
  std::snprintf(buf, sizeof buf, ";ir=v2:%d:%d:%d:%.9g:%s", vpl_paths, vpl_samples, vpl_candidates,
                double(clamp_distance), compensation ? "comp" : "nocomp");
  return buf;
}

void IrIntegrator::check(const Scene& scene) const {
  if (vpl_samples < 0 || vpl_samples > kMaxVplSamples || vpl_candidates < 1 ||
      vpl_candidates > kMaxVplCandidates)
    throw SceneError(scene.path + ": render.integrator: ir's vpl_samples must be in [0, " +
                     std::to_string(kMaxVplSamples) + "] and vpl_candidates in [1, " +
                     std::to_string(kMaxVplCandidates) + "]");
}

}  // namespace rf
