// The pbrt-v4 importer (docs/formats/pbrt.md): directives, graphics state, instancing and the
// mapping of cameras, lights and shapes onto the engine's Scene. Materials and textures are in
// pbrt_materials.cpp, the token and parameter syntax in pbrt_parser.*.
#include <cmath>
#include <map>
#include <memory>

#include "engine/formats/importers.h"
#include "engine/formats/mesh_placement.h"
#include "engine/formats/pbrt/pbrt_builder.h"
#include "engine/formats/pbrt/pbrt_envmap.h"
#include "engine/formats/pbrt/pbrt_shapes.h"
#include "engine/formats/pbrt/pbrt_spectra.h"
#include "engine/formats/scene_files.h"

namespace rf {
namespace pbrt {

namespace {

Mat4 transpose_of(const std::vector<double>& v) {
  Mat4 m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m.m[r][c] = float(v[size_t(c) * 4 + size_t(r)]);
  return m;
}

constexpr float kPiF = 3.14159265358979f;

Vec3 vec_at(const std::vector<double>& v, size_t i) {
  return {float(v[i]), float(v[i + 1]), float(v[i + 2])};
}

}  // namespace

Builder::Builder(const std::string& path, Scene& scene, SceneFiles& files)
    : path_(path), scene_(scene), files_(files) {
  // pbrt-v4's defaults: a 90 degree perspective camera at the origin, 1280x720, gaussian filter,
  // 16 spp, the volumetric path tracer with max depth 5.
  scene_.camera.camera_to_world = Mat4::scale({1, 1, -1});
  scene_.camera.fov_deg = 90;
  scene_.camera.focus_distance = 1e6f;
  scene_.film.width = 1280;
  scene_.film.height = 720;
  scene_.film.filter = {FilterType::Gaussian, 1.5f, 0.5f};
  scene_.render.spp = 16;
  scene_.render.passes = default_passes(16);
  scene_.render.sampler = "sobol";
  scene_.render.integrator.max_depth = 5;
  named_coords_["world"] = {Mat4::identity(), Mat4::identity()};
}

void Builder::warn(const Location& at, const std::string& what) {
  scene_.warnings.push_back(warning_text(at, what));
}

void Builder::warn_unused(const ParamList& params, const std::string& directive) {
  for (const Param* p : params.unused())
    warn(p->at, directive + ": parameter " + p->decl() + " is not supported (ignored)");
}

void Builder::run(const std::string& main_bytes) {
  lexers_.push_back(std::make_unique<Lexer>(main_bytes, path_, ""));
  while (!lexers_.empty()) {
    Lexer& lex = *lexers_.back();
    Token t = lex.next();
    if (t.kind == Token::End) {
      lexers_.pop_back();
      continue;
    }
    Location at = lex.at(t.line);
    if (t.kind != Token::Word)
      fail(at, "expected a directive, got " +
                   (t.kind == Token::String ? "\"" + t.text + "\"" : "'" + t.text + "'"));
    directive(t.text, lex, at);
  }
  resolve_pending_materials();
  finish();
  if (current_object_ >= 0)
    fail(object_begin_at_,
         "ObjectBegin \"" + scene_.objects[size_t(current_object_)].name + "\" has no ObjectEnd");
  if (!stack_.empty())
    warn(stack_.back().begun_at,
         "AttributeBegin without a matching AttributeEnd at the end of the scene");
}

// pbrt-v4's sensor ("cie1931") scales the image by its imaging ratio, exposure time x ISO / 100.
// Light transport is linear, so scaling every emitter by it gives the same image.
void Builder::finish() {
  const float k = float(exposure_time_ * iso_ / 100.0);
  if (k == 1.0f) return;
  for (Light& l : scene_.lights) l.intensity = l.intensity * k, l.irradiance = l.irradiance * k;
  for (Mesh& m : scene_.meshes)
    if (m.emission) m.emission->radiance = m.emission->radiance * k;
  for (SceneObject& o : scene_.objects)
    for (Mesh& m : o.meshes)
      if (m.emission) m.emission->radiance = m.emission->radiance * k;
  if (scene_.environment) scene_.environment->scale = scene_.environment->scale * k;
}

// ------------------------------------------------------------------------------------------
// Positional arguments.

std::string Builder::string_arg(Lexer& lex, const std::string& directive) {
  Token t = lex.next();
  if (t.kind != Token::String)
    fail(lex.at(t.line),
         directive + ": expected a quoted string, got " +
             (t.kind == Token::End ? std::string("the end of the file") : "'" + t.text + "'"));
  return t.text;
}

std::vector<double> Builder::number_args(Lexer& lex, const std::string& directive, size_t n) {
  std::vector<double> v;
  bool bracket = lex.peek().kind == Token::Open;
  Location at = lex.at(lex.peek().line);
  if (bracket) lex.next();
  for (;;) {
    if (bracket && lex.peek().kind == Token::Close) {
      lex.next();
      break;
    }
    if (!bracket && v.size() == n) break;
    if (bracket && lex.peek().kind != Token::Word) {
      Token t = lex.next();
      fail(lex.at(t.line),
           directive + ": ']' expected, got " +
               (t.kind == Token::End ? std::string("the end of the file") : "'" + t.text + "'"));
    }
    Token t = lex.next();
    v.push_back(to_number(t, lex.at(t.line), directive));
  }
  if (v.size() != n)
    fail(at, directive + ": expected " + std::to_string(n) + " numbers, got " +
                 std::to_string(v.size()));
  return v;
}

// ------------------------------------------------------------------------------------------
// The directives.

void Builder::directive(const std::string& name, Lexer& lex, const Location& at) {
  GraphicsState& gs = gs_;
  // The transform directives change the transforms ActiveTransform names (pbrt-v4).
  const bool start = active_ != Active::End, end = active_ != Active::Start;
  auto concat = [&](const Mat4& m) {
    if (start) gs.ctm = gs.ctm * m;
    if (end) gs.ctm_end = gs.ctm_end * m;
  };
  auto set = [&](const Mat4& m) {
    if (start) gs.ctm = m;
    if (end) gs.ctm_end = m;
  };
  if (name == "Translate") {
    auto v = number_args(lex, name, 3);
    concat(Mat4::translate({float(v[0]), float(v[1]), float(v[2])}));
  } else if (name == "Scale") {
    auto v = number_args(lex, name, 3);
    concat(Mat4::scale({float(v[0]), float(v[1]), float(v[2])}));
  } else if (name == "Rotate") {
    auto v = number_args(lex, name, 4);
    Vec3 axis = vec_at(v, 1);
    if (!(length(axis) > 0)) fail(at, "Rotate: the axis must not be zero");
    concat(Mat4::rotate(axis, float(v[0])));
  } else if (name == "LookAt") {
    auto v = number_args(lex, name, 9);
    concat(look_at(at, v));
  } else if (name == "Transform" || name == "ConcatTransform") {
    auto v = number_args(lex, name, 16);
    Mat4 m = transpose_of(v);
    if (name == "Transform")
      set(m);
    else
      concat(m);
  } else if (name == "Identity") {
    set(Mat4::identity());
  } else if (name == "CoordinateSystem") {
    named_coords_[string_arg(lex, name)] = {gs.ctm, gs.ctm_end};
  } else if (name == "CoordSysTransform") {
    std::string n = string_arg(lex, name);
    auto it = named_coords_.find(n);
    if (it == named_coords_.end())
      warn(at, "CoordSysTransform: unknown coordinate system \"" + n + "\" (ignored)");
    else
      gs.ctm = it->second.first, gs.ctm_end = it->second.second;
  } else if (name == "ActiveTransform") {
    Token t = lex.next();
    if (t.kind != Token::Word || (t.text != "StartTime" && t.text != "EndTime" && t.text != "All"))
      fail(lex.at(t.line),
           "ActiveTransform: expected StartTime, EndTime or All, got '" + t.text + "'");
    active_ = t.text == "EndTime"     ? Active::End
              : t.text == "StartTime" ? Active::Start
                                      : Active::All;
  } else if (name == "TransformTimes") {
    auto v = number_args(lex, name, 2);
    if (!(std::isfinite(v[0]) && std::isfinite(v[1]) && v[1] > v[0]))
      fail(at, "TransformTimes: the end time must be after the start time, got " +
                   format_number(v[0]) + " and " + format_number(v[1]));
    transform_times_[0] = v[0], transform_times_[1] = v[1];
  } else if (name == "ReverseOrientation") {
    gs.reverse_orientation = !gs.reverse_orientation;
  } else if (name == "AttributeBegin" || name == "TransformBegin") {
    if (stack_.size() + transform_stack_.size() >= size_t(kMaxNesting))
      fail(at, name + ": blocks nested more than " + std::to_string(kMaxNesting) +
                   " deep (the import limit on nesting)");
    if (name == "TransformBegin")
      transform_stack_.push_back({gs.ctm, gs.ctm_end});
    else {
      stack_.push_back(gs);
      stack_.back().begun_at = at;
    }
  } else if (name == "AttributeEnd" || name == "TransformEnd") {
    if (name == "TransformEnd") {
      if (transform_stack_.empty()) fail(at, "TransformEnd without a matching TransformBegin");
      gs.ctm = transform_stack_.back().first, gs.ctm_end = transform_stack_.back().second;
      transform_stack_.pop_back();
    } else {
      if (stack_.empty()) fail(at, "AttributeEnd without a matching AttributeBegin");
      gs = stack_.back();
      stack_.pop_back();
    }
  } else if (name == "Attribute") {
    std::string target = string_arg(lex, name);
    ParamList params = read_params(lex);
    for (const Param& p : params.items)
      warn(p.at, "Attribute \"" + target + "\": default parameter " + p.decl() +
                     " is not supported (ignored)");
  } else if (name == "Option") {
    ParamList params = read_params(lex);
    for (const Param& p : params.items)
      warn(p.at, "Option " + p.decl() + " is not supported (ignored)");
  } else if (name == "ColorSpace") {
    std::string cs = string_arg(lex, name);
    if (cs != "srgb")
      warn(at, "ColorSpace \"" + cs + "\": only srgb is supported; RGB values are read as sRGB");
  } else if (name == "WorldBegin") {
    gs.ctm = gs.ctm_end = Mat4::identity();
    named_coords_["world"] = {Mat4::identity(), Mat4::identity()};
  } else if (name == "WorldEnd") {
    // pbrt-v3's end of the world block: nothing to do.
  } else if (name == "Include" || name == "Import") {
    include(lex, at, name);
  } else if (name == "Camera") {
    std::string type = string_arg(lex, name);
    camera(type, read_params(lex), at);
  } else if (name == "Film") {
    std::string type = string_arg(lex, name);
    film(type, read_params(lex), at);
  } else if (name == "PixelFilter") {
    std::string type = string_arg(lex, name);
    filter(type, read_params(lex), at);
  } else if (name == "Sampler") {
    std::string type = string_arg(lex, name);
    sampler(type, read_params(lex), at);
  } else if (name == "Integrator") {
    std::string type = string_arg(lex, name);
    integrator(type, read_params(lex), at);
  } else if (name == "Accelerator") {
    string_arg(lex, name);
    read_params(lex);  // the acceleration structure does not change the image
  } else if (name == "MakeNamedMedium") {
    std::string n = string_arg(lex, name);
    read_params(lex);
    warn(at, "MakeNamedMedium \"" + n + "\": participating media are not supported (ignored)");
  } else if (name == "MediumInterface") {
    std::string inside = string_arg(lex, name);
    if (lex.peek().kind == Token::String) string_arg(lex, name);
    if (!inside.empty())
      warn(at, "MediumInterface: participating media are not supported (ignored)");
  } else if (name == "Texture") {
    std::string tex_name = string_arg(lex, name);
    std::string kind = string_arg(lex, name);
    std::string cls = string_arg(lex, name);
    texture(tex_name, kind, cls, read_params(lex), at);
  } else if (name == "Material") {
    std::string type = string_arg(lex, name);
    ParamList params = read_params(lex);
    gs.material = define_material("", type, params, at);
    gs.material_name.clear();
  } else if (name == "MakeNamedMaterial") {
    std::string n = string_arg(lex, name);
    ParamList params = read_params(lex);
    const Param* t = params.find("type");
    if (!t || t->type != "string" || t->strings.size() != 1)
      fail(at, "MakeNamedMaterial \"" + n + "\": needs a \"string type\" parameter");
    named_materials_[n] = define_material(n, t->strings[0], params, at);
  } else if (name == "NamedMaterial") {
    // Resolved when a shape uses it: pbrt-v4 allows the definition to come later in the file.
    gs.material_name = string_arg(lex, name);
    gs.material_at = at;
  } else if (name == "LightSource") {
    std::string type = string_arg(lex, name);
    light(type, read_params(lex), at);
  } else if (name == "AreaLightSource") {
    std::string type = string_arg(lex, name);
    area_light(type, read_params(lex), at);
  } else if (name == "Shape") {
    std::string type = string_arg(lex, name);
    shape(type, read_params(lex), at);
  } else if (name == "ObjectBegin") {
    std::string n = string_arg(lex, name);
    if (current_object_ >= 0)
      fail(at, "ObjectBegin \"" + n + "\": inside another ObjectBegin (nesting is not allowed)");
    if (object_ids_.count(n))
      fail(at, "ObjectBegin \"" + n + "\": an object of that name is already defined");
    stack_.push_back(gs);
    stack_.back().begun_at = at;
    object_ids_[n] = uint32_t(scene_.objects.size());
    scene_.objects.push_back({n, {}});
    object_lights_.emplace_back();
    current_object_ = int(scene_.objects.size()) - 1;
    object_begin_at_ = at;
  } else if (name == "ObjectEnd") {
    if (current_object_ < 0) fail(at, "ObjectEnd without a matching ObjectBegin");
    current_object_ = -1;
    if (stack_.empty()) fail(at, "ObjectEnd: the attribute stack is empty");
    gs = stack_.back();
    stack_.pop_back();
  } else if (name == "ObjectInstance") {
    std::string n = string_arg(lex, name);
    if (current_object_ >= 0)
      fail(at, "ObjectInstance \"" + n + "\": not allowed inside ObjectBegin");
    auto it = object_ids_.find(n);
    if (it == object_ids_.end()) fail(at, "ObjectInstance: unknown object \"" + n + "\"");
    Instance inst(it->second, gs.ctm);
    if (gs.moving()) {  // pbrt-v4's animated instance
      inst.motion = ctm_motion(at, "ObjectInstance \"" + n + "\"");
      inst.to_world = inst.motion.keys().front().m;
      if (!object_lights_[it->second].empty())
        warn(at, "ObjectInstance \"" + n + "\": its lights do not move (the start transform)");
    }
    scene_.instances.push_back(inst);
    for (Light l : object_lights_[it->second]) {
      l.position = gs.ctm.point(l.position);
      if (length(gs.ctm.vector(l.direction)) > 0)
        l.direction = normalize(gs.ctm.vector(l.direction));
      scene_.lights.push_back(l);
    }
  } else {
    fail(at, "unknown directive '" + name + "'");
  }
}

Mat4 Builder::look_at(const Location& at, const std::vector<double>& v) {
  Vec3 eye = vec_at(v, 0), look = vec_at(v, 3), up = vec_at(v, 6);
  if (!(length(look - eye) > 0)) fail(at, "LookAt: the eye and the look-at point coincide");
  if (!(length(up) > 0)) fail(at, "LookAt: the up vector is zero");
  Vec3 dir = normalize(look - eye);
  if (!(length(cross(normalize(up), dir)) > 1e-6f))
    fail(at, "LookAt: the up vector is parallel to the viewing direction");
  // pbrt's left-handed camera frame (+x = up x dir, +y up, +z towards the target): the engine's
  // right-handed camera frame with x and z reversed.
  Mat4 world_from_camera = Mat4::look_at(eye, look, normalize(up)) * Mat4::scale({-1, 1, -1});
  return world_from_camera.inverse();
}

void Builder::include(Lexer& lex, const Location& at, const std::string& directive) {
  std::string file = string_arg(lex, directive);
  if (file.size() > 3 && file.compare(file.size() - 3, 3, ".gz") == 0)
    fail(at, directive + " \"" + file + "\": gzip-compressed scene files are not supported");
  std::string bytes = files_call(at, directive + " \"" + file + "\"",
                                 [&] { return files_.read(file, "included file"); });
  if (lexers_.size() > 64)
    fail(at, directive + " \"" + file + "\": includes nested more than 64 deep (a cycle?)");
  std::string shown = files_.path_of(files_.name(file, directive));
  lexers_.push_back(std::make_unique<Lexer>(std::move(bytes), shown,
                                            " (included from " + at.str() + ")" + at.chain));
}

// ------------------------------------------------------------------------------------------
// Camera, film, filter, sampler, integrator.

AnimatedTransform Builder::ctm_motion(const Location& at, const std::string& what,
                                      const Mat4& after) const {
  try {
    return AnimatedTransform(
        {{transform_times_[0], gs_.ctm * after}, {transform_times_[1], gs_.ctm_end * after}});
  } catch (const std::invalid_argument& e) {
    fail(at, what + ": its motion (ActiveTransform): " + e.what());
  }
}

void Builder::camera(const std::string& type, const ParamList& params, const Location& at) {
  if (type != "perspective")
    fail(at, "Camera \"" + type + "\": only the perspective camera is supported");
  Mat4 world_from_camera, world_from_camera_end;
  try {
    world_from_camera = gs_.ctm.inverse();
    world_from_camera_end = gs_.ctm_end.inverse();
  } catch (const std::domain_error&) {
    fail(at, "Camera: the current transform is singular");
  }
  named_coords_["camera"] = {world_from_camera, world_from_camera_end};
  // pbrt's camera space looks down +z (left-handed: x right, y up); ours looks down -z.
  const Mat4 flip = Mat4::scale({1, 1, -1});
  scene_.camera.camera_to_world = world_from_camera * flip;
  if (gs_.moving()) {  // a moving camera: its two transforms at TransformTimes
    try {
      scene_.camera.motion =
          AnimatedTransform({{transform_times_[0], world_from_camera * flip},
                             {transform_times_[1], world_from_camera_end * flip}});
    } catch (const std::invalid_argument& e) {
      fail(at, std::string("Camera: ") + e.what());
    }
  }
  double fov = params.number("fov", 90);
  if (!(fov > 0 && fov < 180))
    fail(at, "Camera: \"float fov\" must be between 0 and 180 degrees, got " + format_number(fov));
  scene_.camera.fov_deg = float(fov);
  scene_.camera.lens_radius = float(params.number("lensradius", 0));
  scene_.camera.focus_distance = float(params.number("focaldistance", 1e6));
  if (scene_.camera.lens_radius < 0) fail(at, "Camera: \"float lensradius\" must be at least 0");
  if (!(scene_.camera.focus_distance > 0)) fail(at, "Camera: \"float focaldistance\" must be > 0");
  // The shutter, in seconds of one frame at 1 fps (pbrt renders one instant's image: frame 0);
  // its length is also the sensor's exposure time (see finish()).
  const double open = params.number("shutteropen", 0), close = params.number("shutterclose", 1);
  exposure_time_ = close - open;
  if (!(exposure_time_ > 0)) fail(at, "Camera: \"shutterclose\" must be after \"shutteropen\"");
  if (!(std::fabs(open) <= kMaxShutterFrames && std::fabs(close) <= kMaxShutterFrames))
    fail(at, "Camera: the shutter must lie within " + format_number(kMaxShutterFrames) +
                 " seconds of 0");
  scene_.time = ShotTime{1, open, close};
  warn_unused(params, "Camera \"perspective\"");
}

void Builder::film(const std::string& type, const ParamList& params, const Location& at) {
  if (type != "rgb" && type != "gbuffer" && type != "spectral" && type != "image")
    warn(at, "Film \"" + type + "\": unknown film type; its resolution is used");
  int w = params.integer("xresolution", 1280), h = params.integer("yresolution", 720);
  if (w < 1 || w > kMaxResolution || h < 1 || h > kMaxResolution)
    fail(at, "Film: resolution must be between 1 and " + std::to_string(kMaxResolution) + ", got " +
                 std::to_string(w) + "x" + std::to_string(h));
  scene_.film.width = w;
  scene_.film.height = h;
  params.find("filename");  // the output file is named on the command line
  iso_ = params.number("iso", 100);
  if (!(iso_ > 0)) fail(at, "Film: \"float iso\" must be > 0");
  std::string sensor = params.string("sensor", "cie1931");
  if (sensor != "cie1931")
    warn(at, "Film: \"sensor\" \"" + sensor + "\" is not supported; the CIE 1931 observer is used");
  if (params.number("whitebalance", 0) != 0)
    warn(at, "Film: \"whitebalance\" is not supported (ignored)");
  params.find("savefp16"), params.find("diagonal");  // output precision; the realistic camera's
  warn_unused(params, "Film \"" + type + "\"");
}

void Builder::filter(const std::string& type, const ParamList& params, const Location& at) {
  FilterSettings f;
  float def_radius = 0.5f;
  if (type == "box") {
    f.type = FilterType::Box;
  } else if (type == "triangle") {
    f.type = FilterType::Triangle;
    def_radius = 2;
  } else if (type == "gaussian") {
    f.type = FilterType::Gaussian;
    def_radius = 1.5f;
    f.sigma = float(params.number("sigma", 0.5));
    if (!(f.sigma > 0)) fail(at, "PixelFilter \"gaussian\": \"float sigma\" must be > 0");
    warn(at,
         "PixelFilter \"gaussian\": truncated at the radius rather than shifted to 0 there as in "
         "pbrt-v4 (a difference of exp(-r^2 / 2 sigma^2) of the peak)");
  } else {
    warn(at, "PixelFilter \"" + type + "\": not supported; a gaussian of radius 1.5 is used");
    for (const Param& p : params.items) p.used = true;
    scene_.film.filter = {FilterType::Gaussian, 1.5f, 0.5f};
    return;
  }
  float xr = float(params.number("xradius", def_radius)),
        yr = float(params.number("yradius", def_radius));
  if (!(xr > 0 && yr > 0)) fail(at, "PixelFilter \"" + type + "\": radii must be > 0");
  if (xr != yr)
    warn(at, "PixelFilter \"" + type + "\": different x and y radii; their mean is used");
  f.radius = 0.5f * (xr + yr);
  scene_.film.filter = f;
  warn_unused(params, "PixelFilter \"" + type + "\"");
}

void Builder::sampler(const std::string& type, const ParamList& params, const Location& at) {
  static const char* known[] = {"independent", "sobol",   "zsobol",    "paddedsobol",
                                "halton",      "pmj02bn", "stratified"};
  bool ok = false;
  for (const char* k : known) ok = ok || type == k;
  if (!ok) warn(at, "Sampler \"" + type + "\": unknown sampler; rayfarm's sobol sampler is used");
  scene_.render.sampler = type == "independent" ? "independent" : "sobol";
  int spp = type == "stratified" ? params.integer("xsamples", 4) * params.integer("ysamples", 4)
                                 : params.integer("pixelsamples", 16);
  if (type == "stratified") params.find("jitter");
  if (spp < 1) fail(at, "Sampler: \"integer pixelsamples\" must be at least 1");
  scene_.render.spp = uint64_t(spp);
  scene_.render.passes = default_passes(scene_.render.spp);
  scene_.render.seed = uint64_t(std::max(0, params.integer("seed", 0)));
  params.find("randomization");  // the scrambling does not change the expected image
  warn_unused(params, "Sampler \"" + type + "\"");
}

void Builder::integrator(const std::string& type, const ParamList& params, const Location& at) {
  IntegratorSettings& is = scene_.render.integrator;
  std::string ours = integrator_for_pbrt(type);
  if (ours.empty()) {
    warn(at, "Integrator \"" + type + "\": not supported; the path tracer is used");
    ours = PathIntegrator::kName;
  }
  set_integrator(is, ours);
  int depth = params.integer("maxdepth", 5);
  if (depth < 0) fail(at, "Integrator: \"integer maxdepth\" must be at least 0");
  is.max_depth = depth;
  // The module maps its own parameters (module.h, from_pbrt).
  struct Params : ForeignParams {
    const ParamList& list;
    const Location& at;
    Params(const ParamList& l, const Location& a) : list(l), at(a) {}
    int integer(const std::string& n, int fallback) const override {
      return list.integer(n, fallback);
    }
    double number(const std::string& n, double fallback) const override {
      return list.number(n, fallback);
    }
    bool boolean(const std::string& n, bool fallback) const override {
      return list.boolean(n, fallback);
    }
    [[noreturn]] void fail(const std::string& message) const override {
      rf::pbrt::fail(at, "Integrator: " + message);
    }
  };
  map_pbrt_integrator(is, Params(params, at));
  params.find("lightsampler");  // light selection changes the noise, not the image
  if (params.boolean("regularize", false))
    warn(at, "Integrator \"" + type + "\": \"bool regularize\" is not supported (ignored)");
  warn_unused(params, "Integrator \"" + type + "\"");
}

// ------------------------------------------------------------------------------------------
// Lights.

RGB Builder::light_spectrum(const ParamList& params, const std::string& name,
                            const Location& /*at*/, const std::string& directive) {
  const Param* p = params.find(name);
  if (!p) return RGB(1.0f);  // the colour space's illuminant: white
  return spectrum_value(*p, true, directive);
}

void Builder::light(const std::string& type, const ParamList& params, const Location& at) {
  const std::string d = "LightSource \"" + type + "\"";
  const Mat4& ctm = gs_.ctm;
  if (gs_.moving())
    warn(at, d + ": moving lights are not supported: the start transform places it");
  float scale = float(params.number("scale", 1));
  Light l;
  l.name = d + " at " + at.str();
  if (type == "point" || type == "spot") {
    RGB I = light_spectrum(params, "I", at, d);
    std::vector<double> from = params.numbers("from", "point3", 3);
    Vec3 p = from.empty() ? Vec3(0.0f) : Vec3(float(from[0]), float(from[1]), float(from[2]));
    l.position = ctm.point(p);
    double power = params.number("power", -1);
    if (type == "point") {
      l.type = LightType::Point;
      if (power > 0) scale *= float(power / (4 * kPiF));
    } else {
      l.type = LightType::Spot;
      std::vector<double> to = params.numbers("to", "point3", 3);
      Vec3 q = to.empty() ? Vec3(0, 0, 1) : Vec3(float(to[0]), float(to[1]), float(to[2]));
      if (!(length(q - p) > 0)) fail(at, d + ": \"from\" and \"to\" coincide");
      l.direction = normalize(ctm.vector(q - p));
      float cone = float(params.number("coneangle", 30)),
            delta = float(params.number("conedeltaangle", 5));
      if (!(cone > 0 && cone <= 90))
        fail(at, d + ": \"float coneangle\" must be in (0, 90], got " + format_number(cone));
      l.cone_angle_deg = cone;
      l.falloff_start_deg = std::clamp(cone - delta, 0.0f, cone);
      if (power > 0) {
        double ce = std::cos(cone * kPiF / 180), cs = std::cos(l.falloff_start_deg * kPiF / 180);
        scale *= float(power / (2 * kPiF * ((1 - cs) + (cs - ce) / 2)));
      }
    }
    l.intensity = I * scale;
  } else if (type == "distant") {
    RGB L = light_spectrum(params, "L", at, d);
    std::vector<double> from = params.numbers("from", "point3", 3),
                        to = params.numbers("to", "point3", 3);
    Vec3 p = from.empty() ? Vec3(0.0f) : Vec3(float(from[0]), float(from[1]), float(from[2]));
    Vec3 q = to.empty() ? Vec3(0, 0, 1) : Vec3(float(to[0]), float(to[1]), float(to[2]));
    if (!(length(ctm.vector(q - p)) > 0)) fail(at, d + ": \"from\" and \"to\" give no direction");
    l.type = LightType::Directional;
    l.direction = normalize(ctm.vector(q - p));  // the direction the light travels
    double e = params.number("illuminance", -1);
    l.irradiance = L * scale * (e > 0 ? float(e) : 1.0f);
  } else if (type == "infinite") {
    infinite_light(params, at, scale);
    warn_unused(params, d);
    return;
  } else {
    fail(at, d + ": light type not supported (known: point, spot, distant, infinite)");
  }
  warn_unused(params, d);
  if (current_object_ >= 0)
    object_lights_[size_t(current_object_)].push_back(l);
  else
    scene_.lights.push_back(l);
}

void Builder::infinite_light(const ParamList& params, const Location& at, float scale) {
  const std::string d = "LightSource \"infinite\"";
  if (current_object_ >= 0) fail(at, d + ": not allowed inside ObjectBegin");
  if (scene_.environment) warn(at, d + ": a second environment light replaces the first");
  if (params.find("portal"))
    warn(at, d + ": \"portal\" is not supported (ignored: light arrives from all directions)");
  Environment env;
  double e = params.number("illuminance", -1);
  std::string file = params.string("filename", "");
  if (!file.empty()) {
    if (params.has("L")) fail(at, d + ": give either \"L\" or \"filename\", not both");
    env.file =
        files_call(at, d + " \"filename\"", [&] { return files_.add(file, "filename", "image"); });
    env.resolved_path = files_call(at, d + " \"" + file + "\"", [&] {
      return octahedral_to_latlong(files_.path_of(env.file), "'" + env.file + "'");
    });
    if (e > 0) warn(at, d + ": \"illuminance\" with an image is not supported (ignored)");
    env.scale = RGB(scale);
    // pbrt's light space: the map's directions are in the frame of the current transform.
    env.to_world = gs_.ctm;
  } else {
    RGB L = light_spectrum(params, "L", at, d);
    env.scale = L * scale * (e > 0 ? float(e / kPiF) : 1.0f);
  }
  scene_.environment = env;
}

void Builder::area_light(const std::string& type, const ParamList& params, const Location& at) {
  const std::string d = "AreaLightSource \"" + type + "\"";
  if (type != "diffuse") fail(at, d + ": only \"diffuse\" area lights are supported");
  AreaLight a;
  a.at = at;
  if (params.has("filename")) fail(at, d + ": image area lights (\"filename\") are not supported");
  a.L = light_spectrum(params, "L", at, d);
  a.scale = float(params.number("scale", 1));
  a.two_sided = params.boolean("twosided", false);
  a.power = params.number("power", -1);
  warn_unused(params, d);
  gs_.area_light = a;
}

}  // namespace pbrt

void import_pbrt(const std::string& bytes, SceneFiles& files, Scene& scene) {
  pbrt::Builder builder(scene.path, scene, files);
  builder.run(bytes);
}

}  // namespace rf
