// The Mitsuba 3 XML importer (docs/formats/mitsuba.md): plugins of a <scene> mapped onto the
// engine's Scene by one parser, declared here and defined by concept: mitsuba_scene.cpp (the
// <scene>, values and transforms, the entry point), mitsuba_settings.cpp (integrator, sensor,
// film, sampler), mitsuba_materials.cpp (textures, BSDFs), mitsuba_shapes.cpp and
// mitsuba_emitters.cpp. The XML layer (includes, defaults, $substitution, locations) is
// mitsuba_xml.h; value tables and spectra are mitsuba_values.h.
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
#pragma once

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

namespace rf::mitsuba {

// Mitsuba's max_depth -1 (unbounded) becomes this many scattering events.
inline constexpr int kInfiniteDepth = 1024;
inline constexpr int kMitsubaRrDepth = 5;  // Mitsuba's path tracers' rr_depth default
inline constexpr double kPiD = 3.14159265358979323846;

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

  void parse();

 private:
  // ---------------------------------------------------------------------------------------------
  // Values.

  [[noreturn]] void fail(const Node& n, const std::string& what);
  double number(const Node& n, const std::string& text, const char* what = "value");
  std::vector<double> numbers(const Node& n, const char* attribute);
  float float_of(const Node& n);
  float get_float(Props& p, const std::string& name, float fallback);
  int get_int(Props& p, const std::string& name, int fallback);
  bool get_bool(Props& p, const std::string& name, bool fallback);
  std::string get_string(Props& p, const std::string& name, const std::string& fallback);
  Vec3 vec3_of(const Node& n, float fallback);
  Vec3 get_point(Props& p, const std::string& name, Vec3 fallback);

  // rgb, spectrum, float: an RGB colour. bounded: a reflectance, each channel in [0, 1].
  RGB color_of(const Node& n, bool bounded);
  ColorParam color_param(Props& p, const std::string& name, RGB fallback, bool bounded);
  FloatParam float_param(Props& p, const std::string& name, float fallback, float lo, float hi);

  // <transform>: its operations apply in the order written (each one after the previous).
  Mat4 transform_of(const Node& n);
  Mat4 get_transform(Props& p, const std::string& name);
  Mat4 transform_op(const Node& op);
  static bool is_rotation(const Mat4& m);

  // ---------------------------------------------------------------------------------------------
  // Integrator, sensor, film, sampler.

  void parse_integrator(const Node& n, IntegratorSettings& out);
  void parse_sensor(const Node& n);
  void parse_film(const Node& n);
  void parse_rfilter(const Node& n);
  void parse_sampler(const Node& n);

  // ---------------------------------------------------------------------------------------------
  // Textures.

  const Node& resolve_ref(const Node& ref);
  int32_t texture(const Node& at);

  // ---------------------------------------------------------------------------------------------
  // BSDFs.

  float ior(Props& p, const char* name, float fallback);

  // alpha (or alpha_u/alpha_v) and distribution of a rough BSDF; Beckmann alpha is used as GGX
  // alpha.
  FloatParam roughness(Props& p, const Node& n);
  uint32_t add_material(Material m);
  uint32_t default_material();
  BsdfResult& bsdf(const Node& at);
  BsdfResult parse_bsdf(const Node& n);
  void parse_conductor(Props& p, const Node& n, Material& m);

  // Mitsuba's plastic with nonlinear = false scales the diffuse base by 1 / (1 - F_dr,int); the
  // engine's plastic is the nonlinear one, R / (1 - R F_dr,int). The base R' = R / (1 - F + R F)
  // (F = F_dr,int) gives the same reflectance, exactly, for a constant R.
  void parse_plastic(Props& p, const Node& n, Material& m);

  // ---------------------------------------------------------------------------------------------
  // Shapes.

  void parse_shape(const Node& n, std::vector<Mesh>& out, bool in_group);

  // Mitsuba's sphere: pole on +z, uv = (phi / 2pi, theta / pi) with phi from +x towards +y. The
  // engine's UV sphere (pole +y, 64 x 128) turned by +90 degrees about x has exactly that frame.
  static MeshData mitsuba_sphere();
  std::optional<Emission> area_emission(const Node& n);

  // ---------------------------------------------------------------------------------------------
  // Emitters that are not shapes.

  void parse_emitter(const Node& n);

  // ---------------------------------------------------------------------------------------------
  // State: the document, the scene being filled, its files, and what was parsed once by id.

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

}  // namespace rf::mitsuba
