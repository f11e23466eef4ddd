// The scene overrides `render` and `submit` share.
#include <cstdio>

#include "cli/commands.h"

namespace rf::cli {

namespace {

std::pair<int, int> parse_resolution(const std::string& s) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  if (std::sscanf(s.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
    throw UsageError("--res: expected WIDTHxHEIGHT (e.g. 640x480), got '" + s + "'");
  return {w, h};
}

}  // namespace

void add_override_options(CLI::App& cmd, OverrideArgs& a) {
  cmd.add_option("--spp", a.spp, "samples per pixel (all passes)");
  cmd.add_option("--passes", a.passes, "number of passes (spp must be a multiple)");
  cmd.add_option("--integrator", a.integrator, "integrator name");
  cmd.add_option("--seed", a.seed, "job seed");
  cmd.add_option("--res", a.res, "resolution WIDTHxHEIGHT");
  cmd.add_option("--max-depth", a.max_depth, "max scattering events");
  cmd.add_option("--filter", a.filter, "pixel filter (box, triangle, gaussian)");
  cmd.add_option("--sampler", a.sampler, "sampler (independent, sobol)");
  cmd.add_option("--light-selection", a.light_selection,
                 "light selection for next-event estimation (auto, power, bvh)");
  cmd.add_option("--noise-target", a.noise_target, "stop when relMSE <= this");
  cmd.add_option("--aov", a.aovs,
                 "auxiliary outputs, comma-separated: albedo, normal, depth (docs/outputs.md)");
}

SceneOverrides overrides_of(const OverrideArgs& a) {
  SceneOverrides ov;
  ov.spp = a.spp;
  ov.passes = a.passes;
  ov.seed = a.seed;
  ov.max_depth = a.max_depth;
  ov.noise_target = a.noise_target;
  if (!a.integrator.empty()) ov.integrator = a.integrator;
  if (!a.filter.empty()) ov.filter = a.filter;
  if (!a.sampler.empty()) ov.sampler = a.sampler;
  if (!a.light_selection.empty()) ov.light_selection = a.light_selection;
  if (a.aovs) ov.aovs = *a.aovs;
  if (!a.res.empty()) std::tie(ov.width, ov.height) = parse_resolution(a.res);
  return ov;
}

}  // namespace rf::cli
