// The ao integrator's settings (scene layer, rayfarm_scene): its keys under render.integrator
// and its part of the settings text. Its estimator is ao.cpp (renderer).
#include <cstdio>
#include <string>

#include "engine/integrators/ao.h"
#include "engine/json_reader.h"

namespace rf {

void AoIntegrator::parse(const JsonReader& r, const Json& j, const std::string& p) {
  if (const Json* v = r.find(j, "max_distance")) {
    max_distance = r.number(*v, p + ".max_distance");
    if (!(max_distance > 0)) r.fail(p + ".max_distance", "must be > 0, got " + v->dump());
  }
  if (const Json* v = r.find(j, "sampling")) {
    std::string s = r.string(*v, p + ".sampling");
    if (s != "cosine" && s != "uniform")
      r.fail(p + ".sampling", "expected \"cosine\" or \"uniform\", got '" + s + "'");
    cosine = s == "cosine";
  }
  if (const Json* v = r.find(j, "samples"))
    samples = int(r.integer(*v, p + ".samples", 1, 1 << 16));
}

std::string AoIntegrator::settings_text() const {
  char buf[128];
  std::snprintf(buf, sizeof buf, ";ao=%g:%s:%d", double(max_distance),
                cosine ? "cosine" : "uniform", samples);
  return buf;
}

void AoIntegrator::from_pbrt(const ForeignParams& p) {
  cosine = p.boolean("cossample", true);
  double d = p.number("maxdistance", 1e30);
  max_distance = d >= 1e30 ? kInf : float(d);
}

}  // namespace rf
