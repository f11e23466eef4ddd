// The ppm integrator's settings (scene layer, rayfarm_scene): its keys under render.integrator
// and its part of the settings text. Its estimator is ppm.cpp (renderer).
#include <algorithm>
#include <cstdio>
#include <string>

#include "engine/integrators/ppm.h"
#include "engine/json_reader.h"

namespace rf {

void PpmIntegrator::parse(const JsonReader& r, const Json& j, const std::string& p) {
  // At most 2^24 photons per pass: each costs about 64 bytes in the photon map and its tree, so
  // the cap bounds a pass's map to about 1 GiB (2^28 would ask for 16 GiB and end in bad_alloc).
  if (const Json* v = r.find(j, "photons"))
    photons = int(r.integer(*v, p + ".photons", 1, 1 << 24));
  if (const Json* v = r.find(j, "radius")) {
    radius = r.number(*v, p + ".radius");
    if (radius < 0) r.fail(p + ".radius", "must be >= 0 (0: automatic), got " + v->dump());
  }
  if (const Json* v = r.find(j, "alpha")) {
    alpha = r.number(*v, p + ".alpha");
    if (!(alpha > 0 && alpha < 1)) r.fail(p + ".alpha", "must lie in (0, 1), got " + v->dump());
  }
}

std::string PpmIntegrator::settings_text() const {
  char buf[128];
  std::snprintf(buf, sizeof buf, ";ppm=%d:%.9g:%.9g", photons, double(radius), double(alpha));
  return buf;
}

void PpmIntegrator::from_pbrt(const ForeignParams& p) {
  int per_iteration = p.integer("photonsperiteration", -1);
  photons = std::max(1, per_iteration > 0 ? per_iteration : photons);
  radius = float(p.number("radius", 0));
}

}  // namespace rf
