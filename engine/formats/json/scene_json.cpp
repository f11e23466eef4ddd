// The native scene format, version 1 (docs/scene-format.md): a JSON file plus mesh files beside
// it. Parsing and validation live here in one place; every problem becomes a SceneError that
// names the scene file, the JSON path (or line and column) and what was expected.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>
#include <set>
#include <sstream>
#include <string_view>

#include "engine/digest.h"
#include "engine/formats/importers.h"
#include "engine/formats/mesh_placement.h"
#include "engine/formats/scene_files.h"
#include "engine/json_reader.h"
#include "engine/mesh_io.h"
#include "engine/shapes.h"
#include "engine/scene.h"

namespace rf {
namespace {

using json = nlohmann::json;
namespace fs = std::filesystem;

constexpr int kFormatVersion = 1;

const std::vector<std::string> kMaterialTypes = {"diffuse",         "conductor",        "rough_conductor",
                                                 "dielectric",      "thin_dielectric",  "rough_dielectric",
                                                 "plastic"};
const std::vector<std::string> kShapeTypes = {"obj",  "ply",    "mesh",  "rectangle",
                                              "cube", "sphere", "disk"};
const std::vector<std::string> kLightTypes = {"point", "spot", "directional"};
const std::vector<std::string> kTextureTypes = {"constant", "checkerboard", "image"};

// ---------------------------------------------------------------------------------------------
// The scene file.

class SceneParser {
 public:
  SceneParser(const std::string& path, Scene& scene, SceneFiles& files)
      : r_(path), scene_(scene), files_(files) {}

  void parse(const json& root) {
    r_.expect_object(root, "");
    parse_version(root);
    r_.check_keys(root, "",
                  {"format", "version", "time", "camera", "film", "render", "textures", "materials",
                   "shapes", "lights", "environment", "objects", "instances"});
    if (const json* t = r_.find(root, "time")) parse_time(*t);
    parse_camera(r_.require(root, "", "camera"));
    parse_film(r_.require(root, "", "film"));
    if (const json* j = r_.find(root, "render"))
      parse_render(*j);
    else
      set_default_passes();
    if (const json* t = r_.find(root, "textures")) parse_textures(*t);
    parse_materials(r_.require(root, "", "materials"));
    const json& shapes = r_.array(r_.require(root, "", "shapes"), "shapes");
    for (size_t i = 0; i < shapes.size(); ++i)
      parse_world_shape(shapes[i], json_child("shapes", i));
    if (const json* o = r_.find(root, "objects")) parse_objects(*o);
    if (const json* i = r_.find(root, "instances")) parse_instances(*i);
    if (const json* l = r_.find(root, "lights")) {
      r_.array(*l, "lights");
      for (size_t i = 0; i < l->size(); ++i) parse_light((*l)[i], json_child("lights", i));
    }
    if (const json* e = r_.find(root, "environment")) parse_environment(*e);
  }

 private:
  void parse_version(const json& root) {
    if (const json* f = r_.find(root, "format"))
      if (r_.string(*f, "format") != "rayfarm-scene")
        r_.fail("format", "expected \"rayfarm-scene\", got " + describe_json(*f));
    const json* v = r_.find(root, "version");
    if (!v) r_.fail("version", "required key is missing (this build reads version 1)");
    if (!v->is_number_integer() || v->get<int64_t>() != kFormatVersion)
      r_.fail("version", "unsupported format version " + v->dump() + " (this build reads version " +
                             std::to_string(kFormatVersion) + ")");
  }

  // "time": {"fps": 24, "shutter": {"open": 0, "close": 0.5, "unit": "frames", "curve": "box"}}.
  void parse_time(const json& j) {
    const std::string p = "time";
    r_.check_keys(j, p, {"fps", "shutter"});
    ShotTime& t = scene_.time;
    if (const json* f = r_.find(j, "fps")) {
      t.fps = r_.real(*f, "time.fps");
      if (!(t.fps > 0 && t.fps <= 1e6))
        r_.fail("time.fps", "must be above 0 and at most 1000000, got " + f->dump());
    }
    if (const json* sh = r_.find(j, "shutter")) {
      const std::string q = "time.shutter";
      r_.check_keys(*sh, q, {"open", "close", "unit", "curve"});
      double scale = 1;  // to frames
      if (const json* u = r_.find(*sh, "unit")) {
        const std::string unit = r_.string(*u, q + ".unit");
        if (unit == "seconds")
          scale = t.fps;
        else if (unit != "frames")
          r_.fail(q + ".unit", "unknown unit '" + unit + "' (known: frames, seconds)");
      }
      if (const json* c = r_.find(*sh, "curve"))
        if (const std::string curve = r_.string(*c, q + ".curve"); curve != "box")
          r_.fail(q + ".curve", "unknown shutter curve '" + curve + "' (known: box)");
      auto frames = [&](const char* key, double fallback) {
        const json* v = r_.find(*sh, key);
        if (!v) return fallback;
        const double x = r_.real(*v, q + "." + key) * scale;
        if (!(std::fabs(x) <= kMaxShutterFrames))
          r_.fail(q + "." + key, "must lie within " + format_number(kMaxShutterFrames) +
                                     " frames of the frame's start, got " + v->dump());
        return x;
      };
      t.shutter_open = frames("open", 0);
      t.shutter_close = frames("close", t.shutter_open + 0.5);
      if (t.shutter_close < t.shutter_open)
        r_.fail(q + ".close", "the shutter closes (" + format_number(t.shutter_close) +
                                  " frames) before it opens (" + format_number(t.shutter_open) +
                                  ")");
    }
  }

