// The Mitsuba 3 XML importer (docs/formats/mitsuba.md): plugins of a <scene> mapped onto the
// engine's Scene. The XML layer (includes, defaults, $substitution, locations) is mitsuba_xml.h;
// value tables and spectra are mitsuba_values.h.
//
// Every element a plugin does not read is a warning naming its file, line and XML path; an
// unsupported plugin that would change the image a lot (a BSDF on a shape, a shape, an emitter,
// a texture in use) is a SceneError. Conventions mapped here:
// - camera: Mitsuba's sensor looks down +z of its to_world with +x to the image's left, so our
//   camera_to_world (+x right, -z forward) is to_world * diag(-1, 1, -1);
// - max_depth m (Mitsuba counts the camera vertex's emission as depth 1) is our m - 1; -1 is
//   kInfiniteDepth;
// - uvs stay in Mitsuba's convention (v = 0 is an image's top row; OBJ's v flipped as Mitsuba's
//   flip_tex_coords does by default), and image textures flip v in their uv transform.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "engine/formats/importers.h"
#include "engine/formats/mesh_placement.h"
#include "engine/formats/mitsuba/mitsuba_values.h"
#include "engine/formats/mitsuba/mitsuba_xml.h"
#include "engine/formats/scene_files.h"
#include "engine/fresnel.h"
#include "engine/json_reader.h"
#include "engine/shapes.h"

namespace rf {
namespace {

using mitsuba::Document;
using mitsuba::Node;

// Mitsuba's max_depth -1 (unbounded) becomes this many scattering events.
constexpr int kInfiniteDepth = 1024;
constexpr int kMitsubaRrDepth = 5;  // Mitsuba's path tracers' rr_depth default
constexpr double kPiD = 3.14159265358979323846;

// A plugin element and its children (properties and nested plugins), with what was read.
class Props {
 public:
  Props(Document& doc, const Node& n) : doc_(doc), node_(n), children_(doc.children(n)) {
    used_.assign(children_.size(), false);
    for (const Node& c : children_) {
      names_.push_back(c.has("name") ? doc.attr(c, "name") : "");
      if (names_.back().empty()) continue;
      for (size_t i = 0; i + 1 < names_.size(); ++i)
        if (names_[i] == names_.back())
          doc.fail(c, "property '" + names_.back() + "' given twice (first at line " +
                          std::to_string(children_[i].line()) + ")");
    }
  }

  const Node& node() const { return node_; }
  std::string type() { return doc_.attr(node_, "type"); }

  // The property child called `name`, or nullptr; marks it read.
  const Node* find(const std::string& name) {
    for (size_t i = 0; i < children_.size(); ++i)
      if (names_[i] == name) {
        used_[i] = true;
        return &children_[i];
      }
    return nullptr;
  }
  bool has(const std::string& name) const {
    return std::find(names_.begin(), names_.end(), name) != names_.end();
  }
  // Children with one of these tags (nested plugins and refs), named or not; marks them read.
  std::vector<Node> nested(std::initializer_list<const char*> tags) {
    std::vector<Node> out;
    for (size_t i = 0; i < children_.size(); ++i)
      for (const char* t : tags)
        if (children_[i].tag() == t) {
          used_[i] = true;
          out.push_back(children_[i]);
        }
    return out;
  }
  // Marks a property as known but ignored (it does not change the image).
  void ignore(const std::string& name) { find(name); }

  // Every child nobody read becomes a warning.
  void finish() {
    for (size_t i = 0; i < children_.size(); ++i)
      if (!used_[i])
        doc_.warn(children_[i], "not supported by this importer's '" +
                                    doc_.attr_or(node_, "type", node_.tag()) + "' " + node_.tag() +
                                    "; ignored");
  }

 private:
  Document& doc_;
  Node node_;
  std::vector<Node> children_;
  std::vector<std::string> names_;
  std::vector<bool> used_;
};

struct BsdfResult {
  int32_t material = -1;
  std::string unsupported;  // why it cannot be rendered ("" = fine)
  bool one_sided = false;   // a Mitsuba BSDF that is black from behind
  Node node;
  bool used = false, warned = false;
};

class MitsubaParser {
 public:
  MitsubaParser(Document& doc, Scene& scene, SceneFiles& files)
      : doc_(doc), scene_(scene), files_(files) {}

