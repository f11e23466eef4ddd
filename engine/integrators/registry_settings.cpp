// The registry's scene-layer half (registry.h): integrator names, parsing `render.integrator`, the
// settings text that keys a buffer, and the check of a scene before a render. Nothing here
// renders: the scene library (rayfarm_scene, no Embree, no TBB) holds it with every module's
// NAME_settings.cpp; registry.cpp (render dispatch) and each NAME.cpp are the renderer's.
#include <cstdio>
#include <stdexcept>
#include <type_traits>
#include <utility>

#include "engine/integrators/registry.h"
#include "engine/json_reader.h"
#include "engine/scene.h"

namespace rf {

namespace {

template <size_t... I>
std::vector<std::string> variant_names(std::index_sequence<I...>) {
  return {std::variant_alternative_t<I, Integrator>::kName...};
}

template <size_t I = 0>
Integrator make_by_name(const std::string& name) {
  if constexpr (I == std::variant_size_v<Integrator>) {
    throw std::invalid_argument("unknown integrator '" + name +
                                "' (known: " + join_names(known_integrators()) + ")");
  } else {
    using T = std::variant_alternative_t<I, Integrator>;
    if (name == T::kName) return T{};
    return make_by_name<I + 1>(name);
  }
}

template <class T>
std::vector<std::string> keys_of() {
  return std::vector<std::string>(std::begin(T::kKeys), std::end(T::kKeys));
}

// The words of a space-separated list.
std::vector<std::string> words(const char* list) {
  std::vector<std::string> out;
  std::string w;
  for (const char* c = list;; ++c) {
    if (*c == ' ' || *c == 0) {
      if (!w.empty()) out.push_back(w);
      w.clear();
      if (*c == 0) return out;
    } else {
      w += *c;
    }
  }
}

// The integrator whose pbrt-v4 (or Mitsuba 3) type list holds `type`; "" if none.
template <bool kMitsuba>
std::string integrator_for(const std::string& type) {
  std::string found;
  for (const std::string& name : known_integrators()) {
    std::visit(
        [&](const auto& i) {
          using T = std::decay_t<decltype(i)>;
          for (const std::string& w : words(kMitsuba ? T::kMitsubaTypes : T::kPbrtTypes))
            if (w == type && found.empty()) found = T::kName;
        },
        make_integrator(name));
  }
  return found;
}

const char* filter_name(FilterType t) {
  switch (t) {
    case FilterType::Box:
      return "box";
    case FilterType::Triangle:
      return "triangle";
    case FilterType::Gaussian:
      return "gaussian";
  }
  return "?";
}

}  // namespace

const std::vector<std::string>& known_integrators() {
  static const std::vector<std::string> names =
      variant_names(std::make_index_sequence<std::variant_size_v<Integrator>>{});
  return names;
}

Integrator make_integrator(const std::string& name) { return make_by_name(name); }

std::string integrator_name(const Integrator& integrator) {
  return std::visit([](const auto& i) -> std::string { return i.kName; }, integrator);
}

bool integrator_splats(const Integrator& integrator) {
  return std::visit([](const auto& i) { return i.kSplats; }, integrator);
}

bool integrator_needs_lights(const Integrator& integrator) {
  return std::visit([](const auto& i) { return i.kNeedsLights; }, integrator);
}

std::string integrator_for_pbrt(const std::string& type) { return integrator_for<false>(type); }

std::string integrator_for_mitsuba(const std::string& type) { return integrator_for<true>(type); }

std::string mitsuba_integrator_types() {
  std::string out;
  for (const std::string& name : known_integrators()) {
    std::vector<std::string> types =
        std::visit([](const auto& i) { return words(std::decay_t<decltype(i)>::kMitsubaTypes); },
                   make_integrator(name));
    for (const std::string& t : types) out += (out.empty() ? "" : ", ") + t;
    if (!types.empty() && types != std::vector<std::string>{name}) out += " (as " + name + ")";
  }
  return out;
}

void map_pbrt_integrator(IntegratorSettings& settings, const ForeignParams& params) {
  std::visit([&](auto& i) { i.from_pbrt(params); }, settings.method);
}

void map_mitsuba_integrator(IntegratorSettings& settings, const ForeignParams& params) {
  std::visit([&](auto& i) { i.from_mitsuba(params); }, settings.method);
}

void parse_integrator(const JsonReader& r, const Json& j, const std::string& p,
                      IntegratorSettings& out) {
  r.expect_object(j, p);
  std::string type = r.string(r.require(j, p, "type"), p + ".type");
  if (!contains_name(known_integrators(), type))
    r.fail(p + ".type",
           "unknown integrator '" + type + "' (known: " + join_names(known_integrators()) + ")");
  out.method = make_integrator(type);
  std::visit(
      [&](auto& integrator) {
        using T = std::decay_t<decltype(integrator)>;
        r.check_keys(j, p, keys_of<T>());
        if (const Json* v = r.find(j, "max_depth"))
          out.max_depth = int(r.integer(*v, p + ".max_depth", 0, INT32_MAX));
        if (const Json* v = r.find(j, "rr_min_depth"))
          out.rr_min_depth = int(r.integer(*v, p + ".rr_min_depth", 1, INT32_MAX));
        integrator.parse(r, j, p);
      },
      out.method);
  apply_fixed_max_depth(out);
}

void set_integrator(IntegratorSettings& settings, const std::string& name) {
  if (settings.type() != name) settings.method = make_integrator(name);
  apply_fixed_max_depth(settings);
}

void apply_fixed_max_depth(IntegratorSettings& settings) {
  std::visit(
      [&](const auto& integrator) {
        using T = std::decay_t<decltype(integrator)>;
        if constexpr (requires { T::kFixedMaxDepth; }) settings.max_depth = T::kFixedMaxDepth;
      },
      settings.method);
}

// The estimator version: raised by every change to what a pass computes that the settings below do
// not show (geometry, a sampling routine, the mapping of random numbers), i.e. with every golden
// BASE bump that changes images, so that a buffer of an older build never merges with a newer one
// (a farm mid-upgrade, a partial .rfb kept from last week). 2: exact spheres, cone-sampled sphere
// lights, two-step light selection (issue 12). 3: the light BVH; "auto" uses it with many lights.
// 4: the conductor Fresnel term in real arithmetic (the same function, rounded differently).
// 5: a hit on an exact sphere at rayfarm's own distance (Accel::hit_from_embree), not Embree's.
// 6: Embree's medium-quality BVH (a ray through a shared edge may take the other triangle).
// 7: the concentric disk's cosine and sine by polynomials (sin_cos_quarter_pi), not libm.
// 8: the sphere cone's and the visible-normal sample's phi by polynomials (cos_sin_turn).
// 9: the path tracer's diffuse vertices at the last depth take their light sample at full weight
// and trace no BSDF ray (path/path.cpp).
// 10: power selection picks the light's group by u_point.x too, rescaled (LightSelection::select).
// 11: the Sobol kinds draw the first vertex's light point and direction (path) and the first
// round of each strategy (direct) jointly with the filter offset (Sampler::get_2d_joint).
// 12: the path tracer's second vertex draws them jointly with the first vertex's direction.
constexpr int kEstimatorVersion = 12;

std::string settings_text(const Scene& s) {
  const IntegratorSettings& i = s.render.integrator;
  char buf[320];
  std::snprintf(
      buf, sizeof buf,
      "estimator=%d;max_depth=%d;rr_min_depth=%d;spp_per_pass=%llu;filter=%s:%g:%g;sampler=%s;"
      "lights=%s",
      kEstimatorVersion, i.max_depth, i.rr_min_depth, (unsigned long long)s.render.spp_per_pass(),
      filter_name(s.film.filter.type), double(s.film.filter.radius), double(s.film.filter.sigma),
      s.render.sampler.c_str(), s.render.light_selection.c_str());
  std::string text =
      buf + std::visit([](const auto& integrator) { return integrator.settings_text(); }, i.method);
  // The shot's time changes the image only where something moves: a still scene's text stays as
  // it was, so its buffers merge with those of builds before motion.
  if (scene_moves(s)) {
    char t[160];
    std::snprintf(t, sizeof t, ";time=fps:%.17g:shutter:%.17g:%.17g", s.time.fps,
                  s.time.shutter_open, s.time.shutter_close);
    text += t;
  }
  return text;
}

void check_renderable(const Scene& scene) {
  std::visit(
      [&](const auto& integrator) {
        using Module = std::decay_t<decltype(integrator)>;
        const uint64_t pixels = uint64_t(scene.film.width) * uint64_t(scene.film.height);
        if (Module::kSplats && pixels > kMaxSplatPixels)
          throw SceneError(
              scene.path + ": film " + std::to_string(scene.film.width) + "x" +
              std::to_string(scene.film.height) + ": the " + std::string(Module::kName) +
              " integrator splats light paths over the whole frame, so every task carries a "
              "plane of the whole frame (24 bytes a pixel) and the frame cannot be kept in "
              "tiles; it renders at most " +
              std::to_string(kMaxSplatPixels) +
              " pixels (4096x4096). Path, direct, ao and whitted render up to " +
              std::to_string(kMaxResolution) + "x" + std::to_string(kMaxResolution));
        if (!Module::kMovingGeometry)
          for (size_t i = 0; i < scene.instances.size(); ++i)
            if (scene.instances[i].moves())
              throw SceneError(
                  scene.path + ": '" + scene.objects.at(scene.instances[i].object).name +
                  "' (instance " + std::to_string(i) + ") moves during the shot: the " +
                  std::string(Module::kName) +
                  " integrator shares its per-pass light state between camera samples at "
                  "different times, so it does not render moving geometry; path, direct, ao, "
                  "whitted, light and bdpt do");
        if (!Module::kMovingGeometry)
          for (const Mesh& m : scene.meshes)
            if (m.deforms())
              throw SceneError(scene.path + ": shape '" + m.name +
                               "' deforms during the shot: the " + std::string(Module::kName) +
                               " integrator shares its per-pass light state between camera "
                               "samples at different times, so it does not render moving "
                               "geometry; path, direct, ao, whitted, light and bdpt do");
        integrator.check(scene);
      },
      scene.render.integrator.method);
}

}  // namespace rf