  // A keyframe list at path p: [{"frame": F or "time": SECONDS, ...}], times increasing, each
  // key's matrix from transform_of(key, key path), whose keys are `keys` besides frame and time.
  template <class TransformOf>
  AnimatedTransform parse_keyframes(const json& list, const std::string& p,
                                    std::initializer_list<const char*> keys,
                                    TransformOf&& transform_of) {
    r_.array(list, p);
    if (list.empty()) r_.fail(p, "needs at least one key");
    std::vector<std::string> allowed = {"frame", "time"};
    allowed.insert(allowed.end(), keys.begin(), keys.end());
    std::vector<Keyframe> frames;
    for (size_t i = 0; i < list.size(); ++i) {
      const std::string q = json_child(p, i);
      const json& k = list[i];
      r_.expect_object(k, q);
      r_.check_keys(k, q, allowed);
      const json* frame = r_.find(k, "frame");
      const json* time = r_.find(k, "time");
      if (!frame == !time) r_.fail(q, "give its 'frame' or its 'time' (seconds), one of them");
      const double at =
          frame ? r_.real(*frame, q + ".frame") / scene_.time.fps : r_.real(*time, q + ".time");
      if (!std::isfinite(at)) r_.fail(q, "the key's time is not finite");
      if (!frames.empty() && !(at > frames.back().time))
        r_.fail(q + (frame ? ".frame" : ".time"),
                "keys must be in increasing time: this one is not after " + json_child(p, i - 1));
      frames.push_back({at, transform_of(k, q)});
    }
    try {
      return AnimatedTransform(frames);
    } catch (const std::invalid_argument& e) {
      r_.fail(p, e.what());
    }
  }

  // camera.keyframes: keys with a 'look_at' or a 'to_world'; the camera_to_world of a moving
  // camera (Camera::motion).
  void parse_camera_keyframes(const json& keys) {
    scene_.camera.motion = parse_keyframes(
        keys, "camera.keyframes", {"look_at", "to_world"},
        [&](const json& k, const std::string& q) { return camera_transform(k, q); });
    scene_.camera.camera_to_world = scene_.camera.motion.keys().front().m;
  }

  // A shape's or an instance's "keyframes": keys with a 'transform' (the transform list; a key
  // without one is the identity).
  AnimatedTransform parse_motion(const json& keys, const std::string& p) {
    return parse_keyframes(keys, p, {"transform"}, [&](const json& k, const std::string& q) {
      const json* t = r_.find(k, "transform");
      return t ? parse_transform(*t, q + ".transform") : Mat4::identity();
    });
  }

  // A camera's transform from its 'look_at' or 'to_world' (at path p).
  Mat4 camera_transform(const json& j, const std::string& p) {
    const json* look = r_.find(j, "look_at");
    const json* to_world = r_.find(j, "to_world");
    if (!look && !to_world) r_.fail(p, "needs either 'look_at' or 'to_world'");
    if (look && to_world) r_.fail(p, "give either 'look_at' or 'to_world', not both");
    return look ? parse_look_at(*look, p + ".look_at")
                : parse_camera_matrix(*to_world, p + ".to_world");
  }

  void parse_camera(const json& j) {
    const std::string p = "camera";
    r_.check_keys(j, p,
                  {"type", "fov_deg", "look_at", "to_world", "keyframes", "aperture_radius",
                   "focus_distance"});
    if (const json* t = r_.find(j, "type"))
      if (std::string type = r_.string(*t, "camera.type"); type != "perspective")
        r_.fail("camera.type", "unknown camera type '" + type + "' (known: perspective)");
    float fov = r_.number(r_.require(j, p, "fov_deg"), "camera.fov_deg");
    if (!(fov > 0 && fov < 180))
      r_.fail("camera.fov_deg",
              "must be between 0 and 180 degrees (exclusive), got " + format_number(fov));
    scene_.camera.fov_deg = fov;
    if (const json* keys = r_.find(j, "keyframes")) {
      if (r_.find(j, "look_at") || r_.find(j, "to_world"))
        r_.fail("camera.keyframes",
                "give the camera's 'keyframes' or one 'look_at'/'to_world', "
                "not both");
      parse_camera_keyframes(*keys);
    } else {
      scene_.camera.camera_to_world = camera_transform(j, p);
    }
    if (const json* a = r_.find(j, "aperture_radius")) {
      scene_.camera.lens_radius = r_.number(*a, "camera.aperture_radius");
      if (scene_.camera.lens_radius < 0)
        r_.fail("camera.aperture_radius", "must be at least 0, got " + a->dump());
    }
    if (const json* f = r_.find(j, "focus_distance")) {
      scene_.camera.focus_distance = r_.number(*f, "camera.focus_distance");
      if (!(scene_.camera.focus_distance > 0))
        r_.fail("camera.focus_distance", "must be > 0, got " + f->dump());
    } else if (scene_.camera.lens_radius > 0) {
      r_.fail("camera.focus_distance", "required when aperture_radius > 0");
    }
  }

  Mat4 parse_look_at(const json& j, const std::string& p) {
    r_.check_keys(j, p, {"eye", "target", "up"});
    Vec3 eye = r_.vec3(r_.require(j, p, "eye"), p + ".eye");
    Vec3 target = r_.vec3(r_.require(j, p, "target"), p + ".target");
    Vec3 up = r_.vec3(r_.require(j, p, "up"), p + ".up");
    if (!(length(target - eye) > 0)) r_.fail(p + ".target", "must differ from eye");
    try {
      return Mat4::look_at(eye, target, up);
    } catch (const std::domain_error&) {
      r_.fail(p + ".up", "must not be zero or parallel to the view direction");
    }
  }

  // The camera matrix must be a rotation and a translation: a scale or shear would silently
  // change the field of view, a mirror the handedness.
  Mat4 parse_camera_matrix(const json& j, const std::string& p) {
    Mat4 m = r_.matrix(j, p);
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) {
        float d = m.m[0][a] * m.m[0][b] + m.m[1][a] * m.m[1][b] + m.m[2][a] * m.m[2][b];
        if (std::fabs(d - (a == b ? 1.0f : 0.0f)) > 1e-3f)
          r_.fail(p, "the upper 3x3 must be a rotation (orthonormal columns), no scale or shear");
      }
    if (m.det3() < 0) r_.fail(p, "the upper 3x3 must be a rotation, not a mirror (det < 0)");
    return m;
  }