  void parse() {
    std::vector<Node> top = doc_.children(doc_.root());
    for (const Node& n : top)
      if (n.has("id")) {
        std::string id = doc_.attr(n, "id");
        auto [it, fresh] = ids_.emplace(id, n);
        if (!fresh) doc_.fail(n, "id '" + id + "' already used at " + it->second.where());
      }
    bool have_sensor = false, have_integrator = false;
    for (const Node& n : top) {
      std::string tag = n.tag();
      if (tag == "integrator") {
        if (have_integrator) doc_.fail(n, "a second <integrator>");
        have_integrator = true;
        parse_integrator(n, scene_.render.integrator);
      } else if (tag == "sensor") {
        if (have_sensor) {
          doc_.warn(n, "a second <sensor>: only the first one is rendered; ignored");
          continue;
        }
        have_sensor = true;
        parse_sensor(n);
      } else if (tag == "bsdf") {
        bsdf(n);
      } else if (tag == "texture") {
        // Parsed when a material refers to it.
      } else if (tag == "shape") {
        parse_shape(n, scene_.meshes, /*in_group=*/false);
      } else if (tag == "emitter") {
        parse_emitter(n);
      } else if (tag == "medium") {
        doc_.warn(n,
                  "participating media are not supported; ignored (refused where a shape uses it)");
      } else {
        doc_.warn(n, "unknown element <" + tag + "> in <scene>; ignored");
      }
    }
    if (!have_sensor) doc_.fail(doc_.root(), "the scene has no <sensor> (rayfarm needs a camera)");
    if (!have_integrator) {
      scene_.render.integrator = IntegratorSettings{};
      scene_.render.integrator.max_depth = kInfiniteDepth;
      scene_.render.integrator.rr_min_depth = kMitsubaRrDepth;  // as rr_depth maps (below)
    }
    for (auto& [key, b] : bsdfs_)
      if (!b.used && !b.unsupported.empty())
        doc_.warn(b.node, b.unsupported + " (not used by any shape; ignored)");
    if (scene_.materials.empty()) default_material();  // the engine wants at least one
  }

 private:
  // ---------------------------------------------------------------------------------------------
  // Values.

  [[noreturn]] void fail(const Node& n, const std::string& what) { doc_.fail(n, what); }

  double number(const Node& n, const std::string& text, const char* what = "value") {
    std::optional<double> v = mitsuba::parse_number(text);
    if (!v) fail(n, std::string("@") + what + ": '" + text + "' is not a number");
    return *v;
  }
  std::vector<double> numbers(const Node& n, const char* attribute) {
    std::string text = doc_.attr(n, attribute);
    std::optional<std::vector<double>> v = mitsuba::parse_numbers(text);
    if (!v) fail(n, std::string("@") + attribute + ": '" + text + "' is not a list of numbers");
    return *v;
  }

