// The Mitsuba 3 importer's <scene> element, values and transforms, and its entry point
// (mitsuba_parser.h).
#include "engine/formats/mitsuba/mitsuba_parser.h"

#include <optional>

namespace rf::mitsuba {

void MitsubaParser::parse() {
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

void MitsubaParser::fail(const Node& n, const std::string& what) { doc_.fail(n, what); }

double MitsubaParser::number(const Node& n, const std::string& text, const char* what) {
  std::optional<double> v = mitsuba::parse_number(text);
  if (!v) fail(n, std::string("@") + what + ": '" + text + "' is not a number");
  return *v;
}

std::vector<double> MitsubaParser::numbers(const Node& n, const char* attribute) {
  std::string text = doc_.attr(n, attribute);
  std::optional<std::vector<double>> v = mitsuba::parse_numbers(text);
  if (!v) fail(n, std::string("@") + attribute + ": '" + text + "' is not a list of numbers");
  return *v;
}

float MitsubaParser::float_of(const Node& n) {
  std::string tag = n.tag();
  if (tag != "float" && tag != "integer") fail(n, "expected a <float>, got <" + tag + ">");
  return float(number(n, doc_.attr(n, "value")));
}

float MitsubaParser::get_float(Props& p, const std::string& name, float fallback) {
  const Node* n = p.find(name);
  return n ? float_of(*n) : fallback;
}

int MitsubaParser::get_int(Props& p, const std::string& name, int fallback) {
  const Node* n = p.find(name);
  if (!n) return fallback;
  if (n->tag() != "integer") fail(*n, "expected an <integer>, got <" + n->tag() + ">");
  std::string text = doc_.attr(*n, "value");
  double v = number(*n, text);
  if (v != std::floor(v) || std::fabs(v) > 2147483647.0)
    fail(*n, "@value: '" + text + "' is not an integer");
  return int(v);
}

bool MitsubaParser::get_bool(Props& p, const std::string& name, bool fallback) {
  const Node* n = p.find(name);
  if (!n) return fallback;
  if (n->tag() != "boolean") fail(*n, "expected a <boolean>, got <" + n->tag() + ">");
  std::string v = doc_.attr(*n, "value");
  if (v == "true" || v == "1") return true;
  if (v == "false" || v == "0") return false;
  fail(*n, "@value: '" + v + "' is not a boolean (true or false)");
}

std::string MitsubaParser::get_string(Props& p, const std::string& name,
                                      const std::string& fallback) {
  const Node* n = p.find(name);
  if (!n) return fallback;
  if (n->tag() != "string") fail(*n, "expected a <string>, got <" + n->tag() + ">");
  return doc_.attr(*n, "value");
}

Vec3 MitsubaParser::vec3_of(const Node& n, float fallback) {
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

Vec3 MitsubaParser::get_point(Props& p, const std::string& name, Vec3 fallback) {
  const Node* n = p.find(name);
  if (!n) return fallback;
  if (n->tag() != "point" && n->tag() != "vector")
    fail(*n, "expected a <point> or <vector>, got <" + n->tag() + ">");
  return vec3_of(*n, 0);
}

RGB MitsubaParser::color_of(const Node& n, bool bounded) {
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

ColorParam MitsubaParser::color_param(Props& p, const std::string& name, RGB fallback,
                                      bool bounded) {
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

FloatParam MitsubaParser::float_param(Props& p, const std::string& name, float fallback, float lo,
                                      float hi) {
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

Mat4 MitsubaParser::transform_of(const Node& n) {
  if (n.tag() == "animation") {
    // Mitsuba 0.6's animated transform; Mitsuba 3's XML has none. Its first key stands.
    std::optional<Node> first;
    for (const Node& k : doc_.children(n))
      if (!first && k.tag() == "transform") first = k;
    if (!first) fail(n, "an <animation> without a <transform> key");
    doc_.warn(n,
              "<animation>: Mitsuba 3 scenes have no animated transforms and rayfarm reads "
              "none from this format: the motion is dropped, the first key's transform is "
              "used (give the keys in rayfarm's JSON, pbrt-v4 or glTF to move it)");
    return transform_of(*first);
  }
  if (n.tag() != "transform") fail(n, "expected a <transform>, got <" + n.tag() + ">");
  Mat4 m = Mat4::identity();
  for (const Node& op : doc_.children(n)) m = transform_op(op) * m;
  if (!m.is_finite()) fail(n, "the transform is not finite");
  return m;
}

Mat4 MitsubaParser::get_transform(Props& p, const std::string& name) {
  const Node* n = p.find(name);
  return n ? transform_of(*n) : Mat4::identity();
}

Mat4 MitsubaParser::transform_op(const Node& op) {
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
      fail(op, "@value: a matrix has 16 (4x4) or 9 (3x3) numbers, got " + std::to_string(v.size()));
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

bool MitsubaParser::is_rotation(const Mat4& m) {
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) {
      float d = m.m[0][a] * m.m[0][b] + m.m[1][a] * m.m[1][b] + m.m[2][a] * m.m[2][b];
      if (std::fabs(d - (a == b ? 1.0f : 0.0f)) > 1e-3f) return false;
    }
  return m.det3() > 0;
}

}  // namespace rf::mitsuba

namespace rf {

void import_mitsuba(const std::string& bytes, SceneFiles& files, Scene& scene) {
  mitsuba::Document doc(scene.path, bytes, files, scene.warnings);
  mitsuba::MitsubaParser parser(doc, scene, files);
  parser.parse();
}

}  // namespace rf
