// Materials and textures: pbrt-v4's material types onto the engine's (docs/formats/pbrt.md
// "Materials", "Textures", "Colour").
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>

#include "engine/formats/pbrt/pbrt_builder.h"
#include "engine/formats/pbrt/pbrt_images.h"
#include "engine/formats/pbrt/pbrt_spectra.h"

namespace rf::pbrt {

namespace {

// pbrt-v4 treats a microfacet distribution with alpha below this as perfectly smooth.
constexpr float kSmoothAlpha = 1e-3f;

void use_all(const ParamList& params) {
  for (const Param& p : params.items) p.used = true;
}

std::string lower_ext(const std::string& f) {
  size_t dot = f.rfind('.');
  std::string e = dot == std::string::npos ? "" : f.substr(dot + 1);
  std::transform(e.begin(), e.end(), e.begin(),
                 [](unsigned char c) { return char(std::tolower(c)); });
  return e;
}

}  // namespace

// A spectrum file (pbrt's .spd): whitespace-separated (wavelength nm, value) pairs, '#' comments.
std::vector<double> Builder::read_spd(const Param& p, const std::string& file,
                                      const std::string& d) {
  const std::string what = d + ": parameter " + p.decl() + " \"" + file + "\"";
  std::string bytes = files_call(p.at, what, [&] { return files_.read(file, "spectrum file"); });
  std::vector<double> v;
  std::istringstream in(bytes);
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    line = line.substr(0, line.find('#'));
    std::istringstream words(line);
    std::string w;
    while (words >> w) {
      char* end = nullptr;
      double x = std::strtod(w.c_str(), &end);
      if (end == w.c_str() || *end != '\0' || !std::isfinite(x))
        fail(p.at,
             what + ": line " + std::to_string(line_no) + ": expected a number, got '" + w + "'");
      v.push_back(x);
    }
  }
  if (v.size() < 4 || v.size() % 2 != 0)
    fail(p.at, what + ": expected (wavelength, value) pairs, got " + std::to_string(v.size()) +
                   " numbers");
  for (size_t i = 2; i < v.size(); i += 2)
    if (!(v[i] > v[i - 2])) fail(p.at, what + ": wavelengths must increase");
  return v;
}

RGB Builder::spectrum_value(const Param& p, bool illuminant, const std::string& d) {
  const std::string what = d + ": parameter " + p.decl();
  if (p.type == "rgb" || p.type == "color") {
    if (p.numbers.size() != 3)
      fail(p.at, what + ": expected 3 values, got " + std::to_string(p.numbers.size()));
    RGB c(float(p.numbers[0]), float(p.numbers[1]), float(p.numbers[2]));
    if (c.x < 0 || c.y < 0 || c.z < 0) fail(p.at, what + ": RGB values must not be negative");
    return c;
  }
  if (p.type == "blackbody") {
    if (p.numbers.empty() || p.numbers.size() > 2 || !(p.numbers[0] > 0))
      fail(p.at, what + ": expected a temperature in kelvin (> 0)");
    // Stars run from about 2,000 K to 50,000 K; far outside that a value is likely a typo (the
    // spectrum is normalised to a peak of 1, so 1e30 K renders as a plain blue-white).
    if (p.numbers[0] < 500 || p.numbers[0] > 1e5)
      warn(p.at, what + ": a blackbody of " + format_number(p.numbers[0]) +
                     " K is outside 500..100000 K (a typo?); its normalised colour is used");
    RGB c = blackbody_rgb(p.numbers[0]);
    return p.numbers.size() == 2 ? c * float(p.numbers[1]) : c;  // pbrt-v3's [T scale]
  }
  if (p.type == "spectrum") {
    if (!p.strings.empty()) {
      if (p.strings.size() != 1) fail(p.at, what + ": expected one spectrum name");
      const std::string& n = p.strings[0];
      if (std::optional<RGB> c = named_spectrum_rgb(n, illuminant)) return *c;
      if (lower_ext(n) == "spd" || n.find('/') != std::string::npos ||
          n.find('.') != std::string::npos)
        return sampled_spectrum_rgb(read_spd(p, n, d), illuminant);
      fail(p.at, what + ": unknown named spectrum \"" + n +
                     "\" (known: " + join_names(known_spectrum_names()) + ")");
    }
    if (p.numbers.size() < 4 || p.numbers.size() % 2 != 0)
      fail(p.at, what + ": expected (wavelength, value) pairs, got " +
                     std::to_string(p.numbers.size()) + " values");
    for (size_t i = 2; i < p.numbers.size(); i += 2)
      if (!(p.numbers[i] > p.numbers[i - 2])) fail(p.at, what + ": wavelengths must increase");
    return sampled_spectrum_rgb(p.numbers, illuminant);
  }
  if (p.type == "float" && p.numbers.size() == 1) return RGB(float(p.numbers[0]));
  fail(p.at, what + ": expected an \"rgb\", \"spectrum\" or \"blackbody\" value");
}