  float float_of(const Node& n) {
    std::string tag = n.tag();
    if (tag != "float" && tag != "integer") fail(n, "expected a <float>, got <" + tag + ">");
    return float(number(n, doc_.attr(n, "value")));
  }
  float get_float(Props& p, const std::string& name, float fallback) {
    const Node* n = p.find(name);
    return n ? float_of(*n) : fallback;
  }
  int get_int(Props& p, const std::string& name, int fallback) {
    const Node* n = p.find(name);
    if (!n) return fallback;
    if (n->tag() != "integer") fail(*n, "expected an <integer>, got <" + n->tag() + ">");
    std::string text = doc_.attr(*n, "value");
    double v = number(*n, text);
    if (v != std::floor(v) || std::fabs(v) > 2147483647.0)
      fail(*n, "@value: '" + text + "' is not an integer");
    return int(v);
  }
  bool get_bool(Props& p, const std::string& name, bool fallback) {
    const Node* n = p.find(name);
    if (!n) return fallback;
    if (n->tag() != "boolean") fail(*n, "expected a <boolean>, got <" + n->tag() + ">");
    std::string v = doc_.attr(*n, "value");
    if (v == "true" || v == "1") return true;
    if (v == "false" || v == "0") return false;
    fail(*n, "@value: '" + v + "' is not a boolean (true or false)");
  }
  std::string get_string(Props& p, const std::string& name, const std::string& fallback) {
    const Node* n = p.find(name);
    if (!n) return fallback;
    if (n->tag() != "string") fail(*n, "expected a <string>, got <" + n->tag() + ">");
    return doc_.attr(*n, "value");
  }
  Vec3 vec3_of(const Node& n, float fallback) {
    if (n.has("value")) {
      std::vector<double> v = numbers(n, "value");
      if (v.size() == 1) return Vec3(float(v[0]));
      if (v.size() != 3) fail(n, "@value: expected 3 numbers, got " + std::to_string(v.size()));
      return {float(v[0]), float(v[1]), float(v[2])};
    }
    Vec3 r(fallback);
    const char* axes[3] = {"x", "y", "z"};
    for (int i = 0; i < 3; ++i)
      if (n.has(axes[i])) r[i] = float(number(n, doc_.attr(n, axes[i]), axes[i]));
    return r;
  }
  Vec3 get_point(Props& p, const std::string& name, Vec3 fallback) {
    const Node* n = p.find(name);
    if (!n) return fallback;
    if (n->tag() != "point" && n->tag() != "vector")
      fail(*n, "expected a <point> or <vector>, got <" + n->tag() + ">");
    return vec3_of(*n, 0);
  }

  // rgb, spectrum, float: an RGB colour. bounded: a reflectance, each channel in [0, 1].
  RGB color_of(const Node& n, bool bounded) {
    std::string tag = n.tag();
    RGB c;
    if (tag == "rgb") {
      std::vector<double> v = numbers(n, "value");
      if (v.size() == 1) v = {v[0], v[0], v[0]};
      if (v.size() != 3)
        fail(n, "@value: expected 3 numbers (r, g, b), got " + std::to_string(v.size()));
      c = {float(v[0]), float(v[1]), float(v[2])};
    } else if (tag == "float" || tag == "integer") {
      c = RGB(float_of(n));
    } else if (tag == "spectrum") {
      if (n.has("filename")) fail(n, "spectra from files are not supported (give rgb values)");
      std::string text = doc_.attr(n, "value");
      if (text.find(':') == std::string::npos) {
        c = RGB(float(number(n, text)));
      } else {
        std::vector<double> nm, vals;
        std::string item;
        std::vector<std::string> items;
        for (char ch : text + ",")
          if (ch == ',') {
            items.push_back(item);
            item.clear();
          } else {
            item += ch;
          }
        for (const std::string& it : items) {
          if (it.find_first_not_of(" \t\r\n") == std::string::npos) continue;
          size_t colon = it.find(':');
          if (colon == std::string::npos)
            fail(n, "@value: '" + it + "' is not a wavelength:value pair");
          nm.push_back(number(n, it.substr(0, colon)));
          vals.push_back(number(n, it.substr(colon + 1)));
          if (nm.size() > 1 && !(nm.back() > nm[nm.size() - 2]))
            fail(n, "@value: wavelengths must increase");
        }
        c = mitsuba::spectrum_to_rgb(nm, vals);
        c = vmax(c, RGB(0.0f));
      }
    } else if (tag == "blackbody") {
      fail(n, "<blackbody> spectra are not supported (give rgb values)");
    } else {
      fail(n, "expected a colour (<rgb>, <spectrum> or <float>), got <" + tag + ">");
    }
    if (!is_finite(c)) fail(n, "@value: not finite");
    if (c.x < 0 || c.y < 0 || c.z < 0) fail(n, "@value: must not be negative");
    if (bounded && max_component(c) > 1.0f)
      fail(n, "@value: a reflectance must be at most 1 per channel");
    return c;
  }