  void parse_film(const json& j) {
    const std::string p = "film";
    r_.check_keys(j, p, {"resolution", "filter"});
    const json& res = r_.array(r_.require(j, p, "resolution"), "film.resolution", 2);
    scene_.film.width = int(r_.integer(res[0], "film.resolution[0]", 1, kMaxResolution));
    scene_.film.height = int(r_.integer(res[1], "film.resolution[1]", 1, kMaxResolution));
    scene_.film.filter = {};
    if (const json* f = r_.find(j, "filter")) {
      r_.check_keys(*f, "film.filter", {"type", "radius", "sigma"});
      std::string type = r_.string(r_.require(*f, "film.filter", "type"), "film.filter.type");
      if (!contains_name(known_filters(), type))
        r_.fail("film.filter.type",
                "unknown filter '" + type + "' (known: " + join_names(known_filters()) + ")");
      scene_.film.filter.type = filter_type(type);
      scene_.film.filter.radius = default_filter_radius(scene_.film.filter.type);
      if (const json* sg = r_.find(*f, "sigma")) {
        if (type != "gaussian") r_.fail("film.filter.sigma", "only the gaussian filter has a sigma");
        float sigma = r_.number(*sg, "film.filter.sigma");
        if (!(sigma > 0)) r_.fail("film.filter.sigma", "must be > 0, got " + sg->dump());
        scene_.film.filter.sigma = sigma;
      }
      if (const json* rad = r_.find(*f, "radius")) {
        float radius = r_.number(*rad, "film.filter.radius");
        if (!(radius > 0)) r_.fail("film.filter.radius", "must be > 0, got " + rad->dump());
        scene_.film.filter.radius = radius;
      }
    }
  }

  void parse_render(const json& j) {
    const std::string p = "render";
    r_.check_keys(j, p, {"integrator", "spp", "passes", "seed", "noise_target", "sampler",
                          "light_selection", "aovs"});
    RenderSettings& rs = scene_.render;
    if (const json* i = r_.find(j, "integrator"))
      rf::parse_integrator(r_, *i, "render.integrator", rs.integrator);
    if (const json* v = r_.find(j, "spp")) rs.spp = r_.unsigned_integer(*v, "render.spp", 1);
    if (const json* v = r_.find(j, "passes")) {
      rs.passes = uint32_t(r_.integer(*v, "render.passes", 1, UINT32_MAX));
      if (rs.spp % rs.passes != 0)
        r_.fail("render.spp", "must be a multiple of render.passes (" + std::to_string(rs.passes) +
                                  "), got " + std::to_string(rs.spp));
    } else {
      set_default_passes();
    }
    if (const json* v = r_.find(j, "seed")) rs.seed = r_.unsigned_integer(*v, "render.seed", 0);
    if (const json* v = r_.find(j, "sampler")) {
      rs.sampler = r_.string(*v, "render.sampler");
      if (!contains_name(known_samplers(), rs.sampler))
        r_.fail("render.sampler", "unknown sampler '" + rs.sampler + "' (known: " + join_names(known_samplers()) + ")");
    }
    if (const json* v = r_.find(j, "light_selection")) {
      rs.light_selection = r_.string(*v, "render.light_selection");
      if (rs.light_selection != "auto" && rs.light_selection != "power" && rs.light_selection != "bvh")
        r_.fail("render.light_selection",
                "unknown light selection '" + rs.light_selection + "' (known: auto, power, bvh)");
    }
    if (const json* v = r_.find(j, "aovs")) {
      std::string list;
      for (size_t i = 0; i < r_.array(*v, "render.aovs").size(); ++i)
        list += (i ? "," : "") + r_.string((*v)[i], json_child("render.aovs", i));
      try {
        rs.aovs = parse_aovs(list);
      } catch (const std::invalid_argument& e) {
        r_.fail("render.aovs", e.what());
      }
    }
    if (const json* v = r_.find(j, "noise_target")) {
      rs.noise_target = r_.real(*v, "render.noise_target");
      if (rs.noise_target < 0)
        r_.fail("render.noise_target", "must be at least 0, got " + v->dump());
    }
  }

  void set_default_passes() {
    scene_.render.passes = default_passes(scene_.render.spp);
  }

  void parse_materials(const json& j) {
    r_.expect_object(j, "materials");
    // nlohmann's object is a std::map, so this walks names in sorted order.
    for (auto it = j.begin(); it != j.end(); ++it) {
      if (it.key().empty()) r_.fail("materials", "material names must not be empty");
      material_ids_[it.key()] = uint32_t(scene_.materials.size());
      scene_.materials.push_back(parse_material(it.key(), it.value()));
    }
  }

  // Keys each material type reads (besides "type").
  static std::vector<std::string> material_keys(const std::string& type) {
    if (type == "diffuse") return {"reflectance"};
    if (type == "conductor" || type == "rough_conductor") {
      std::vector<std::string> k = {"eta", "k", "preset", "tint"};
      if (type == "rough_conductor") k.push_back("roughness");
      return k;
    }
    if (type == "dielectric" || type == "thin_dielectric") return {"ior", "specular"};
    if (type == "rough_dielectric") return {"ior", "specular", "roughness"};
    return {"reflectance", "ior", "roughness"};  // plastic
  }

