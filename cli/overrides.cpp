// The scene overrides `render` and `submit` share, and the checks every command's flags use.
#include <sys/stat.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "cli/commands.h"
#include "engine/integrators/registry.h"
#include "engine/scene.h"

namespace rf::cli {

namespace {

std::pair<int, int> parse_resolution(const std::string& s) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  if (std::sscanf(s.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
    throw UsageError("--res: expected WIDTHxHEIGHT (e.g. 640x480), got '" + s + "'");
  if (w < 1 || h < 1 || w > kMaxResolution || h > kMaxResolution)
    throw UsageError("--res: " + s + ": width and height must be in 1.." +
                     std::to_string(kMaxResolution));
  return {w, h};
}

}  // namespace

uint64_t byte_size_option(const std::string& name, const std::string& v) {
  size_t end = 0;
  unsigned long long n = 0;
  bool ok = !v.empty() && std::isdigit(static_cast<unsigned char>(v[0]));
  try {
    if (ok) n = std::stoull(v, &end);
  } catch (const std::exception&) {
    ok = false;
  }
  const std::string unit = ok ? v.substr(end) : "";
  const int shift = unit.empty()  ? 0
                    : unit == "K" ? 10
                    : unit == "M" ? 20
                    : unit == "G" ? 30
                    : unit == "T" ? 40
                                  : -1;
  if (!ok || shift < 0 || (shift > 0 && n > (~0ull >> shift)))
    throw CLI::ValidationError(name, "'" + v + "' is not a size (bytes, or 512M, 20G, 1T)");
  return uint64_t(n) << shift;
}

CLI::Validator finite_in(double lo, double hi) {
  char desc[96];
  std::snprintf(desc, sizeof desc, "NUMBER in [%g, %g]", lo, hi);
  return CLI::Validator(
      [lo, hi](std::string& s) -> std::string {
        char* end = nullptr;
        double v = std::strtod(s.c_str(), &end);
        if (s.empty() || end == s.c_str() || *end != 0) return "'" + s + "' is not a number";
        if (!std::isfinite(v) || v < lo || v > hi) {
          char buf[128];
          std::snprintf(buf, sizeof buf, "%s is outside [%g, %g]", s.c_str(), lo, hi);
          return buf;
        }
        return "";
      },
      desc);
}

void check_outputs(const std::vector<std::pair<std::string, std::string>>& outputs) {
  namespace fs = std::filesystem;
  std::vector<std::pair<std::string, fs::path>> seen;
  for (const auto& [flag, path] : outputs) {
    if (path.empty()) continue;
    if (path.find('\0') != std::string::npos) throw UsageError(flag + ": the path holds a NUL");
    struct stat st {};
    if (::stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode))
      throw UsageError(flag + ": " + path +
                       " exists and is not a regular file (a device, FIFO or directory); "
                       "refusing to replace it");
    fs::path abs = fs::weakly_canonical(fs::absolute(path));
    for (const auto& [other_flag, other] : seen)
      if (abs == other)
        throw UsageError(flag + " and " + other_flag + " name the same file " + path +
                         "; one would overwrite the other");
    seen.emplace_back(flag, abs);
  }
}

void check_extension(const std::string& flag, const std::string& path,
                     const std::vector<std::string>& allowed) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  std::string list;
  for (const std::string& a : allowed) {
    if (ext == a) return;
    list += (list.empty() ? "" : " or ") + a;
  }
  throw UsageError(flag + ": " + path + " must end in " + list +
                   (ext == ".png" ? " (the PNG preview is written beside the .exr)" : ""));
}

void add_override_options(CLI::App& cmd, OverrideArgs& a) {
  cmd.add_option("--spp", a.spp, "samples per pixel (all passes)")->check(finite_in(1, 1e12));
  cmd.add_option("--passes", a.passes, "number of passes (spp must be a multiple)")
      ->check(finite_in(1, 1e6));
  auto joined = [](const std::vector<std::string>& names) {
    std::string out;
    for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
    return out;
  };
  cmd.add_option("--integrator", a.integrator, "integrator (" + joined(known_integrators()) + ")");
  cmd.add_option("--seed", a.seed, "job seed")->check(finite_in(0, 1.8e19));
  cmd.add_option("--res", a.res, "resolution WIDTHxHEIGHT");
  cmd.add_option("--max-depth", a.max_depth, "max scattering events")->check(finite_in(0, 1e6));
  cmd.add_option("--filter", a.filter, "pixel filter (" + joined(known_filters()) + ")");
  cmd.add_option("--sampler", a.sampler, "sampler (independent, sobol, sobol-sequence)");
  cmd.add_option("--light-selection", a.light_selection,
                 "light selection for next-event estimation (auto, power, bvh)");
  cmd.add_option("--noise-target", a.noise_target, "stop when relMSE <= this")
      ->check(finite_in(0, 1e6));
  cmd.add_option("--shutter", a.shutter,
                 "shutter OPEN,CLOSE in frames from each frame's start (0,0.5), or one instant "
                 "(0); overrides the scene's time.shutter (scenes where something moves)");
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
  if (!a.shutter.empty()) ov.shutter = a.shutter;
  if (a.aovs) ov.aovs = *a.aovs;
  if (!a.res.empty()) std::tie(ov.width, ov.height) = parse_resolution(a.res);
  try {
    check_overrides(ov);  // a bad flag is a usage error (exit 2), before any scene is read
  } catch (const SceneError& e) {
    throw UsageError(e.what());
  }
  return ov;
}

}  // namespace rf::cli