  ColorParam color_param(Props& p, const std::string& name, RGB fallback, bool bounded) {
    ColorParam c;
    c.value = fallback;
    const Node* n = p.find(name);
    if (!n) return c;
    if (n->tag() == "texture" || n->tag() == "ref")
      c.texture = texture(*n);
    else
      c.value = color_of(*n, bounded);
    return c;
  }
  FloatParam float_param(Props& p, const std::string& name, float fallback, float lo, float hi) {
    FloatParam f;
    f.value = fallback;
    const Node* n = p.find(name);
    if (!n) return f;
    if (n->tag() == "texture" || n->tag() == "ref") {
      f.texture = texture(*n);
      return f;
    }
    f.value = float_of(*n);
    if (!(f.value >= lo && f.value <= hi))
      fail(*n, "@value: must be between " + format_number(lo) + " and " + format_number(hi) +
                   ", got " + format_number(f.value));
    return f;
  }

  // <transform>: its operations apply in the order written (each one after the previous).
  Mat4 transform_of(const Node& n) {
    if (n.tag() != "transform") fail(n, "expected a <transform>, got <" + n.tag() + ">");
    Mat4 m = Mat4::identity();
    for (const Node& op : doc_.children(n)) m = transform_op(op) * m;
    if (!m.is_finite()) fail(n, "the transform is not finite");
    return m;
  }
  Mat4 get_transform(Props& p, const std::string& name) {
    const Node* n = p.find(name);
    return n ? transform_of(*n) : Mat4::identity();
  }

  Mat4 transform_op(const Node& op) {
    std::string tag = op.tag();
    if (tag == "translate") return Mat4::translate(vec3_of(op, 0));
    if (tag == "scale") {
      Vec3 s = vec3_of(op, 1);
      if (s.x == 0 || s.y == 0 || s.z == 0) fail(op, "singular: a scale factor is 0");
      return Mat4::scale(s);
    }
    if (tag == "rotate") {
      Vec3 axis = vec3_of(op, 0);
      float angle = float(number(op, doc_.attr(op, "angle"), "angle"));
      if (!(length(axis) > 0)) fail(op, "the rotation axis must not be zero");
      return Mat4::rotate(axis, angle);
    }
    if (tag == "matrix") {
      std::vector<double> v = numbers(op, "value");
      Mat4 m;
      if (v.size() == 16) {
        for (int r = 0; r < 4; ++r)
          for (int c = 0; c < 4; ++c) m.m[r][c] = float(v[size_t(4 * r + c)]);
      } else if (v.size() == 9) {
        for (int r = 0; r < 3; ++r)
          for (int c = 0; c < 3; ++c) m.m[r][c] = float(v[size_t(3 * r + c)]);
      } else {
        fail(op,
             "@value: a matrix has 16 (4x4) or 9 (3x3) numbers, got " + std::to_string(v.size()));
      }
      if (m.m[3][0] != 0 || m.m[3][1] != 0 || m.m[3][2] != 0 || m.m[3][3] != 1)
        fail(op, "@value: projective matrices are not supported (the last row must be 0 0 0 1)");
      if (std::fabs(m.det3()) < 1e-12f) fail(op, "@value: the matrix is singular");
      return m;
    }
    if (tag == "lookat") {
      auto point = [&](const char* a) {
        std::vector<double> v = numbers(op, a);
        if (v.size() != 3)
          fail(op, std::string("@") + a + ": expected 3 numbers, got " + std::to_string(v.size()));
        return Vec3(float(v[0]), float(v[1]), float(v[2]));
      };
      Vec3 origin = point("origin"), target = point("target");
      Vec3 up = op.has("up") ? point("up") : Vec3(0, 1, 0);
      Vec3 dir = target - origin;
      if (!(length(dir) > 0)) fail(op, "@target: must differ from origin");
      dir = normalize(dir);
      if (!(length(cross(up, dir)) > 1e-6f))
        fail(op, "@up: must not be zero or parallel to the view direction");
      // Mitsuba's look-at frame: +x left, +y up, +z towards the target (the engine's right-handed
      // camera frame with x and z reversed).
      return Mat4::look_at(origin, target, up) * Mat4::scale({-1, 1, -1});
    }
    fail(op, "unknown transform operation <" + tag +
                 "> (known: translate, rotate, scale, matrix, lookat)");
  }

  static bool is_rotation(const Mat4& m) {
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        float d = m.m[0][a] * m.m[0][b] + m.m[1][a] * m.m[1][b] + m.m[2][a] * m.m[2][b];
        if (std::fabs(d - (a == b ? 1.0f : 0.0f)) > 1e-3f) return false;
      }
    return m.det3() > 0;
  }