  Material parse_material(const std::string& name, const json& j) {
    const std::string p = json_child("materials", name);
    r_.expect_object(j, p);
    std::string type = r_.string(r_.require(j, p, "type"), p + ".type");
    if (!contains_name(kMaterialTypes, type))
      r_.fail(p + ".type",
              "unknown material type '" + type + "' (known: " + join_names(kMaterialTypes) + ")");
    std::vector<std::string> keys = material_keys(type);
    keys.push_back("type");
    r_.check_keys(j, p, keys);
    Material m;
    m.name = name;
    static const std::map<std::string, MaterialType> kTypes = {
        {"diffuse", MaterialType::Diffuse},
        {"conductor", MaterialType::Conductor},
        {"rough_conductor", MaterialType::RoughConductor},
        {"dielectric", MaterialType::Dielectric},
        {"thin_dielectric", MaterialType::ThinDielectric},
        {"rough_dielectric", MaterialType::RoughDielectric},
        {"plastic", MaterialType::Plastic}};
    m.type = kTypes.at(type);
    if (const json* v = r_.find(j, "reflectance")) m.reflectance = color_param(*v, p + ".reflectance", 1);
    if (const json* v = r_.find(j, "specular")) m.specular = color_param(*v, p + ".specular", 1);
    if (const json* v = r_.find(j, "roughness")) m.roughness = float_param(*v, p + ".roughness", 0, 1);
    if (type == "rough_conductor" || type == "rough_dielectric")
      if (!r_.find(j, "roughness")) r_.fail(p + ".roughness", "required key is missing");
    if (const json* v = r_.find(j, "ior")) {
      m.ior = r_.number(*v, p + ".ior");
      if (!(m.ior > 1.0f && m.ior < 4.0f))
        r_.fail(p + ".ior", "must be between 1 and 4 (exclusive), got " + v->dump());
    }
    if (type == "conductor" || type == "rough_conductor") parse_conductor(j, p, m);
    return m;
  }

  // A conductor is given by a preset name, by eta and k, or by a tint (Schlick, F0 = tint).
  void parse_conductor(const json& j, const std::string& p, Material& m) {
    int given = (r_.find(j, "preset") ? 1 : 0) + (r_.find(j, "tint") ? 1 : 0) +
                (r_.find(j, "eta") || r_.find(j, "k") ? 1 : 0);
    if (given > 1) r_.fail(p, "give one of 'preset', 'tint', or 'eta' and 'k'");
    const ConductorPreset* gold = conductor_preset("gold");
    m.eta = gold->eta, m.k = gold->k;  // gold by default
    if (const json* v = r_.find(j, "preset")) {
      std::string name = r_.string(*v, p + ".preset");
      const ConductorPreset* c = conductor_preset(name);
      if (!c) {
        std::vector<std::string> names;
        for (const ConductorPreset& k : conductor_presets()) names.push_back(k.name);
        r_.fail(p + ".preset", "unknown conductor '" + name + "' (known: " + join_names(names) + ")");
      }
      m.eta = c->eta, m.k = c->k;
    } else if (const json* v = r_.find(j, "tint")) {
      m.conductor_tint = true;
      m.specular = color_param(*v, p + ".tint", 1);
    } else if (r_.find(j, "eta") || r_.find(j, "k")) {
      m.eta = r_.rgb(r_.require(j, p, "eta"), p + ".eta", 100);
      m.k = r_.rgb(r_.require(j, p, "k"), p + ".k", 100);
    }
  }

  // A colour parameter: [r, g, b], a number, or {"texture": "name"}.
  ColorParam color_param(const json& j, const std::string& p, float max) {
    ColorParam c;
    if (j.is_object()) {
      c.texture = texture_ref(j, p);
      return c;
    }
    c.value = r_.rgb(j, p, max);
    return c;
  }

  FloatParam float_param(const json& j, const std::string& p, float lo, float hi) {
    FloatParam f;
    if (j.is_object()) {
      f.texture = texture_ref(j, p);
      return f;
    }
    f.value = r_.number(j, p);
    if (f.value < lo || f.value > hi)
      r_.fail(p, "must be between " + format_number(lo) + " and " + format_number(hi) + ", got " +
                     j.dump());
    return f;
  }

  int32_t texture_ref(const json& j, const std::string& p) {
    r_.check_keys(j, p, {"texture"});
    std::string name = r_.string(r_.require(j, p, "texture"), p + ".texture");
    for (size_t i = 0; i < scene_.textures.size(); ++i)
      if (scene_.textures[i].name == name) return int32_t(i);
    std::vector<std::string> known;
    for (const Texture& t : scene_.textures) known.push_back(t.name);
    r_.fail(p + ".texture", "unknown texture '" + name +
                                "' (known: " + (known.empty() ? std::string("none") : join_names(known)) + ")");
  }

  void parse_textures(const json& j) {
    r_.expect_object(j, "textures");
    for (auto it = j.begin(); it != j.end(); ++it) {
      const std::string p = json_child("textures", it.key());
      const json& t = it.value();
      r_.expect_object(t, p);
      std::string type = r_.string(r_.require(t, p, "type"), p + ".type");
      Texture tex;
      tex.name = it.key();
      std::vector<std::string> keys = {"type", "scale", "offset"};
      if (type == "constant") {
        keys.push_back("value");
        r_.check_keys(t, p, keys);
        tex.type = TextureType::Constant;
        tex.value = r_.rgb(r_.require(t, p, "value"), p + ".value", 1);
      } else if (type == "checkerboard") {
        keys.insert(keys.end(), {"color_a", "color_b"});
        r_.check_keys(t, p, keys);
        tex.type = TextureType::Checkerboard;
        tex.color_a = r_.rgb(r_.require(t, p, "color_a"), p + ".color_a", 1);
        tex.color_b = r_.rgb(r_.require(t, p, "color_b"), p + ".color_b", 1);
      } else if (type == "image") {
        keys.insert(keys.end(), {"file", "data"});
        r_.check_keys(t, p, keys);
        tex.type = TextureType::Image;
        tex.file = files_.add(r_.string(r_.require(t, p, "file"), p + ".file"), p + ".file");
        tex.resolved_path = files_.path_of(tex.file);
        if (const json* d = r_.find(t, "data")) tex.is_data = r_.boolean(*d, p + ".data");
      } else {
        r_.fail(p + ".type", "unknown texture type '" + type + "' (known: " + join_names(kTextureTypes) + ")");
      }
      if (const json* v = r_.find(t, "scale")) {
        if (v->is_number()) {
          tex.uv_scale = {r_.number(*v, p + ".scale"), r_.number(*v, p + ".scale")};
        } else {
          r_.array(*v, p + ".scale", 2);
          tex.uv_scale = {r_.number((*v)[0], p + ".scale[0]"), r_.number((*v)[1], p + ".scale[1]")};
        }
      }
      if (const json* v = r_.find(t, "offset")) {
        r_.array(*v, p + ".offset", 2);
        tex.uv_offset = {r_.number((*v)[0], p + ".offset[0]"), r_.number((*v)[1], p + ".offset[1]")};
      }
      scene_.textures.push_back(std::move(tex));
    }
  }