// ------------------------------------------------------------------------------------------
// Material parameters.

ColorParam Builder::color_param(const ParamList& params, const std::string& name, RGB def,
                                const std::string& d) {
  ColorParam c;
  c.value = def;
  const Param* p = params.find(name);
  if (!p) return c;
  if (p->type == "texture") {
    TexValue t = tex_input(params, name, def, false, d);
    c.value = t.value;
    c.texture = t.texture;
    return c;
  }
  c.value = spectrum_value(*p, false, d);
  return c;
}

FloatParam Builder::float_param(const ParamList& params, const std::string& name, float def,
                                const std::string& d) {
  FloatParam f;
  f.value = def;
  const Param* p = params.find(name);
  if (!p) return f;
  if (p->type == "texture") {
    TexValue t = tex_input(params, name, RGB(def), true, d);
    f.value = t.value.x;
    f.texture = t.texture;
    return f;
  }
  if (p->type != "float" || p->numbers.size() != 1)
    fail(p->at, d + ": parameter " + p->decl() + ": expected one \"float\"");
  f.value = float(p->numbers[0]);
  return f;
}

// pbrt-v4: uroughness / vroughness (default: roughness, default 0); remaproughness (default true)
// maps roughness r to the GGX alpha sqrt(r) (TrowbridgeReitzDistribution::RoughnessToAlpha).
FloatParam Builder::roughness(const ParamList& params, const std::string& prefix,
                              const std::string& d) {
  bool remap = params.boolean("remaproughness", true);
  FloatParam base = float_param(params, prefix + "roughness", 0, d);
  FloatParam u =
      params.has(prefix + "uroughness") ? float_param(params, prefix + "uroughness", 0, d) : base;
  FloatParam v =
      params.has(prefix + "vroughness") ? float_param(params, prefix + "vroughness", 0, d) : base;
  const Location& at = cur_at_;
  if (u.texture >= 0 || v.texture >= 0) {
    if (remap)
      warn(
          at,
          d + ": a roughness texture is used as the GGX alpha directly (pbrt would take its sqrt)");
    return u.texture >= 0 ? u : v;
  }
  if (u.value < 0 || v.value < 0) fail(at, d + ": roughness must not be negative");
  float au = remap ? std::sqrt(u.value) : u.value, av = remap ? std::sqrt(v.value) : v.value;
  if (au != av)
    warn(at, d + ": anisotropic roughness (alpha " + format_number(au) + " x " + format_number(av) +
                 ") is not supported; their mean is used");
  FloatParam out;
  out.value = std::min(1.0f, 0.5f * (au + av));
  return out;
}

float Builder::ior_value(const ParamList& params, const std::string& name, const std::string& d) {
  const Param* p = params.find(name);
  if (!p) return 1.5f;
  if (p->type == "float" && p->numbers.size() == 1) return float(p->numbers[0]);
  if (p->type == "spectrum" && p->strings.size() == 1) {
    if (std::optional<float> ior = named_glass_ior(p->strings[0])) {
      warn(p->at, d + ": " + p->decl() + " \"" + p->strings[0] +
                      "\": dispersion is not supported; n_d = " + format_number(*ior) + " is used");
      return *ior;
    }
    fail(p->at, d + ": parameter " + p->decl() + ": unknown glass \"" + p->strings[0] + "\"");
  }
  if (p->type == "spectrum" && p->numbers.size() >= 2 && p->numbers.size() % 2 == 0) {
    // The value at 550 nm, linearly interpolated.
    const auto& v = p->numbers;
    double ior = v[1];
    for (size_t i = 0; i + 3 < v.size(); i += 2)
      if (v[i] <= 550 && 550 <= v[i + 2])
        ior = v[i + 1] + (v[i + 3] - v[i + 1]) * (550 - v[i]) / std::max(1e-9, v[i + 2] - v[i]);
    if (v.size() > 2 && v.back() != v[1])
      warn(p->at,
           d + ": " + p->decl() + ": dispersion is not supported; the index at 550 nm is used");
    return float(ior);
  }
  fail(p->at, d + ": parameter " + p->decl() + ": expected a \"float " + name +
                  "\" or a named glass spectrum");
}

