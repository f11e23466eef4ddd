// The Mitsuba 3 importer's integrator, sensor, film, reconstruction filter and sampler
// (mitsuba_parser.h).
#include "engine/formats/mitsuba/mitsuba_parser.h"

namespace rf::mitsuba {

void MitsubaParser::parse_integrator(const Node& n, IntegratorSettings& out) {
  Props p(doc_, n);
  std::string type = p.type();
  if (type == "aov") {
    doc_.warn(n,
              "AOVs are not rendered by this importer (see rayfarm's --aov); the nested "
              "integrator is used");
    for (const Node& c : p.nested({"string"})) (void)c;
    std::vector<Node> inner = p.nested({"integrator"});
    if (inner.empty()) fail(n, "an 'aov' integrator needs a nested <integrator>");
    parse_integrator(inner[0], out);
    return;
  }
  std::string ours = integrator_for_mitsuba(type);
  if (ours.empty())
    fail(n,
         "unsupported integrator '" + type + "' (supported: " + mitsuba_integrator_types() + ")");
  out = IntegratorSettings{};
  out.method = make_integrator(ours);
  int max_depth = get_int(p, "max_depth", -1);
  if (max_depth == 0 || max_depth < -1)
    fail(*p.find("max_depth"), "@value: max_depth must be -1 (unbounded) or at least 1, got " +
                                   std::to_string(max_depth));
  out.max_depth = max_depth == -1 ? kInfiniteDepth : max_depth - 1;
  int rr_depth = get_int(p, "rr_depth", kMitsubaRrDepth);
  if (rr_depth < 1) fail(*p.find("rr_depth"), "@value: rr_depth must be at least 1");
  // Mitsuba counts depth after a vertex's BSDF sample (1 at the camera ray's hit) and plays
  // roulette once depth >= rr_depth; rayfarm plays it at vertex depth + 1 >= rr_min_depth: the
  // same vertex for the same number (unlike max_depth, whose Mitsuba count includes the
  // emitter vertex).
  out.rr_min_depth = rr_depth;
  if (get_bool(p, "hide_emitters", false))
    doc_.warn(*p.find("hide_emitters"),
              "not supported: emitters seen directly by the camera are rendered (their light is "
              "the same)");
  // The module maps its own parameters (module.h, from_mitsuba).
  struct Params : ForeignParams {
    MitsubaParser& parser;
    Props& props;
    const Node& node;
    Params(MitsubaParser& pa, Props& pr, const Node& no) : parser(pa), props(pr), node(no) {}
    int integer(const std::string& name, int fallback) const override {
      return parser.get_int(props, name, fallback);
    }
    double number(const std::string& name, double fallback) const override {
      return parser.get_float(props, name, float(fallback));
    }
    bool boolean(const std::string& name, bool fallback) const override {
      return parser.get_bool(props, name, fallback);
    }
    [[noreturn]] void fail(const std::string& message) const override {
      parser.fail(node, message);
    }
  };
  map_mitsuba_integrator(out, Params(*this, p, n));
  p.ignore("samples_per_pass");
  p.ignore("timeout");
  apply_fixed_max_depth(out);
  p.finish();
}

void MitsubaParser::parse_sensor(const Node& n) {
  Props p(doc_, n);
  std::string type = p.type();
  if (type != "perspective" && type != "thinlens")
    fail(n, "unsupported sensor '" + type + "' (supported: perspective, thinlens)");
  // Film and sampler first: the field of view depends on the aspect ratio.
  std::vector<Node> films = p.nested({"film"});
  if (films.size() > 1) fail(films[1], "a second <film>");
  if (films.empty()) {
    scene_.film.width = 768, scene_.film.height = 576;
    scene_.film.filter = {FilterType::Gaussian, 2.0f, 0.5f};
  } else {
    parse_film(films[0]);
  }
  std::vector<Node> samplers = p.nested({"sampler"});
  if (samplers.size() > 1) fail(samplers[1], "a second <sampler>");
  scene_.render.spp = 4;
  if (!samplers.empty()) parse_sampler(samplers[0]);
  scene_.render.passes = default_passes(scene_.render.spp);

  const Node* fov_node = p.find("fov");
  const Node* focal_node = p.find("focal_length");
  if (fov_node && focal_node) fail(*focal_node, "give either 'fov' or 'focal_length', not both");
  double w = scene_.film.width, h = scene_.film.height, aspect = w / h;
  double fov_deg;
  std::string axis;
  if (fov_node) {
    fov_deg = float_of(*fov_node);
    if (!(fov_deg > 0 && fov_deg < 180)) fail(*fov_node, "@value: fov must be in (0, 180) degrees");
    axis = get_string(p, "fov_axis", "x");
    std::transform(axis.begin(), axis.end(), axis.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    if (axis == "smaller") axis = aspect > 1 ? "y" : "x";
    if (axis == "larger") axis = aspect > 1 ? "x" : "y";
    if (axis != "x" && axis != "y" && axis != "diagonal")
      fail(*p.find("fov_axis"),
           "@value: unknown fov_axis '" + axis + "' (known: x, y, diagonal, smaller, larger)");
  } else {
    std::string f = get_string(p, "focal_length", "50mm");
    std::string digits =
        f.size() > 2 && f.substr(f.size() - 2) == "mm" ? f.substr(0, f.size() - 2) : f;
    double focal = focal_node ? number(*focal_node, digits) : 50.0;
    if (!(focal > 0)) fail(*focal_node, "@value: the focal length must be > 0");
    fov_deg = 2 * std::atan(std::sqrt(36.0 * 36.0 + 24.0 * 24.0) / (2 * focal)) * 180 / kPiD;
    axis = "diagonal";
  }
  // Half extents of the image plane at distance 1, then the angle across the shorter side.
  double t = std::tan(fov_deg * kPiD / 360);
  double half_w = axis == "x"   ? t
                  : axis == "y" ? t * aspect
                                : t * aspect / std::sqrt(1 + aspect * aspect);
  double half_h = half_w / aspect;
  scene_.camera.fov_deg = float(2 * std::atan(std::min(half_w, half_h)) * 180 / kPiD);

  Mat4 to_world = get_transform(p, "to_world");
  if (!is_rotation(to_world)) {
    const Node* t_node = p.find("to_world");
    fail(t_node ? *t_node : n,
         "the sensor's to_world must be a rotation and a translation (no scale, shear or mirror)");
  }
  scene_.camera.camera_to_world = to_world * Mat4::scale({-1, 1, -1});

  if (type == "thinlens") {
    const Node* a = p.find("aperture_radius");
    if (!a) fail(n, "a thinlens sensor needs 'aperture_radius'");
    scene_.camera.lens_radius = float_of(*a);
    if (!(scene_.camera.lens_radius >= 0)) fail(*a, "@value: must be at least 0");
    scene_.camera.focus_distance = get_float(p, "focus_distance", get_float(p, "far_clip", 1e4f));
    if (!(scene_.camera.focus_distance > 0)) fail(*p.find("focus_distance"), "@value: must be > 0");
  }
  for (const char* k :
       {"near_clip", "far_clip", "principal_point_offset_x", "principal_point_offset_y"})
    if (const Node* c = p.find(k)) {
      std::string name = k;
      if (name == "far_clip" && type == "thinlens") continue;
      doc_.warn(*c,
                "ignored: rayfarm's camera has no " +
                    std::string(name.find("clip") != std::string::npos ? "clipping planes"
                                                                       : "principal point offset"));
    }
  p.ignore("shutter_open");
  p.ignore("shutter_close");
  p.ignore("srf");
  p.finish();
}

void MitsubaParser::parse_film(const Node& n) {
  Props p(doc_, n);
  std::string type = p.type();
  if (type != "hdrfilm" && type != "specfilm")
    fail(n, "unsupported film '" + type + "' (supported: hdrfilm)");
  scene_.film.width = get_int(p, "width", 768);
  scene_.film.height = get_int(p, "height", 576);
  for (const char* k : {"width", "height"}) {
    int v = std::string(k) == "width" ? scene_.film.width : scene_.film.height;
    if (v < 1 || v > kMaxResolution)
      fail(*p.find(k), "@value: must be between 1 and " + std::to_string(kMaxResolution));
  }
  // Output encodings: rayfarm writes its own EXR (RGB, float), so these change no pixel.
  for (const char* k : {"file_format", "pixel_format", "component_format", "banner",
                        "high_quality_edges", "sample_border", "compensate"})
    p.ignore(k);
  for (const char* k : {"crop_offset_x", "crop_offset_y", "crop_width", "crop_height"})
    if (const Node* c = p.find(k))
      doc_.warn(*c, "cropping is not supported; the whole film is rendered");
  scene_.film.filter = {FilterType::Gaussian, 2.0f,
                        0.5f};  // Mitsuba's default: gaussian, stddev 0.5
  std::vector<Node> filters = p.nested({"rfilter"});
  if (filters.size() > 1) fail(filters[1], "a second <rfilter>");
  if (!filters.empty()) parse_rfilter(filters[0]);
  p.finish();
}

void MitsubaParser::parse_rfilter(const Node& n) {
  Props p(doc_, n);
  std::string type = p.type();
  FilterSettings& f = scene_.film.filter;
  if (type == "box") {
    f = {FilterType::Box, 0.5f, 0.5f};
  } else if (type == "tent") {
    f = {FilterType::Triangle, get_float(p, "radius", 1.0f), 0.5f};
    if (!(f.radius > 0)) fail(*p.find("radius"), "@value: must be > 0");
  } else if (type == "gaussian") {
    float sigma = get_float(p, "stddev", 0.5f);
    if (!(sigma > 0)) fail(*p.find("stddev"), "@value: must be > 0");
    f = {FilterType::Gaussian, 4 * sigma, sigma};  // Mitsuba truncates at 4 standard deviations
  } else {
    doc_.warn(n, "the '" + type +
                     "' filter is not supported; using Mitsuba's default gaussian (stddev 0.5)");
    f = {FilterType::Gaussian, 2.0f, 0.5f};
    return;
  }
  p.finish();
}

void MitsubaParser::parse_sampler(const Node& n) {
  Props p(doc_, n);
  std::string type = p.type();
  static const std::set<std::string> kLowDiscrepancy = {"stratified", "multijitter", "orthogonal",
                                                        "ldsampler", "sobol"};
  if (type == "independent")
    scene_.render.sampler = "independent";
  else if (kLowDiscrepancy.count(type))
    scene_.render.sampler = "sobol";  // same expected image, stratified differently
  else
    doc_.warn(n, "unknown sampler '" + type + "'; using the independent sampler");
  int spp = get_int(p, "sample_count", 4);
  if (spp < 1) fail(*p.find("sample_count"), "@value: must be at least 1");
  scene_.render.spp = uint64_t(spp);
  int seed = get_int(p, "seed", 0);
  if (seed < 0) fail(*p.find("seed"), "@value: must be at least 0");
  scene_.render.seed = uint64_t(seed);
  for (const char* k : {"jitter", "scramble_seed", "strength", "dimension"}) p.ignore(k);
  p.finish();
}

}  // namespace rf::mitsuba