  // ---------------------------------------------------------------------------------------------
  // Integrator, sensor, film, sampler.

  void parse_integrator(const Node& n, IntegratorSettings& out) {
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

  void parse_sensor(const Node& n) {
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
      if (!(fov_deg > 0 && fov_deg < 180))
        fail(*fov_node, "@value: fov must be in (0, 180) degrees");
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
      fail(
          t_node ? *t_node : n,
          "the sensor's to_world must be a rotation and a translation (no scale, shear or mirror)");
    }
    scene_.camera.camera_to_world = to_world * Mat4::scale({-1, 1, -1});

    if (type == "thinlens") {
      const Node* a = p.find("aperture_radius");
      if (!a) fail(n, "a thinlens sensor needs 'aperture_radius'");
      scene_.camera.lens_radius = float_of(*a);
      if (!(scene_.camera.lens_radius >= 0)) fail(*a, "@value: must be at least 0");
      scene_.camera.focus_distance = get_float(p, "focus_distance", get_float(p, "far_clip", 1e4f));
      if (!(scene_.camera.focus_distance > 0))
        fail(*p.find("focus_distance"), "@value: must be > 0");
    }
    for (const char* k :
         {"near_clip", "far_clip", "principal_point_offset_x", "principal_point_offset_y"})
      if (const Node* c = p.find(k)) {
        std::string name = k;
        if (name == "far_clip" && type == "thinlens") continue;
        doc_.warn(
            *c, "ignored: rayfarm's camera has no " +
                    std::string(name.find("clip") != std::string::npos ? "clipping planes"
                                                                       : "principal point offset"));
      }
    p.ignore("shutter_open");
    p.ignore("shutter_close");
    p.ignore("srf");
    p.finish();
  }

