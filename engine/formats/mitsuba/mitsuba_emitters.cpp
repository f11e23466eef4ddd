// The Mitsuba 3 importer's emitters that are not shapes (mitsuba_parser.h).
#include "engine/formats/mitsuba/mitsuba_parser.h"

namespace rf::mitsuba {

void MitsubaParser::parse_emitter(const Node& n) {
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

}  // namespace rf::mitsuba