// ------------------------------------------------------------------------------------------
// Materials.

MaterialDef Builder::build_material(const std::string& type, const ParamList& params,
                                    const std::string& d) {
  MaterialDef def;
  Material& m = def.material;
  if (type == "diffuse") {
    m.type = MaterialType::Diffuse;
    m.reflectance = color_param(params, "reflectance", RGB(0.5f), d);
  } else if (type == "coateddiffuse") {
    m.type = MaterialType::Plastic;
    m.reflectance = color_param(params, "reflectance", RGB(0.5f), d);
    m.roughness = roughness(params, "", d);
    m.ior = ior_value(params, "eta", d);
    ColorParam albedo = color_param(params, "albedo", RGB(0.0f), d);
    if (albedo.texture >= 0 || !is_black(albedo.value))
      warn(params.find("albedo")->at,
           d + ": a scattering coating (\"albedo\") is not supported (ignored)");
    float thickness = float(params.number("thickness", 0.01));
    if (thickness > 0.1f)
      warn(params.find("thickness")->at,
           d + ": the coating's thickness (absorption) is not supported (ignored)");
    params.find("g"), params.find("maxdepth"),
        params.find("nsamples");  // the layered walk's own settings
  } else if (type == "conductor" || type == "coatedconductor") {
    const std::string pre = type == "coatedconductor" ? "conductor." : "";
    if (type == "coatedconductor") {
      warn(cur_at_,
           d + ": \"coatedconductor\" is rendered as its conductor without the dielectric coating");
      for (const char* k : {"interface.roughness", "interface.uroughness", "interface.vroughness",
                            "interface.eta", "thickness", "albedo", "g", "maxdepth", "nsamples"})
        params.find(k);
    }
    FloatParam r = roughness(params, pre, d);
    m.roughness = r;
    m.type = r.texture < 0 && r.value < kSmoothAlpha ? MaterialType::Conductor
                                                     : MaterialType::RoughConductor;
    if (const Param* refl = params.find("reflectance")) {
      ColorParam c = color_param(params, "reflectance", RGB(1.0f), d);
      if (c.texture >= 0) {
        warn(refl->at,
             d + ": a textured \"reflectance\" uses Schlick's Fresnel with F0 = the texture");
        m.conductor_tint = true;
        m.specular = c;
      } else {
        // pbrt-v4's artist-friendly conductor: eta = 1, k = 2 sqrt(r) / sqrt(1 - r).
        auto k_of = [](float r) {
          r = std::clamp(r, 0.0f, 0.9999f);
          return 2 * std::sqrt(r) / std::sqrt(1 - r);
        };
        m.eta = RGB(1.0f);
        m.k = RGB(k_of(c.value.x), k_of(c.value.y), k_of(c.value.z));
      }
      params.find(pre + "eta"), params.find(pre + "k");
    } else {
      const ConductorPreset* cu = conductor_preset("copper");  // pbrt's default: metal-Cu
      m.eta = cu->eta, m.k = cu->k;
      for (const char* which : {"eta", "k"}) {
        const Param* p = params.find(pre + which);
        if (!p) continue;
        if (p->type == "texture") {
          warn(p->at, d + ": textured " + p->decl() + " is not supported; copper's value is used");
          continue;
        }
        (std::string(which) == "eta" ? m.eta : m.k) = spectrum_value(*p, false, d);
      }
    }
  } else if (type == "dielectric" || type == "thindielectric") {
    m.ior = ior_value(params, "eta", d);
    if (type == "thindielectric") {
      m.type = MaterialType::ThinDielectric;
    } else {
      FloatParam r = roughness(params, "", d);
      m.roughness = r;
      m.type = r.texture < 0 && r.value < kSmoothAlpha ? MaterialType::Dielectric
                                                       : MaterialType::RoughDielectric;
    }
    if (m.ior == 1.0f && m.type == MaterialType::Dielectric) {
      def.interface = true;  // index-matched: no visible surface
    } else if (!(m.ior > 1.0f && m.ior < 4.0f)) {
      def.error = d + ": \"eta\" " + format_number(m.ior) +
                  " is not supported (rayfarm's dielectrics need 1 < eta < 4)";
    }
  } else if (type == "diffusetransmission") {
    m.type = MaterialType::Diffuse;
    m.reflectance = color_param(params, "reflectance", RGB(0.25f), d);
    warn(cur_at_, d + ": \"diffusetransmission\" is rendered as diffuse reflection (its "
                      "transmission is lost)");
    params.find("transmittance"), params.find("scale");
  } else if (type == "mix") {
    const Param* mats = params.find("materials");
    if (!mats || mats->type != "string" || mats->strings.size() != 2) {
      use_all(params);
      def.error = d + ": \"mix\" needs \"string materials\" with two material names";
      return def;
    }
    FloatParam amount = float_param(params, "amount", 0.5f, d);
    float a = amount.texture >= 0 ? 0.5f : amount.value;
    const std::string& chosen = mats->strings[a < 0.5f ? 0 : 1];
    if (amount.texture >= 0 || (a > 0 && a < 1))
      warn(mats->at, d + ": \"mix\" is not supported; material \"" + chosen +
                         "\" (the larger weight) is used");
    auto it = named_materials_.find(chosen);
    if (it == named_materials_.end()) {
      def.error = d + ": \"mix\" names an unknown material \"" + chosen + "\"";
      return def;
    }
    def = materials_[size_t(it->second)];
    def.scene_index = -1;
    return def;
  } else if (type == "interface" || type == "" || type == "none") {
    def.interface = true;
  } else {
    use_all(params);
    static const char* known_unsupported[] = {"measured", "subsurface", "hair", "conductor_rough"};
    bool known = false;
    for (const char* k : known_unsupported) known = known || type == k;
    def.error = d + ": material type \"" + type + "\" " +
                (known ? std::string("is not supported") : std::string("is unknown")) +
                " (supported: diffuse, coateddiffuse, conductor, dielectric, thindielectric, "
                "diffusetransmission, coatedconductor, mix, interface)";
    return def;
  }
  // Albedos above 1 are not physical; pbrt-v4 refuses them, we clamp.
  for (ColorParam* c : {&m.reflectance}) {
    RGB v = c->value;
    if (c->texture < 0 && (v.x > 1 || v.y > 1 || v.z > 1)) {
      warn(cur_at_, d + ": reflectance above 1 is clamped to 1");
      c->value = RGB(std::min(v.x, 1.0f), std::min(v.y, 1.0f), std::min(v.z, 1.0f));
    }
  }
  return def;
}