  void parse_light(const json& j, const std::string& p) {
    r_.expect_object(j, p);
    std::string type = r_.string(r_.require(j, p, "type"), p + ".type");
    Light l;
    l.name = p;
    if (type == "point") {
      r_.check_keys(j, p, {"type", "name", "position", "intensity"});
      l.type = LightType::Point;
    } else if (type == "spot") {
      r_.check_keys(j, p, {"type", "name", "position", "intensity", "target", "direction",
                           "cone_angle_deg", "falloff_start_deg"});
      l.type = LightType::Spot;
    } else if (type == "directional") {
      r_.check_keys(j, p, {"type", "name", "direction", "irradiance"});
      l.type = LightType::Directional;
    } else {
      r_.fail(p + ".type", "unknown light type '" + type + "' (known: " + join_names(kLightTypes) + ")");
    }
    if (const json* n = r_.find(j, "name")) l.name = r_.string(*n, p + ".name");
    if (l.type != LightType::Directional) {
      l.position = r_.vec3(r_.require(j, p, "position"), p + ".position");
      l.intensity = r_.rgb(r_.require(j, p, "intensity"), p + ".intensity", kInf);
    }
    if (l.type == LightType::Spot) {
      const json* target = r_.find(j, "target");
      const json* dir = r_.find(j, "direction");
      if (!target == !dir) r_.fail(p, "a spot light needs exactly one of 'target' or 'direction'");
      Vec3 d = dir ? r_.vec3(*dir, p + ".direction")
                   : r_.vec3(*target, p + ".target") - l.position;
      if (!(length(d) > 0)) r_.fail(p + (dir ? ".direction" : ".target"), "gives a zero direction");
      l.direction = normalize(d);
      if (const json* v = r_.find(j, "cone_angle_deg")) l.cone_angle_deg = r_.number(*v, p + ".cone_angle_deg");
      if (const json* v = r_.find(j, "falloff_start_deg"))
        l.falloff_start_deg = r_.number(*v, p + ".falloff_start_deg");
      else
        l.falloff_start_deg = std::min(l.falloff_start_deg, l.cone_angle_deg);
      if (!(l.cone_angle_deg > 0 && l.cone_angle_deg <= 90))
        r_.fail(p + ".cone_angle_deg", "must be in (0, 90], got " + format_number(l.cone_angle_deg));
      if (!(l.falloff_start_deg >= 0 && l.falloff_start_deg <= l.cone_angle_deg))
        r_.fail(p + ".falloff_start_deg", "must be in [0, cone_angle_deg], got " +
                                              format_number(l.falloff_start_deg));
    }
    if (l.type == LightType::Directional) {
      Vec3 d = r_.vec3(r_.require(j, p, "direction"), p + ".direction");
      if (!(length(d) > 0)) r_.fail(p + ".direction", "must not be zero");
      l.direction = normalize(d);
      l.irradiance = r_.rgb(r_.require(j, p, "irradiance"), p + ".irradiance", kInf);
    }
    scene_.lights.push_back(l);
  }

  void parse_environment(const json& j) {
    const std::string p = "environment";
    r_.check_keys(j, p, {"file", "radiance", "scale", "transform"});
    Environment env;
    const json* file = r_.find(j, "file");
    const json* radiance = r_.find(j, "radiance");
    if (!file == !radiance) r_.fail(p, "needs exactly one of 'file' (a lat-long map) or 'radiance'");
    if (file) {
      env.file = files_.add(r_.string(*file, p + ".file"), p + ".file");
      env.resolved_path = files_.path_of(env.file);
      if (const json* sc = r_.find(j, "scale")) env.scale = r_.rgb(*sc, p + ".scale", kInf);
    } else {
      if (r_.find(j, "scale")) r_.fail(p + ".scale", "only with 'file'");
      env.scale = r_.rgb(*radiance, p + ".radiance", kInf);
    }
    if (const json* t = r_.find(j, "transform")) {
      env.to_world = parse_transform(*t, p + ".transform");
      // Only rotations: a scale would change nothing visible but the pdf's Jacobian.
      for (int a = 0; a < 3; ++a)
        for (int b = 0; b < 3; ++b) {
          const Mat4& m = env.to_world;
          float d = m.m[0][a] * m.m[0][b] + m.m[1][a] * m.m[1][b] + m.m[2][a] * m.m[2][b];
          if (std::fabs(d - (a == b ? 1.0f : 0.0f)) > 1e-3f || m.det3() < 0)
            r_.fail(p + ".transform", "must be a rotation (no scale, shear or mirror)");
        }
    }
    scene_.environment = env;
  }

