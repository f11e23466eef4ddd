#include "engine/formats/mitsuba/mitsuba_values.h"
#include "engine/formats/spectrum.h"

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <utility>

#include "engine/scene.h"

namespace rf::mitsuba {

std::optional<double> parse_number(const std::string& text) {
  size_t b = 0, e = text.size();
  while (b < e && std::isspace(static_cast<unsigned char>(text[b]))) ++b;
  while (e > b && std::isspace(static_cast<unsigned char>(text[e - 1]))) --e;
  if (b == e) return std::nullopt;
  std::string s = text.substr(b, e - b);
  char* end = nullptr;
  double v = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size() || !std::isfinite(v)) return std::nullopt;
  return v;
}

std::optional<std::vector<double>> parse_numbers(const std::string& text) {
  std::vector<double> out;
  std::string item;
  auto flush = [&]() -> bool {
    if (item.empty()) return true;
    std::optional<double> v = parse_number(item);
    item.clear();
    if (!v) return false;
    out.push_back(*v);
    return true;
  };
  for (char c : text) {
    if (c == ',' || std::isspace(static_cast<unsigned char>(c))) {
      if (!flush()) return std::nullopt;
    } else {
      item += c;
    }
  }
  if (!flush()) return std::nullopt;
  return out;
}

namespace {

// Mitsuba 3's table of named IORs (its dielectric plugin documentation), at 589 nm.
const std::vector<std::pair<std::string, float>>& ior_table() {
  static const std::vector<std::pair<std::string, float>> table = {
      {"vacuum", 1.0f},      {"helium", 1.00004f},         {"hydrogen", 1.00013f},
      {"air", 1.000277f},    {"carbon dioxide", 1.00045f}, {"water", 1.3330f},
      {"acetone", 1.36f},    {"ethanol", 1.361f},          {"carbon tetrachloride", 1.461f},
      {"glycerol", 1.4729f}, {"benzene", 1.501f},          {"silicone oil", 1.52045f},
      {"bromine", 1.661f},   {"water ice", 1.31f},         {"fused quartz", 1.458f},
      {"pyrex", 1.470f},     {"acrylic glass", 1.49f},     {"polypropylene", 1.49f},
      {"bk7", 1.5046f},      {"sodium chloride", 1.544f},  {"amber", 1.55f},
      {"pet", 1.5750f},      {"diamond", 2.419f}};
  return table;
}

// Mitsuba's element symbols for the engine's presets (conductor_presets(): eta, k averaged over
// the R, G, B bands of measured data).
const std::vector<std::pair<std::string, std::string>>& conductor_aliases() {
  static const std::vector<std::pair<std::string, std::string>> aliases = {
      {"Au", "gold"}, {"Ag", "silver"}, {"Cu", "copper"}, {"Al", "aluminium"}};
  return aliases;
}

template <class F>
RGB integrate_rgb(F&& spectrum) {
  return xyz_to_srgb(integrate_xyz(spectrum));
}

}  // namespace

std::optional<float> named_ior(const std::string& name) {
  for (const auto& [n, v] : ior_table())
    if (n == name) return v;
  return std::nullopt;
}

std::vector<std::string> named_ior_names() {
  std::vector<std::string> names;
  for (const auto& [n, v] : ior_table()) names.push_back(n);
  return names;
}

std::optional<ConductorIor> conductor_material(const std::string& name) {
  std::string preset = name;
  for (const auto& [symbol, ours] : conductor_aliases())
    if (symbol == name) preset = ours;
  if (const ConductorPreset* p = conductor_preset(preset)) return ConductorIor{p->eta, p->k};
  return std::nullopt;
}

std::vector<std::string> conductor_material_names() {
  std::vector<std::string> names;
  for (const auto& [symbol, ours] : conductor_aliases()) names.push_back(symbol);
  names.push_back("none");
  return names;
}

RGB spectrum_to_rgb(const std::vector<double>& wavelengths, const std::vector<double>& values) {
  auto sampled = [&](double nm) {
    if (wavelengths.empty() || nm < wavelengths.front() || nm > wavelengths.back()) return 0.0;
    if (wavelengths.size() == 1) return values[0];
    size_t i = 1;
    while (i + 1 < wavelengths.size() && wavelengths[i] < nm) ++i;
    double t = (nm - wavelengths[i - 1]) / (wavelengths[i] - wavelengths[i - 1]);
    return values[i - 1] + t * (values[i] - values[i - 1]);
  };
  static const RGB white = integrate_rgb([](double) { return 1.0; });
  return integrate_rgb(sampled) / white;
}

}  // namespace rf::mitsuba