int Builder::define_material(const std::string& name, const std::string& type,
                             const ParamList& params, const Location& at) {
  const std::string d =
      name.empty() ? "Material \"" + type + "\"" : "MakeNamedMaterial \"" + name + "\"";
  cur_at_ = at;
  MaterialDef def = build_material(type, params, d);
  def.at = at;
  def.material.name = name.empty() ? "Material \"" + type + "\" at " + at.str() : name;
  warn_unused(params, d);
  materials_.push_back(std::move(def));
  return int(materials_.size()) - 1;
}

uint32_t Builder::material_for_shape(const Location& at, const std::string& shape, bool& interface,
                                     bool& pending) {
  pending = false;
  int idx = gs_.material;
  if (!gs_.material_name.empty()) {
    auto it = named_materials_.find(gs_.material_name);
    if (it == named_materials_.end()) {
      pending = true;
      return 0;
    }
    idx = it->second;
  }
  if (idx < 0) {
    if (default_material_ < 0) {
      MaterialDef def;
      def.material.type = MaterialType::Diffuse;
      def.material.reflectance.value = RGB(0.5f);
      def.material.name = "pbrt default (diffuse 0.5)";
      materials_.push_back(def);
      default_material_ = int(materials_.size()) - 1;
    }
    idx = default_material_;
  }
  return use_material(idx, at, shape, interface);
}

uint32_t Builder::use_material(int index, const Location& at, const std::string& shape,
                               bool& interface) {
  MaterialDef& m = materials_[size_t(index)];
  if (!m.error.empty())
    fail(at, shape + ": " + m.error + " (the material is defined at " + m.at.str() + ")");
  if (m.interface) {
    interface = true;
    return 0;
  }
  if (m.scene_index < 0) {
    m.scene_index = int32_t(scene_.materials.size());
    scene_.materials.push_back(m.material);
  }
  return uint32_t(m.scene_index);
}