  // Instancing: objects are named groups of shapes in their own space; instances place them.
  void parse_objects(const json& j) {
    r_.array(j, "objects");
    for (size_t i = 0; i < j.size(); ++i) {
      const std::string p = json_child("objects", i);
      r_.expect_object(j[i], p);
      r_.check_keys(j[i], p, {"name", "shapes"});
      SceneObject obj;
      obj.name = r_.string(r_.require(j[i], p, "name"), p + ".name");
      if (object_ids_.count(obj.name)) r_.fail(p + ".name", "duplicate object name '" + obj.name + "'");
      const json& shapes = r_.array(r_.require(j[i], p, "shapes"), p + ".shapes");
      for (size_t k = 0; k < shapes.size(); ++k)
        obj.meshes.push_back(parse_shape(shapes[k], json_child(p + ".shapes", k)));
      object_ids_[obj.name] = uint32_t(scene_.objects.size());
      scene_.objects.push_back(std::move(obj));
    }
  }

  void parse_instances(const json& j) {
    r_.array(j, "instances");
    for (size_t i = 0; i < j.size(); ++i) {
      const std::string p = json_child("instances", i);
      r_.expect_object(j[i], p);
      r_.check_keys(j[i], p, {"object", "transform", "keyframes"});
      std::string name = r_.string(r_.require(j[i], p, "object"), p + ".object");
      auto it = object_ids_.find(name);
      if (it == object_ids_.end()) {
        std::vector<std::string> known;
        for (const SceneObject& o : scene_.objects) known.push_back(o.name);
        r_.fail(p + ".object", "unknown object '" + name + "' (known: " +
                                   (known.empty() ? std::string("none") : join_names(known)) + ")");
      }
      Instance inst;
      inst.object = it->second;
      const json* keys = r_.find(j[i], "keyframes");
      if (keys && r_.find(j[i], "transform"))
        r_.fail(p + ".keyframes", "give the instance's 'keyframes' or its 'transform', not both");
      if (keys) {
        inst.motion = parse_motion(*keys, p + ".keyframes");
        inst.to_world = inst.motion.keys().front().m;
      } else if (const json* t = r_.find(j[i], "transform")) {
        inst.to_world = parse_transform(*t, p + ".transform");
      }
      if (!(std::fabs(inst.to_world.det3()) > 0))
        r_.fail(p + ".transform", "must be invertible (a zero scale flattens the object)");
      scene_.instances.push_back(inst);
    }
  }

  // A shape of the scene's "shapes": a world mesh, or, with "keyframes", a moving shape: an object
  // holding the shape (its own "transform" applied first) placed by one moving instance.
  void parse_world_shape(const json& j, const std::string& p) {
    const json* keys = j.is_object() ? r_.find(j, "keyframes") : nullptr;
    const json* deform = j.is_object() ? r_.find(j, "deform") : nullptr;
    if (keys && deform)
      r_.fail(p + ".deform",
              "a shape deforms ('deform') or moves by 'keyframes', not both: put its motion "
              "into the deform keys' vertices");
    if (!keys) {
      Mesh mesh = parse_shape(j, p, /*moving=*/false, /*world=*/true);
      if (deform) parse_deform(*deform, j, p, mesh);
      scene_.meshes.push_back(std::move(mesh));
      return;
    }
    SceneObject obj;
    obj.meshes.push_back(parse_shape(j, p, /*moving=*/true));
    obj.name = obj.meshes.front().name;
    Instance inst;
    inst.object = uint32_t(scene_.objects.size());
    inst.motion = parse_motion(*keys, p + ".keyframes");
    inst.to_world = inst.motion.keys().front().m;
    scene_.objects.push_back(std::move(obj));
    scene_.instances.push_back(inst);
  }

