// The Mitsuba 3 importer's textures and BSDFs (mitsuba_parser.h).
#include "engine/formats/mitsuba/mitsuba_parser.h"

namespace rf::mitsuba {

const Node& MitsubaParser::resolve_ref(const Node& ref) {
  std::string id = doc_.attr(ref, "id");
  auto it = ids_.find(id);
  if (it == ids_.end()) fail(ref, "reference to unknown id '" + id + "'");
  return it->second;
}

int32_t MitsubaParser::texture(const Node& at) {
  const Node& n = at.tag() == "ref" ? resolve_ref(at) : at;
  if (n.tag() != "texture")
    fail(at, "expected a texture, '" + doc_.attr_or(at, "id", "") + "' is a <" + n.tag() + ">");
  auto cached = textures_.find(n.xml.internal_object());
  if (cached != textures_.end()) return cached->second;
  Props p(doc_, n);
  std::string type = p.type();
  Texture t;
  t.name = n.has("id") ? doc_.attr(n, "id") : n.path;
  Mat4 to_uv = get_transform(p, "to_uv");
  if (std::fabs(to_uv.m[0][1]) > 1e-6f || std::fabs(to_uv.m[1][0]) > 1e-6f)
    doc_.warn(*p.find("to_uv"),
              "only the scale and translation of to_uv are supported; rotation ignored");
  Vec2 s{to_uv.m[0][0], to_uv.m[1][1]}, o{to_uv.m[0][3], to_uv.m[1][3]};
  if (type == "bitmap") {
    t.type = TextureType::Image;
    std::string file = get_string(p, "filename", "");
    if (file.empty()) fail(n, "a bitmap texture needs 'filename'");
    const Node& fn = *p.find("filename");
    t.file = doc_.with_location(fn, [&] { return files_.add(file, fn.path, "texture"); });
    t.resolved_path = files_.path_of(t.file);
    t.is_data = get_bool(p, "raw", false);
    // Mitsuba looks images up with v = 0 at the top row; the engine has v = 0 at the bottom.
    t.uv_scale = {s.x, -s.y};
    t.uv_offset = {o.x, 1 - o.y};
    std::string filter = get_string(p, "filter_type", "bilinear");
    if (filter != "bilinear")
      doc_.warn(*p.find("filter_type"),
                "'" + filter + "' filtering is not supported; textures are filtered trilinearly");
    std::string wrap = get_string(p, "wrap_mode", "repeat");
    if (wrap != "repeat")
      doc_.warn(*p.find("wrap_mode"), "wrap mode '" + wrap + "' is not supported; textures repeat");
    p.ignore("format");
    p.ignore("accel");
  } else if (type == "checkerboard") {
    t.type = TextureType::Checkerboard;
    Props& pp = p;
    auto plain = [&](const char* name, float fallback) {
      const Node* c = pp.find(name);
      if (!c) return RGB(fallback);
      if (c->tag() == "texture" || c->tag() == "ref") fail(*c, "nested textures are not supported");
      return color_of(*c, true);
    };
    t.color_a = plain("color0", 0.4f);
    t.color_b = plain("color1", 0.2f);
    // Mitsuba: color0 where frac(u) > 1/2 equals frac(v) > 1/2; engine: a where
    // floor(u') + floor(v') is even. They agree for u' = 2u, v' = 2v.
    t.uv_scale = {2 * s.x, 2 * s.y};
    t.uv_offset = {2 * o.x, 2 * o.y};
  } else {
    fail(n, "unsupported texture '" + type + "' (supported: bitmap, checkerboard)");
  }
  p.finish();
  int32_t index = int32_t(scene_.textures.size());
  scene_.textures.push_back(std::move(t));
  textures_[n.xml.internal_object()] = index;
  return index;
}

float MitsubaParser::ior(Props& p, const char* name, float fallback) {
  const Node* n = p.find(name);
  if (!n) return fallback;
  if (n->tag() == "string") {
    std::string v = doc_.attr(*n, "value");
    std::optional<float> f = mitsuba::named_ior(v);
    if (!f)
      fail(*n, "@value: unknown IOR name '" + v +
                   "' (known: " + join_names(mitsuba::named_ior_names()) + ")");
    return *f;
  }
  float v = float_of(*n);
  if (!(v >= 1 && v < 10)) fail(*n, "@value: an IOR must be in [1, 10), got " + format_number(v));
  return v;
}

FloatParam MitsubaParser::roughness(Props& p, const Node& n) {
  std::string dist = get_string(p, "distribution", "beckmann");
  if (dist != "beckmann" && dist != "ggx")
    fail(*p.find("distribution"),
         "@value: unknown distribution '" + dist + "' (known: beckmann, ggx)");
  FloatParam a;
  if (p.has("alpha_u") || p.has("alpha_v")) {
    if (p.has("alpha")) fail(*p.find("alpha"), "give either 'alpha' or 'alpha_u' and 'alpha_v'");
    float au = get_float(p, "alpha_u", 0.1f), av = get_float(p, "alpha_v", 0.1f);
    a.value = std::sqrt(au * av);
    if (au != av)
      doc_.warn(n, "anisotropic roughness is not supported: alpha_u " + format_number(au) +
                       ", alpha_v " + format_number(av) + " rendered as isotropic alpha " +
                       format_number(a.value));
  } else {
    a = float_param(p, "alpha", 0.1f, 0.0f, 1.0f);
  }
  if (!(a.value >= 0 && a.value <= 1)) fail(n, "alpha must be in [0, 1]");
  if (dist == "beckmann")
    doc_.warn(n,
              "Beckmann roughness is rendered with the GGX distribution at the same alpha "
              "(same peak density 1/(pi alpha^2); GGX has longer tails)");
  p.ignore("sample_visible");
  return a;
}

uint32_t MitsubaParser::add_material(Material m) {
  scene_.materials.push_back(std::move(m));
  return uint32_t(scene_.materials.size() - 1);
}

uint32_t MitsubaParser::default_material() {
  if (default_material_ < 0) {
    Material m;
    m.name = "default diffuse";
    m.type = MaterialType::Diffuse;
    m.reflectance.value = RGB(0.5f);
    default_material_ = int32_t(add_material(m));
  }
  return uint32_t(default_material_);
}

BsdfResult& MitsubaParser::bsdf(const Node& at) {
  const Node& n = at.tag() == "ref" ? resolve_ref(at) : at;
  if (n.tag() != "bsdf")
    fail(at, "expected a bsdf, '" + doc_.attr_or(at, "id", "") + "' is a <" + n.tag() + ">");
  auto cached = bsdfs_.find(n.xml.internal_object());
  if (cached != bsdfs_.end()) return cached->second;
  BsdfResult r = parse_bsdf(n);
  return bsdfs_.emplace(n.xml.internal_object(), std::move(r)).first->second;
}

BsdfResult MitsubaParser::parse_bsdf(const Node& n) {
  Props p(doc_, n);
  std::string type = p.type();
  BsdfResult r;
  r.node = n;
  Material m;
  m.name = n.has("id") ? doc_.attr(n, "id") : n.path;
  if (type == "twosided") {
    std::vector<Node> inner = p.nested({"bsdf", "ref"});
    if (inner.empty()) fail(n, "'twosided' needs a nested bsdf");
    if (inner.size() > 1) {
      r.unsupported = "'twosided' with different front and back BSDFs is not supported";
      return r;
    }
    BsdfResult& in = bsdf(inner[0]);
    r = in;
    r.node = n;
    r.one_sided = false;
    in.used = true;  // its one-sidedness is resolved here
    p.finish();
    return r;
  }
  if (type == "bumpmap" || type == "normalmap") {
    std::vector<Node> inner;  // the nested bsdf; the bump or normal texture is dropped
    for (const Node& c : p.nested({"bsdf", "ref"}))
      if (c.tag() == "bsdf" || resolve_ref(c).tag() == "bsdf") inner.push_back(c);
    if (inner.size() != 1) fail(n, "'" + type + "' needs one nested bsdf");
    doc_.warn(n, "'" + type + "' is not supported: the nested BSDF is rendered without it");
    p.nested({"texture"});
    p.ignore("normalmap");
    p.ignore("scale");
    p.finish();
    BsdfResult& in = bsdf(inner[0]);
    in.used = true;
    r = in;
    r.node = n;
    return r;
  }
  if (type == "diffuse") {
    m.type = MaterialType::Diffuse;
    m.reflectance = color_param(p, "reflectance", RGB(0.5f), true);
    r.one_sided = true;
  } else if (type == "dielectric" || type == "thindielectric" || type == "roughdielectric") {
    m.type = type == "dielectric"       ? MaterialType::Dielectric
             : type == "thindielectric" ? MaterialType::ThinDielectric
                                        : MaterialType::RoughDielectric;
    float int_ior = ior(p, "int_ior", 1.5046f), ext_ior = ior(p, "ext_ior", 1.000277f);
    m.ior = int_ior / ext_ior;
    if (!(m.ior > 1.0f && m.ior < 4.0f))
      fail(n, "int_ior / ext_ior must be between 1 and 4 (exclusive), got " + format_number(m.ior));
    const Node* sr = p.find("specular_reflectance");
    const Node* st = p.find("specular_transmittance");
    RGB tr = st ? color_of(*st, true) : RGB(1.0f), rf = sr ? color_of(*sr, true) : RGB(1.0f);
    m.specular.value = st ? tr : rf;
    if (sr && st && !(rf == tr))
      doc_.warn(*sr,
                "different reflection and transmission tints are not supported; both use "
                "specular_transmittance");
    if (type == "roughdielectric") m.roughness = roughness(p, n);
    m.separable_masking = true;  // Mitsuba's microfacet model (microfacet.h)
  } else if (type == "conductor" || type == "roughconductor") {
    m.type = type == "conductor" ? MaterialType::Conductor : MaterialType::RoughConductor;
    parse_conductor(p, n, m);
    if (type == "roughconductor") m.roughness = roughness(p, n);
    m.separable_masking = true;  // Mitsuba's microfacet model (microfacet.h)
    r.one_sided = true;
  } else if (type == "plastic" || type == "roughplastic") {
    m.type = MaterialType::Plastic;
    parse_plastic(p, n, m);
    if (type == "roughplastic") m.roughness = roughness(p, n);
    r.one_sided = true;
  } else {
    r.unsupported =
        "unsupported bsdf '" + type +
        "' (supported: diffuse, dielectric, thindielectric, roughdielectric, conductor, "
        "roughconductor, plastic, roughplastic, twosided; bumpmap and normalmap are dropped)";
    return r;
  }
  p.finish();
  r.material = int32_t(add_material(std::move(m)));
  return r;
}

void MitsubaParser::parse_conductor(Props& p, const Node& n, Material& m) {
  const Node* mat = p.find("material");
  const Node* eta = p.find("eta");
  const Node* k = p.find("k");
  if (mat && (eta || k)) fail(*mat, "give either 'material' or 'eta' and 'k'");
  const Node* sr = p.find("specular_reflectance");
  RGB tint = sr ? color_of(*sr, true) : RGB(1.0f);
  if (eta || k) {
    if (!eta || !k) fail(n, "a conductor needs both 'eta' and 'k'");
    m.eta = color_of(*eta, false);
    m.k = color_of(*k, false);
  } else {
    std::string name = mat ? doc_.attr(*mat, "value") : "none";
    if (mat && mat->tag() != "string") fail(*mat, "expected a <string>");
    if (name == "none") {  // Mitsuba's perfect mirror: Fresnel 1, times the tint
      m.conductor_tint = true;
      m.specular.value = tint;
      return;
    }
    std::optional<mitsuba::ConductorIor> c = mitsuba::conductor_material(name);
    if (!c)
      fail(*mat, "@value: conductor material '" + name + "' is not supported (supported: " +
                     join_names(mitsuba::conductor_material_names()) + "; or give eta and k)");
    m.eta = c->eta, m.k = c->k;
  }
  if (!(tint == RGB(1.0f)))
    doc_.warn(*sr, "specular_reflectance on a conductor with eta/k is not supported; ignored");
  if (const Node* e = p.find("ext_eta")) {
    float ext = float_of(*e);
    if (!(ext >= 1)) fail(*e, "@value: must be at least 1");
    m.eta = m.eta / ext, m.k = m.k / ext;
  }
}

void MitsubaParser::parse_plastic(Props& p, const Node& n, Material& m) {
  float int_ior = ior(p, "int_ior", 1.49f), ext_ior = ior(p, "ext_ior", 1.000277f);
  m.ior = int_ior / ext_ior;
  if (!(m.ior > 1.0f && m.ior < 4.0f))
    fail(n, "int_ior / ext_ior must be between 1 and 4 (exclusive), got " + format_number(m.ior));
  m.reflectance = color_param(p, "diffuse_reflectance", RGB(0.5f), true);
  const Node* sr = p.find("specular_reflectance");
  m.specular.value = sr ? color_of(*sr, true) : RGB(1.0f);
  bool nonlinear = get_bool(p, "nonlinear", false);
  if (!nonlinear) {
    if (m.reflectance.texture >= 0) {
      doc_.warn(n,
                "a textured diffuse_reflectance is rendered with nonlinear = true (darker, more "
                "saturated)");
    } else {
      float f = fresnel_diffuse_reflectance_interior(m.ior);
      RGB r = m.reflectance.value;
      for (int c = 0; c < 3; ++c) r[c] = r[c] / (1 - f + r[c] * f);
      m.reflectance.value = r;
    }
  }
}

}  // namespace rf::mitsuba