void Builder::resolve_pending_materials() {
  std::vector<std::pair<int, size_t>> left_out;
  for (const PendingMaterial& p : pending_materials_) {
    auto it = named_materials_.find(p.name);
    if (it == named_materials_.end())
      fail(p.shape_at, p.shape + ": material \"" + p.name + "\" (NamedMaterial at " +
                           p.material_at.str() + ") is not defined anywhere in the scene");
    bool interface = false;
    uint32_t index = use_material(it->second, p.shape_at, p.shape, interface);
    std::vector<Mesh>& list =
        p.object < 0 ? scene_.meshes : scene_.objects[size_t(p.object)].meshes;
    if (interface) {
      left_out.push_back({p.object, p.mesh});
      continue;
    }
    list[p.mesh].material = index;
  }
  // Shapes whose material turned out to be "interface": left out, last first so indices hold.
  std::sort(left_out.begin(), left_out.end(), [](auto a, auto b) { return a.second > b.second; });
  for (auto [object, mesh] : left_out) {
    std::vector<Mesh>& list = object < 0 ? scene_.meshes : scene_.objects[size_t(object)].meshes;
    scene_.warnings.push_back(
        list[mesh].name + ": its material (\"interface\") has no surface; the shape is left out");
    list.erase(list.begin() + std::ptrdiff_t(mesh));
  }
  pending_materials_.clear();
}

// ------------------------------------------------------------------------------------------
// Textures.

int32_t Builder::push_texture(Texture t) {
  scene_.textures.push_back(std::move(t));
  return int32_t(scene_.textures.size()) - 1;
}

TexValue Builder::tex_input(const ParamList& params, const std::string& name, RGB def,
                            bool is_float, const std::string& d) {
  TexValue v;
  v.value = def;
  const Param* p = params.find(name);
  if (!p) return v;
  if (p->type == "texture") {
    if (p->strings.size() != 1)
      fail(p->at, d + ": parameter " + p->decl() + ": expected one texture name");
    auto& first = is_float ? float_textures_ : spectrum_textures_;
    auto& second = is_float ? spectrum_textures_ : float_textures_;
    auto it = first.find(p->strings[0]);
    if (it == first.end()) {
      it = second.find(p->strings[0]);
      if (it == second.end())
        fail(p->at, d + ": parameter " + p->decl() + ": unknown texture \"" + p->strings[0] + "\"");
    }
    return it->second;
  }
  if (p->type == "float" && p->numbers.size() == 1) {
    v.value = RGB(float(p->numbers[0]));
    return v;
  }
  v.value = spectrum_value(*p, false, d);
  return v;
}