  // A deforming shape's "deform" keys (docs/scene-format.md): each at a 'frame' or 'time', with
  // its vertices inline ('positions', 'normals') or from a mesh 'file', or neither for the shape's
  // own; as many vertices as the shape, in its order, moved by the shape's 'transform'. The
  // shape's triangles, uvs and material are every key's.
  void parse_deform(const json& list, const json& shape, const std::string& p, Mesh& mesh) {
    const std::string q = p + ".deform";
    const std::string type = r_.string(r_.require(shape, p, "type"), p + ".type");
    if (type != "mesh" && type != "obj" && type != "ply")
      r_.fail(q, "only triangle meshes deform (type mesh, obj or ply), not a " + type);
    r_.array(list, q);
    if (list.size() < 2) r_.fail(q, "needs at least two keys");
    Mat4 to_world = Mat4::identity();
    if (const json* t = r_.find(shape, "transform"))
      to_world = parse_transform(*t, p + ".transform");
    for (size_t i = 0; i < list.size(); ++i) {
      const std::string kp = json_child(q, i);
      const json& k = list[i];
      r_.expect_object(k, kp);
      r_.check_keys(k, kp, {"frame", "time", "positions", "normals", "file"});
      const json* frame = r_.find(k, "frame");
      const json* time = r_.find(k, "time");
      if (!frame == !time) r_.fail(kp, "give its 'frame' or its 'time' (seconds), one of them");
      VertexKey key;
      key.time =
          frame ? r_.real(*frame, kp + ".frame") / scene_.time.fps : r_.real(*time, kp + ".time");
      if (!std::isfinite(key.time)) r_.fail(kp, "the key's time is not finite");
      if (!mesh.deform.empty() && !(key.time > mesh.deform.back().time))
        r_.fail(kp + (frame ? ".frame" : ".time"),
                "keys must be in increasing time: this one is not after " + json_child(q, i - 1));
      const json* positions = r_.find(k, "positions");
      const json* file = r_.find(k, "file");
      if (positions && file) r_.fail(kp, "give its 'positions' or its 'file', not both");
      if (!positions && !file) {
        if (r_.find(k, "normals")) r_.fail(kp + ".normals", "goes with the key's 'positions'");
        key.positions = mesh.positions, key.normals = mesh.normals;  // the shape's own
        mesh.deform.push_back(std::move(key));
        continue;
      }
      MeshData data;
      std::string where = kp;
      if (file) {
        const std::string name = r_.string(*file, kp + ".file");
        const std::string ext = std::filesystem::path(name).extension().string();
        if (ext != ".obj" && ext != ".ply")
          r_.fail(kp + ".file", "'" + name + "' is not an .obj or .ply mesh");
        where = kp + " (" + name + ")";
        const MeshData& m = files_.mesh(name, ext.substr(1), kp + ".file");
        data.positions = m.positions, data.normals = m.normals;
      } else {
        std::vector<float> v = flat_numbers(*positions, kp + ".positions", 3);
        for (size_t a = 0; a < v.size(); a += 3)
          data.positions.emplace_back(v[a], v[a + 1], v[a + 2]);
        if (const json* n = r_.find(k, "normals")) {
          v = flat_numbers(*n, kp + ".normals", 3);
          for (size_t a = 0; a < v.size(); a += 3)
            data.normals.emplace_back(v[a], v[a + 1], v[a + 2]);
        }
      }
      if (data.positions.size() != mesh.positions.size())
        r_.fail(where, "has " + std::to_string(data.positions.size()) +
                           " vertices; the shape has " + std::to_string(mesh.positions.size()));
      if (!mesh.normals.empty() && data.normals.size() != mesh.positions.size())
        r_.fail(where, "needs a normal per vertex, as the shape has (" +
                           std::to_string(data.normals.size()) + " given)");
      for (Vec3& v : data.positions) {
        v = to_world.point(v);
        if (!is_finite(v)) r_.fail(where, "a vertex is not finite after the shape's transform");
      }
      if (!mesh.normals.empty())
        for (Vec3& n : data.normals) {
          n = to_world.normal(n);
          const float len = length(n);
          if (!(len > 0) || !std::isfinite(len)) r_.fail(where, "a normal is zero or not finite");
          n = n / len;
        }
      key.positions = std::move(data.positions);
      if (!mesh.normals.empty()) key.normals = std::move(data.normals);
      mesh.deform.push_back(std::move(key));
    }
    // The mesh's own vertices are its first key's (Mesh::deform).
    mesh.positions = mesh.deform.front().positions;
    mesh.normals = mesh.deform.front().normals;
  }

  Mesh parse_shape(const json& j, const std::string& p, bool moving = false, bool world = false) {
    r_.expect_object(j, p);
    std::string type = r_.string(r_.require(j, p, "type"), p + ".type");
    std::vector<std::string> keys = {"type", "name", "material", "transform", "emission"};
    if (moving) keys.push_back("keyframes");
    if (world) keys.push_back("deform");
    if (type == "obj" || type == "ply")
      keys.push_back("file");
    else if (type == "mesh")
      keys.insert(keys.end(), {"positions", "indices", "normals", "uvs"});
    else if (type == "sphere")
      keys.insert(keys.end(), {"center", "radius", "tessellation"});
    else if (type == "disk")
      keys.insert(keys.end(), {"segments"});
    else if (type != "rectangle" && type != "cube")
      r_.fail(p + ".type", "unknown shape type '" + type + "' (known: " + join_names(kShapeTypes) + ")");
    r_.check_keys(j, p, keys);

    Mesh mesh;
    mesh.name = p;
    if (const json* n = r_.find(j, "name")) mesh.name = r_.string(*n, p + ".name");
    mesh.material = material_ref(r_.require(j, p, "material"), p + ".material");
    if (const json* e = r_.find(j, "emission")) mesh.emission = parse_emission(*e, p + ".emission");
    Mat4 to_world = Mat4::identity();
    if (const json* t = r_.find(j, "transform")) to_world = parse_transform(*t, p + ".transform");

    std::string where = p;  // for geometry messages: the shape, and its file if any
    MeshData data;
    if (type == "obj" || type == "ply") {
      std::string file = r_.string(r_.require(j, p, "file"), p + ".file");
      where = p + " (" + file + ")";
      data = files_.mesh(file, type, p + ".file");
    } else if (type == "mesh") {
      data = parse_inline_mesh(j, p);
    } else if (type == "sphere") {
      data = parse_sphere(j, p, to_world, mesh);
      if (mesh.sphere) return mesh;
    } else if (type == "disk") {
      int segments = 128;
      if (const json* v = r_.find(j, "segments")) segments = int(r_.integer(*v, p + ".segments", 3, 1 << 16));
      data = make_disk(segments);
    } else {
      data = type == "rectangle" ? make_rectangle() : make_cube();
    }
    place_mesh(std::move(data), to_world, r_.file(), where, mesh);
    return mesh;
  }

  uint32_t material_ref(const json& j, const std::string& p) {
    std::string name = r_.string(j, p);
    auto it = material_ids_.find(name);
    if (it == material_ids_.end()) {
      std::vector<std::string> known;
      for (const Material& m : scene_.materials) known.push_back(m.name);
      r_.fail(p, "unknown material '" + name +
                     "' (known: " + (known.empty() ? std::string("none") : join_names(known)) + ")");
    }
    return it->second;
  }

  std::optional<Emission> parse_emission(const json& j, const std::string& p) {
    r_.check_keys(j, p, {"radiance", "two_sided"});
    Emission e;
    e.radiance = r_.rgb(r_.require(j, p, "radiance"), p + ".radiance", kInf);
    if (const json* t = r_.find(j, "two_sided")) e.two_sided = r_.boolean(*t, p + ".two_sided");
    if (is_black(e.radiance)) return std::nullopt;  // black emission: not a light
    return e;
  }