  void parse_film(const Node& n) {
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

  void parse_rfilter(const Node& n) {
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

  void parse_sampler(const Node& n) {
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

  // ---------------------------------------------------------------------------------------------
  // Textures.

  const Node& resolve_ref(const Node& ref) {
    std::string id = doc_.attr(ref, "id");
    auto it = ids_.find(id);
    if (it == ids_.end()) fail(ref, "reference to unknown id '" + id + "'");
    return it->second;
  }

  int32_t texture(const Node& at) {
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
        doc_.warn(*p.find("wrap_mode"),
                  "wrap mode '" + wrap + "' is not supported; textures repeat");
      p.ignore("format");
      p.ignore("accel");
    } else if (type == "checkerboard") {
      t.type = TextureType::Checkerboard;
      Props& pp = p;
      auto plain = [&](const char* name, float fallback) {
        const Node* c = pp.find(name);
        if (!c) return RGB(fallback);
        if (c->tag() == "texture" || c->tag() == "ref")
          fail(*c, "nested textures are not supported");
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

  // ---------------------------------------------------------------------------------------------
  // BSDFs.

  float ior(Props& p, const char* name, float fallback) {
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

  // alpha (or alpha_u/alpha_v) and distribution of a rough BSDF; Beckmann alpha is used as GGX
  // alpha.
  FloatParam roughness(Props& p, const Node& n) {
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

  uint32_t add_material(Material m) {
    scene_.materials.push_back(std::move(m));
    return uint32_t(scene_.materials.size() - 1);
  }

  uint32_t default_material() {
    if (default_material_ < 0) {
      Material m;
      m.name = "default diffuse";
      m.type = MaterialType::Diffuse;
      m.reflectance.value = RGB(0.5f);
      default_material_ = int32_t(add_material(m));
    }
    return uint32_t(default_material_);
  }

  BsdfResult& bsdf(const Node& at) {
    const Node& n = at.tag() == "ref" ? resolve_ref(at) : at;
    if (n.tag() != "bsdf")
      fail(at, "expected a bsdf, '" + doc_.attr_or(at, "id", "") + "' is a <" + n.tag() + ">");
    auto cached = bsdfs_.find(n.xml.internal_object());
    if (cached != bsdfs_.end()) return cached->second;
    BsdfResult r = parse_bsdf(n);
    return bsdfs_.emplace(n.xml.internal_object(), std::move(r)).first->second;
  }

  BsdfResult parse_bsdf(const Node& n) {
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
        fail(n,
             "int_ior / ext_ior must be between 1 and 4 (exclusive), got " + format_number(m.ior));
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

  void parse_conductor(Props& p, const Node& n, Material& m) {
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

  // Mitsuba's plastic with nonlinear = false scales the diffuse base by 1 / (1 - F_dr,int); the
  // engine's plastic is the nonlinear one, R / (1 - R F_dr,int). The base R' = R / (1 - F + R F)
  // (F = F_dr,int) gives the same reflectance, exactly, for a constant R.
  void parse_plastic(Props& p, const Node& n, Material& m) {
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

  // ---------------------------------------------------------------------------------------------
  // Shapes.

  void parse_shape(const Node& n, std::vector<Mesh>& out, bool in_group) {
    Props p(doc_, n);
    std::string type = p.type();
    if (type == "shapegroup") {
      if (in_group) fail(n, "a shapegroup inside a shapegroup");
      if (!n.has("id")) fail(n, "a shapegroup needs an 'id'");
      SceneObject obj;
      obj.name = doc_.attr(n, "id");
      for (const Node& c : p.nested({"shape"})) parse_shape(c, obj.meshes, true);
      p.finish();
      groups_[n.xml.internal_object()] = uint32_t(scene_.objects.size());
      scene_.objects.push_back(std::move(obj));
      return;
    }
    if (type == "instance") {
      if (in_group) fail(n, "an instance inside a shapegroup");
      std::vector<Node> refs = p.nested({"ref", "shape"});
      if (refs.size() != 1) fail(n, "an instance needs one <ref> to a shapegroup");
      const Node& g = refs[0].tag() == "ref" ? resolve_ref(refs[0]) : refs[0];
      auto it = groups_.find(g.xml.internal_object());
      if (it == groups_.end()) fail(refs[0], "does not name a shapegroup defined before it");
      scene_.instances.push_back({it->second, get_transform(p, "to_world")});
      p.finish();
      return;
    }
    Mesh mesh;
    mesh.name = n.has("id") ? doc_.attr(n, "id") : n.path;
    Mat4 to_world = get_transform(p, "to_world");
    MeshData data;
    std::string where = n.path;
    if (type == "obj" || type == "ply") {
      std::string file = get_string(p, "filename", "");
      if (file.empty()) fail(n, "a '" + type + "' shape needs 'filename'");
      const Node& fn = *p.find("filename");
      where = n.path + " (" + file + ")";
      data = doc_.with_location(fn, [&] { return files_.mesh(file, type, fn.path); });
      if (type == "obj" && get_bool(p, "flip_tex_coords", true))
        for (Vec2& uv : data.uvs) uv.y = 1 - uv.y;  // as Mitsuba: OBJ's v = 0 is the bottom row
    } else if (type == "rectangle") {
      data = make_rectangle();
    } else if (type == "cube") {
      data = make_cube();
    } else if (type == "disk") {
      data = make_disk(128);
    } else if (type == "sphere") {
      Vec3 c = get_point(p, "center", Vec3(0.0f));
      float r = get_float(p, "radius", 1.0f);
      if (!(r > 0)) fail(*p.find("radius"), "@value: the radius must be > 0");
      // Mitsuba's parametrisation (mitsuba_sphere) as make_sphere's axes; exact under a
      // similarity, a mesh otherwise (tessellated only then: a scene of 500,000 exact spheres
      // imports in time linear in their number, with no mesh per sphere).
      static const Vec3 kAxes[3] = {{1, 0, 0}, {0, 0, -1}, {0, -1, 0}};  // v = theta / pi
      SphereShape sphere;
      if (place_sphere(c, r, kAxes, to_world, sphere))
        mesh.sphere = sphere;
      else
        data = mitsuba_sphere();
      to_world = to_world * Mat4::translate(c) * Mat4::scale(Vec3(r));
    } else {
      fail(n, "unsupported shape '" + type +
                  "' (supported: obj, ply, rectangle, cube, sphere, disk, shapegroup, instance)");
    }
    if (get_bool(p, "face_normals", false)) data.normals.clear();
    if (get_bool(p, "flip_normals", false)) {
      for (size_t i = 0; i + 2 < data.indices.size(); i += 3)
        std::swap(data.indices[i + 1], data.indices[i + 2]);
      for (Vec3& nn : data.normals) nn = -nn;
    }
    // Material and emission: nested or referenced.
    std::vector<Node> bsdf_only, emitters = p.nested({"emitter"});
    for (const Node& b : p.nested({"bsdf", "ref"})) {
      if (b.tag() == "ref") {
        const Node& target = resolve_ref(b);
        if (target.tag() == "emitter") {
          emitters.push_back(target);
          continue;
        }
        if (target.tag() == "medium") fail(b, "participating media are not supported");
        if (target.tag() != "bsdf")
          fail(b, "a shape refers to a bsdf or an emitter; '" + doc_.attr(b, "id") + "' is a <" +
                      target.tag() + ">");
      }
      bsdf_only.push_back(b);
    }
    if (bsdf_only.size() > 1) fail(bsdf_only[1], "a shape has one bsdf");
    if (bsdf_only.empty()) {
      mesh.material = default_material();
      if (!default_warned_) {
        doc_.warn(n,
                  "no bsdf: Mitsuba's default one-sided diffuse (0.5) is used, shaded on both "
                  "sides here");
        default_warned_ = true;
      }
    } else {
      BsdfResult& b = bsdf(bsdf_only[0]);
      b.used = true;
      if (!b.unsupported.empty())
        fail(bsdf_only[0],
             b.unsupported + (b.node.xml == bsdf_only[0].xml ? "" : " (" + b.node.where() + ")"));
      mesh.material = uint32_t(b.material);
      if (b.one_sided && !b.warned) {
        doc_.warn(b.node,
                  "Mitsuba's '" + doc_.attr(b.node, "type") +
                      "' is one-sided (black seen from behind unless wrapped in 'twosided'); "
                      "rayfarm shades both sides alike, so back faces seen by the camera differ");
        b.warned = true;
      }
    }
    if (emitters.size() > 1) fail(emitters[1], "a shape has at most one emitter");
    if (!emitters.empty()) {
      if (in_group) fail(emitters[0], "emitters inside a shapegroup are not supported");
      mesh.emission = area_emission(emitters[0]);
    }
    for (const Node& m : p.nested({"medium"})) fail(m, "participating media are not supported");
    p.finish();
    if (!mesh.sphere) place_mesh(std::move(data), to_world, n.file(), where, mesh);
    out.push_back(std::move(mesh));
  }

  // Mitsuba's sphere: pole on +z, uv = (phi / 2pi, theta / pi) with phi from +x towards +y. The
  // engine's UV sphere (pole +y, 64 x 128) turned by +90 degrees about x has exactly that frame.
  static MeshData mitsuba_sphere() {
    static const MeshData sphere = [] {
      MeshData d = make_sphere(Vec3(0.0f), 1.0f, 64, 128);
      auto turn = [](Vec3 v) { return Vec3(v.x, -v.z, v.y); };
      for (Vec3& v : d.positions) v = turn(v);
      for (Vec3& v : d.normals) v = turn(v);
      for (Vec2& uv : d.uvs) uv.y = 1 - uv.y;
      return d;
    }();
    return sphere;
  }

  std::optional<Emission> area_emission(const Node& n) {
    Props p(doc_, n);
    std::string type = p.type();
    if (type != "area") fail(n, "a shape's emitter must be 'area', got '" + type + "'");
    const Node* rad = p.find("radiance");
    if (rad && (rad->tag() == "texture" || rad->tag() == "ref"))
      fail(*rad, "textured emission is not supported");
    Emission e;
    e.radiance = rad ? color_of(*rad, false) : RGB(1.0f);
    p.finish();
    if (is_black(e.radiance)) return std::nullopt;
    return e;
  }

  // ---------------------------------------------------------------------------------------------
  // Emitters that are not shapes.

  void parse_emitter(const Node& n) {
    Props p(doc_, n);
    std::string type = p.type();
    Light l;
    l.name = n.has("id") ? doc_.attr(n, "id") : n.path;
    auto intensity = [&](const char* name) {
      const Node* c = p.find(name);
      if (c && (c->tag() == "texture" || c->tag() == "ref"))
        fail(*c, "textured emission is not supported");
      return c ? color_of(*c, false) : RGB(1.0f);
    };
    if (type == "point") {
      l.type = LightType::Point;
      Mat4 m = get_transform(p, "to_world");
      l.position = get_point(p, "position", m.point(Vec3(0.0f)));
      l.intensity = intensity("intensity");
    } else if (type == "spot") {
      l.type = LightType::Spot;
      Mat4 m = get_transform(p, "to_world");
      l.position = m.point(Vec3(0.0f));
      Vec3 d = m.vector({0, 0, 1});
      if (!(length(d) > 0)) fail(n, "the spot light's to_world maps +z to zero");
      l.direction = normalize(d);
      l.intensity = intensity("intensity");
      l.cone_angle_deg = get_float(p, "cutoff_angle", 20.0f);
      l.falloff_start_deg = get_float(p, "beam_width", l.cone_angle_deg * 0.75f);
      if (!(l.cone_angle_deg > 0 && l.cone_angle_deg <= 90))
        fail(n, "cutoff_angle must be in (0, 90] degrees");
      if (!(l.falloff_start_deg >= 0)) fail(n, "beam_width must be at least 0");
      l.falloff_start_deg = std::min(l.falloff_start_deg, l.cone_angle_deg);
      if (l.falloff_start_deg < l.cone_angle_deg)
        doc_.warn(n,
                  "the falloff between beam_width and cutoff_angle is a smoothstep here, linear in "
                  "angle in Mitsuba");
      if (p.find("texture")) fail(n, "projected spot light textures are not supported");
    } else if (type == "directional") {
      l.type = LightType::Directional;
      Mat4 m = get_transform(p, "to_world");
      Vec3 d = get_point(p, "direction", m.vector({0, 0, 1}));
      if (!(length(d) > 0)) fail(n, "the direction must not be zero");
      l.direction = normalize(d);
      l.irradiance = intensity("irradiance");
    } else if (type == "constant" || type == "envmap") {
      if (scene_.environment) fail(n, "a second environment emitter (constant or envmap)");
      Environment env;
      if (type == "constant") {
        env.scale = intensity("radiance");
      } else {
        std::string file = get_string(p, "filename", "");
        if (file.empty()) fail(n, "an envmap needs 'filename'");
        const Node& fn = *p.find("filename");
        env.file =
            doc_.with_location(fn, [&] { return files_.add(file, fn.path, "environment map"); });
        env.resolved_path = files_.path_of(env.file);
        env.scale = RGB(get_float(p, "scale", 1.0f));
        Mat4 m = get_transform(p, "to_world");
        if (!is_rotation(m)) fail(*p.find("to_world"), "an envmap's to_world must be a rotation");
        // Mitsuba's u = atan2(x, -z) / 2pi is the engine's u minus 1/2: a half turn about y.
        env.to_world = m * Mat4::rotate({0, 1, 0}, 180);
        p.ignore("mis_compensation");
      }
      scene_.environment = env;
      p.finish();
      return;
    } else if (type == "area") {
      fail(n, "an 'area' emitter must be nested in a shape");
    } else {
      fail(n, "unsupported emitter '" + type +
                  "' (supported: area (in a shape), point, spot, directional, constant, envmap)");
    }
    p.finish();
    scene_.lights.push_back(l);
  }

  Document& doc_;
  Scene& scene_;
  SceneFiles& files_;
  std::map<std::string, Node> ids_;
  std::map<const void*, BsdfResult> bsdfs_;
  std::map<const void*, int32_t> textures_;
  std::map<const void*, uint32_t> groups_;
  int32_t default_material_ = -1;
  bool default_warned_ = false;
};

}  // namespace

void import_mitsuba(const std::string& bytes, SceneFiles& files, Scene& scene) {
  mitsuba::Document doc(scene.path, bytes, files, scene.warnings);
  MitsubaParser parser(doc, scene, files);
  parser.parse();
}

}  // namespace rf