void Builder::texture(const std::string& name, const std::string& kind, const std::string& cls,
                      const ParamList& params, const Location& at) {
  const std::string d = "Texture \"" + name + "\"";
  if (kind != "spectrum" && kind != "float" && kind != "color")
    fail(at, d + ": type must be \"spectrum\" or \"float\", got \"" + kind + "\"");
  const bool is_float = kind == "float";
  cur_at_ = at;
  TexValue tv;
  Texture t;
  t.name = name;
  std::string mapping = params.string("mapping", "uv");
  if (mapping != "uv")
    warn(at, d + ": \"mapping\" \"" + mapping + "\" is not supported; uv mapping is used");
  t.uv_scale = {float(params.number("uscale", 1)), float(params.number("vscale", 1))};
  t.uv_offset = {float(params.number("udelta", 0)), float(params.number("vdelta", 0))};
  auto is_const = [](const TexValue& v) { return v.texture < 0; };
  if (cls == "constant") {
    tv = tex_input(params, "value", RGB(1.0f), is_float, d);
  } else if (cls == "imagemap") {
    std::string file = params.string("filename", "");
    if (file.empty()) fail(at, d + ": needs \"string filename\"");
    t.type = TextureType::Image;
    t.file = files_call(at, d + " \"" + file + "\"",
                        [&] { return files_.add(file, "filename", "image"); });
    t.resolved_path = files_.path_of(t.file);
    // pbrt-v4's default encoding: sRGB for PNG files, linear for the rest.
    std::string enc = params.string("encoding", lower_ext(file) == "png" ? "sRGB" : "linear");
    if (enc == "linear") {
      t.is_data = true;
    } else if (enc != "sRGB") {
      warn(at, d + ": \"encoding\" \"" + enc + "\" is not supported; sRGB is used");
    }
    bool invert = params.boolean("invert", false);
    float sc = float(params.number("scale", 1));
    if (invert || sc != 1) {
      t.resolved_path = files_call(at, d + " \"" + file + "\"", [&] {
        return bake_image(t.resolved_path, sc, invert, t.is_data, "'" + t.file + "'");
      });
    }
    std::string wrap = params.string("wrap", "repeat");
    if (wrap != "repeat")
      warn(at, d + ": \"wrap\" \"" + wrap + "\" is not supported; repeat is used");
    params.find("filter"),
        params.find("maxanisotropy");  // lookup filtering: the engine's trilinear
    tv.texture = push_texture(t);
    image_arith_[tv.texture] = {sc, invert};
  } else if (cls == "checkerboard") {
    if (params.integer("dimension", 2) != 2)
      warn(at, d + ": 3D checkerboards are not supported; a 2D one is used");
    TexValue a = tex_input(params, "tex1", RGB(1.0f), is_float, d),
             b = tex_input(params, "tex2", RGB(0.0f), is_float, d);
    if (!is_const(a) || !is_const(b))
      warn(at, d + ": checkerboards of textures are not supported; their constant parts are used");
    t.type = TextureType::Checkerboard;
    t.color_a = a.value;
    t.color_b = b.value;
    tv.texture = push_texture(t);
  } else if (cls == "scale") {
    TexValue a = tex_input(params, "tex", RGB(1.0f), is_float, d),
             s = tex_input(params, "scale", RGB(1.0f), true, d);
    if (is_const(a) && is_const(s)) {
      tv.value = a.value * s.value.x;
    } else if (is_const(s) && s.value.x == 1) {
      tv = a;
    } else if (is_const(a) && a.value == RGB(1.0f)) {
      tv = s;
    } else if (is_const(s) &&
               scene_.textures[size_t(a.texture)].type == TextureType::Checkerboard) {
      Texture c = scene_.textures[size_t(a.texture)];
      c.name = name;
      c.color_a = c.color_a * s.value.x;
      c.color_b = c.color_b * s.value.x;
      tv.texture = push_texture(c);
    } else if (is_const(s) && image_arith_.count(a.texture) && !image_arith_[a.texture].second) {
      // An image times a constant: baked into a scaled copy of the image (pbrt_images.h).
      Texture c = scene_.textures[size_t(a.texture)];
      float total = image_arith_[a.texture].first * s.value.x;
      c.name = name;
      c.resolved_path = files_call(at, d, [&] {
        return bake_image(files_.path_of(c.file), total, false, c.is_data, "'" + c.file + "'");
      });
      tv.texture = push_texture(c);
      image_arith_[tv.texture] = {total, false};
    } else {
      warn(at, d + ": \"scale\" of a texture by a texture is not supported; the unscaled texture "
                   "is used");
      tv = is_const(a) ? s : a;
    }
  } else if (cls == "mix") {
    TexValue a = tex_input(params, "tex1", RGB(0.0f), is_float, d),
             b = tex_input(params, "tex2", RGB(1.0f), is_float, d);
    TexValue amount = tex_input(params, "amount", RGB(0.5f), true, d);
    float w = is_const(amount) ? amount.value.x : 0.5f;
    if (is_const(a) && is_const(b) && is_const(amount)) {
      tv.value = a.value * (1 - w) + b.value * w;
    } else if (is_const(amount) && (w <= 0 || w >= 1)) {
      tv = w <= 0 ? a : b;
    } else {
      warn(at, d + ": \"mix\" of textures is not supported; tex" +
                   std::string(w < 0.5f ? "1" : "2") + " (the larger weight) is used");
      tv = w < 0.5f ? a : b;
    }
  } else {
    use_all(params);
    warn(at, d + ": texture class \"" + cls + "\" is not supported; a constant 0.5 is used");
    tv.value = RGB(0.5f);
  }
  warn_unused(params, d);
  (is_float ? float_textures_ : spectrum_textures_)[name] = tv;
}

}  // namespace rf::pbrt