  // Ops apply in the order written: [A, B, C] maps a point p to C(B(A(p))).
  Mat4 parse_transform(const json& j, const std::string& p) {
    if (j.is_object()) return parse_transform_op(j, p);
    r_.array(j, p);
    Mat4 m = Mat4::identity();
    for (size_t i = 0; i < j.size(); ++i) m = parse_transform_op(j[i], json_child(p, i)) * m;
    r_.check_invertible(m, p);
    return m;
  }

  Mat4 parse_transform_op(const json& j, const std::string& p) {
    r_.expect_object(j, p);
    if (j.size() != 1)
      r_.fail(p, "expected exactly one of translate, scale, rotate, matrix; got " +
                     std::to_string(j.size()) + " keys");
    r_.check_keys(j, p, {"translate", "scale", "rotate", "matrix"});
    const std::string& op = j.begin().key();
    const json& v = j.begin().value();
    const std::string vp = json_child(p, op);
    if (op == "translate") return Mat4::translate(r_.vec3(v, vp));
    if (op == "matrix") return r_.matrix(v, vp);
    if (op == "scale") {
      Vec3 s = v.is_number() ? Vec3(r_.number(v, vp)) : r_.vec3(v, vp);
      if (s.x == 0 || s.y == 0 || s.z == 0) r_.fail(vp, "singular: a scale factor is 0");
      return Mat4::scale(s);
    }
    r_.check_keys(v, vp, {"axis", "angle_deg"});
    Vec3 axis = r_.vec3(r_.require(v, vp, "axis"), vp + ".axis");
    float angle = r_.number(r_.require(v, vp, "angle_deg"), vp + ".angle_deg");
    if (!(length(axis) > 0)) r_.fail(vp + ".axis", "must not be zero");
    return Mat4::rotate(axis, angle);
  }

  // Spheres are exact (mesh.sphere) unless "tessellation" is given or the transform is not a
  // similarity; then they are tessellated (n_theta x n_phi, default 64 x 128) with exact smooth
  // normals; the default's worst-case distance to the true sphere is r (1 - cos(pi/128)) = 3e-4 r.
  MeshData parse_sphere(const json& j, const std::string& p, const Mat4& to_world, Mesh& mesh) {
    Vec3 c(0.0f);
    float r = 1;
    int nt = kSphereThetaSteps, np = kSpherePhiSteps;
    if (const json* v = r_.find(j, "center")) c = r_.vec3(*v, p + ".center");
    if (const json* v = r_.find(j, "radius")) {
      r = r_.number(*v, p + ".radius");
      if (!(r > 0)) r_.fail(p + ".radius", "must be > 0, got " + v->dump());
    }
    if (const json* v = r_.find(j, "tessellation")) {
      r_.array(*v, p + ".tessellation", 2);
      nt = int(r_.integer((*v)[0], p + ".tessellation[0]", 3, 1 << 14));
      np = int(r_.integer((*v)[1], p + ".tessellation[1]", 3, 1 << 14));
      constexpr uint64_t kMaxVertices = uint64_t(1) << 24;  // 16.8 million, 0.8 GB of mesh
      if (uint64_t(nt + 1) * uint64_t(np + 1) > kMaxVertices)
        r_.fail(p + ".tessellation", std::to_string(nt) + " x " + std::to_string(np) + " makes " +
                                         std::to_string(uint64_t(nt + 1) * uint64_t(np + 1)) +
                                         " vertices; a tessellated sphere has at most " +
                                         std::to_string(kMaxVertices));
    } else {
      static const Vec3 kAxes[3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
      SphereShape sphere;
      if (place_sphere(c, r, kAxes, to_world, sphere)) {
        mesh.sphere = sphere;
        return {};
      }
    }
    return make_sphere(c, r, nt, np);
  }

  MeshData parse_inline_mesh(const json& j, const std::string& p) {
    MeshData m;
    std::vector<float> pos = flat_numbers(r_.require(j, p, "positions"), p + ".positions", 3);
    for (size_t i = 0; i < pos.size(); i += 3)
      m.positions.emplace_back(pos[i], pos[i + 1], pos[i + 2]);
    const json& idx = r_.array(r_.require(j, p, "indices"), p + ".indices");
    if (idx.size() % 3 != 0)
      r_.fail(p + ".indices", "expected 3 indices per triangle, got " + std::to_string(idx.size()));
    for (size_t i = 0; i < idx.size(); ++i)
      m.indices.push_back(uint32_t(r_.integer(idx[i], json_child(p + ".indices", i), 0, UINT32_MAX)));
    if (const json* n = r_.find(j, "normals")) {
      std::vector<float> v = flat_numbers(*n, p + ".normals", 3);
      for (size_t i = 0; i < v.size(); i += 3) m.normals.emplace_back(v[i], v[i + 1], v[i + 2]);
    }
    if (const json* uv = r_.find(j, "uvs")) {
      std::vector<float> v = flat_numbers(*uv, p + ".uvs", 2);
      for (size_t i = 0; i < v.size(); i += 2) m.uvs.push_back({v[i], v[i + 1]});
    }
    return m;
  }

  std::vector<float> flat_numbers(const json& j, const std::string& p, size_t group) {
    r_.array(j, p);
    if (j.size() % group != 0 || j.empty())
      r_.fail(p, "expected a flat array of " + std::to_string(group) + "*n numbers, got " +
                     std::to_string(j.size()));
    std::vector<float> out;
    for (size_t i = 0; i < j.size(); ++i) out.push_back(r_.number(j[i], json_child(p, i)));
    return out;
  }

  JsonReader r_;
  Scene& scene_;
  SceneFiles& files_;
  std::map<std::string, uint32_t> material_ids_;
  std::map<std::string, uint32_t> object_ids_;
};

}  // namespace

void import_json(const std::string& bytes, SceneFiles& files, Scene& scene) {
  json root = parse_json_text(bytes, scene.path);
  SceneParser parser(scene.path, scene, files);
  parser.parse(root);
}

}  // namespace rf
