#include "engine/formats/pbrt/pbrt_spectra.h"

#include <algorithm>
#include <cmath>

#include "engine/formats/spectrum.h"
#include "engine/scene.h"

namespace rf::pbrt {

namespace {

RGB clamp_negative(RGB c) {
  return {std::max(0.0f, c.x), std::max(0.0f, c.y), std::max(0.0f, c.z)};
}

}  // namespace

RGB blackbody_rgb(double kelvin) {
  const double c2 = 1.4387769e-2;  // h c / k_B in m K
  Vec3 xyz = integrate_xyz([&](double nm) {
    double l = nm * 1e-9;
    return 1.0 / (std::pow(l, 5.0) * (std::exp(c2 / (l * kelvin)) - 1.0));
  });
  if (!(xyz.y > 0)) return RGB(0.0f);
  return clamp_negative(xyz_to_srgb(xyz / xyz.y));
}

RGB sampled_spectrum_rgb(const std::vector<double>& pairs, bool illuminant) {
  auto value = [&](double nm) {
    size_t n = pairs.size() / 2;
    if (n == 0) return 0.0;
    if (nm <= pairs[0]) return pairs[1];
    if (nm >= pairs[2 * (n - 1)]) return pairs[2 * (n - 1) + 1];
    for (size_t i = 0; i + 1 < n; ++i) {
      double l0 = pairs[2 * i], l1 = pairs[2 * i + 2];
      if (nm <= l1) {
        double t = l1 > l0 ? (nm - l0) / (l1 - l0) : 0.0;
        return pairs[2 * i + 1] * (1 - t) + pairs[2 * i + 3] * t;
      }
    }
    return pairs.back();
  };
  Vec3 xyz = integrate_xyz(value);
  if (illuminant) return xyz.y > 0 ? clamp_negative(xyz_to_srgb(xyz / xyz.y)) : RGB(0.0f);
  RGB white = xyz_to_srgb(integrate_xyz([](double) { return 1.0; }));
  RGB c = xyz_to_srgb(xyz);
  return clamp_negative(RGB(c.x / white.x, c.y / white.y, c.z / white.z));
}

std::optional<RGB> named_spectrum_rgb(const std::string& name, bool illuminant) {
  static const std::pair<const char*, const char*> metals[] = {
      {"Au", "gold"}, {"Ag", "silver"}, {"Cu", "copper"}, {"Al", "aluminium"}};
  for (auto [symbol, preset] : metals) {
    std::string stem = std::string("metal-") + symbol + "-";
    if (name == stem + "eta") return conductor_preset(preset)->eta;
    if (name == stem + "k") return conductor_preset(preset)->k;
  }
  if (name == "stdillum-D65") return RGB(1.0f);
  if (name == "stdillum-A") return illuminant ? blackbody_rgb(2856.0) : std::optional<RGB>{};
  if (std::optional<float> ior = named_glass_ior(name)) return RGB(*ior);
  return std::nullopt;
}

std::optional<float> named_glass_ior(const std::string& name) {
  // Schott's catalogue n_d (587.56 nm).
  static const std::pair<const char*, float> glasses[] = {
      {"glass-BK7", 1.5168f},   {"glass-BAF10", 1.6700f}, {"glass-FK51A", 1.4866f},
      {"glass-LASF9", 1.8503f}, {"glass-F5", 1.6034f},    {"glass-SF5", 1.6727f},
      {"glass-SF10", 1.7283f},  {"glass-SF11", 1.7847f}};
  for (auto [n, ior] : glasses)
    if (name == n) return ior;
  return std::nullopt;
}

std::vector<std::string> known_spectrum_names() {
  return {"metal-Au-eta", "metal-Au-k",   "metal-Ag-eta", "metal-Ag-k", "metal-Cu-eta",
          "metal-Cu-k",   "metal-Al-eta", "metal-Al-k",   "glass-BK7",  "glass-BAF10",
          "glass-FK51A",  "glass-LASF9",  "glass-F5",     "glass-SF5",  "glass-SF10",
          "glass-SF11",   "stdillum-D65", "stdillum-A"};
}

}  // namespace rf::pbrt
