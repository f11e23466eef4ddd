// The direct integrator's settings (scene layer, rayfarm_scene): its keys under render.integrator
// and its part of the settings text. Its estimator is direct.cpp (renderer).
#include <cstdio>
#include <string>

#include "engine/integrators/direct.h"
#include "engine/json_reader.h"

namespace rf {

void DirectIntegrator::parse(const JsonReader& r, const Json& j, const std::string& p) {
  if (const Json* v = r.find(j, "strategy")) {
    std::string s = r.string(*v, p + ".strategy");
    if (s == "light")
      strategy = Strategy::Light;
    else if (s == "bsdf")
      strategy = Strategy::Bsdf;
    else if (s == "mis")
      strategy = Strategy::Mis;
    else
      r.fail(p + ".strategy", "expected \"light\", \"bsdf\" or \"mis\", got '" + s + "'");
  }
  if (const Json* v = r.find(j, "heuristic")) {
    std::string s = r.string(*v, p + ".heuristic");
    if (s != "power" && s != "balance")
      r.fail(p + ".heuristic", "expected \"power\" or \"balance\", got '" + s + "'");
    power_heuristic = s == "power";
  }
  if (const Json* v = r.find(j, "light_samples"))
    light_samples = int(r.integer(*v, p + ".light_samples", 0, 1 << 16));
  if (const Json* v = r.find(j, "bsdf_samples"))
    bsdf_samples = int(r.integer(*v, p + ".bsdf_samples", 0, 1 << 16));
  if (light_samples + bsdf_samples == 0)
    r.fail(p, "light_samples and bsdf_samples cannot both be 0");
}

std::string DirectIntegrator::settings_text() const {
  char buf[128];
  std::snprintf(buf, sizeof buf, ";direct=%d:%s:%d:%d", int(strategy),
                power_heuristic ? "power" : "balance", light_samples, bsdf_samples);
  return buf;
}

void DirectIntegrator::from_mitsuba(const ForeignParams& p) {
  int shading = p.integer("shading_samples", 1);
  light_samples = p.integer("emitter_samples", shading);
  bsdf_samples = p.integer("bsdf_samples", shading);
  if (light_samples < 0 || bsdf_samples < 0 || light_samples + bsdf_samples == 0)
    p.fail("emitter_samples and bsdf_samples must be >= 0 and not both 0");
}

}  // namespace rf
