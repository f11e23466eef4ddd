// The scene's settings independent of any file format: filter and sampler names, conductor
// presets, default passes, and the command-line overrides every format's scene takes.
#include <algorithm>
#include <cmath>
#include <numeric>

#include "engine/check.h"
#include "engine/json_reader.h"
#include "engine/scene.h"
#include "engine/shapes.h"

namespace rf {

const std::vector<std::string>& known_filters() {
  static const std::vector<std::string> names = {"box", "triangle", "gaussian"};
  return names;
}

FilterType filter_type(const std::string& name) {
  if (name == "triangle") return FilterType::Triangle;
  if (name == "gaussian") return FilterType::Gaussian;
  return FilterType::Box;
}

float default_filter_radius(FilterType t) {
  switch (t) {
    case FilterType::Box: return 0.5f;
    case FilterType::Triangle: return 1.0f;
    case FilterType::Gaussian: return 1.5f;
  }
  return 0.5f;
}

const std::vector<std::string>& known_samplers() {
  static const std::vector<std::string> names = {"independent", "sobol", "sobol-sequence"};
  return names;
}

// gcd(spp, 16), halved while it exceeds 4 and leaves a pass fewer than 64 samples per pixel: a
// Sobol pass stratifies only its own samples (passes are independent replicates), so its error
// falls faster with samples per pass than with passes (docs/performance.md, "One Sobol sequence
// across passes (`sobol-sequence`)"), while at least 4 passes keep a batch-means variance (3
// degrees of freedom at least) and progressive merges. 64 -> 4, 256 -> 4, 512 -> 8, 1024 -> 16,
// 100 -> 4, 24 -> 8 -> 4.
uint32_t default_passes(uint64_t spp) {
  uint64_t p = std::gcd(spp, uint64_t(16));
  while (p > 4 && spp / p < 64) p /= 2;
  return uint32_t(p);
}

const std::vector<ConductorPreset>& conductor_presets() {
  // Complex IOR (eta, k) averaged over the R, G, B bands of measured spectral data.
  static const std::vector<ConductorPreset> presets = {
      {"gold", {0.143f, 0.374f, 1.442f}, {3.983f, 2.385f, 1.603f}},
      {"silver", {0.155f, 0.117f, 0.138f}, {4.828f, 3.122f, 2.147f}},
      {"copper", {0.200f, 0.924f, 1.102f}, {3.912f, 2.452f, 2.142f}},
      {"aluminium", {1.657f, 0.880f, 0.521f}, {9.224f, 6.270f, 4.837f}},
  };
  return presets;
}

const ConductorPreset* conductor_preset(const std::string& name) {
  for (const ConductorPreset& c : conductor_presets())
    if (name == c.name) return &c;
  return nullptr;
}

namespace {

// Validated override values; the message names the command-line flag.
[[noreturn]] void flag_fail(const std::string& flag, const std::string& what) {
  throw SceneError(flag + ": " + what);
}

// The CLI sets width and height together as --res WxH.
void check_resolution(const std::optional<int>& v, const char* what) {
  if (v && (*v < 1 || *v > kMaxResolution))
    flag_fail("--res", std::string(what) + " must be between 1 and " +
                           std::to_string(kMaxResolution) + ", got " + std::to_string(*v));
}

// spp and passes together: an explicit --passes must divide the spp; a new --spp alone keeps the
// scene's passes if they divide it, else passes become gcd(spp, 16).
void override_passes(RenderSettings& rs, const SceneOverrides& o) {
  if (o.spp) rs.spp = *o.spp;
  if (o.passes) {
    rs.passes = *o.passes;
    if (rs.spp % rs.passes == 0) return;
    if (o.spp)
      flag_fail("--spp", "must be a multiple of --passes (" + std::to_string(rs.passes) +
                             "), got " + std::to_string(rs.spp));
    flag_fail("--passes", "must divide the scene's spp (" + std::to_string(rs.spp) + "), got " +
                              std::to_string(rs.passes));
  }
  if (o.spp && rs.spp % rs.passes != 0)
    rs.passes = default_passes(rs.spp);
}

}  // namespace

namespace {
// --shutter's value: "OPEN,CLOSE" (frames, OPEN <= CLOSE) or one number T (the instant T).
void parse_shutter(const std::string& text, double& open, double& close) {
  auto number = [&](const std::string& s) {
    size_t used = 0;
    double v = 0;
    try {
      v = std::stod(s, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (s.empty() || used != s.size() || !std::isfinite(v) || std::fabs(v) > kMaxShutterFrames)
      flag_fail(
          "--shutter",
          "expected OPEN,CLOSE in frames (e.g. 0,0.5) or one instant (0), got '" + text + "'");
    return v;
  };
  const size_t comma = text.find(',');
  open = number(text.substr(0, comma));
  close = comma == std::string::npos ? open : number(text.substr(comma + 1));
  if (close < open)
    flag_fail("--shutter", "closes (" + format_number(close) + ") before it opens (" +
                               format_number(open) + ")");
}
}  // namespace

void check_overrides(const SceneOverrides& o) {
  if (o.shutter) {
    double open, close;
    parse_shutter(*o.shutter, open, close);
  }
  if (o.integrator && !contains_name(known_integrators(), *o.integrator))
    flag_fail("--integrator", "unknown integrator '" + *o.integrator +
                                  "' (known: " + join_names(known_integrators()) + ")");
  if (o.max_depth && *o.max_depth < 0)
    flag_fail("--max-depth", "must be at least 0, got " + std::to_string(*o.max_depth));
  check_resolution(o.width, "width");
  check_resolution(o.height, "height");
  if (o.filter && !contains_name(known_filters(), *o.filter))
    flag_fail("--filter",
              "unknown filter '" + *o.filter + "' (known: " + join_names(known_filters()) + ")");
  if (o.sampler && !contains_name(known_samplers(), *o.sampler))
    flag_fail("--sampler",
              "unknown sampler '" + *o.sampler + "' (known: " + join_names(known_samplers()) + ")");
  if (o.light_selection && *o.light_selection != "auto" && *o.light_selection != "power" &&
      *o.light_selection != "bvh")
    flag_fail("--light-selection",
              "unknown light selection '" + *o.light_selection + "' (known: auto, power, bvh)");
  if (o.aovs) {
    try {
      parse_aovs(*o.aovs);
    } catch (const std::invalid_argument& e) {
      flag_fail("--aov", e.what());
    }
  }
  if (o.noise_target && !(*o.noise_target >= 0 && std::isfinite(*o.noise_target)))
    flag_fail("--noise-target",
              "must be a finite number >= 0, got " + format_number(*o.noise_target));
  if (o.spp && *o.spp < 1) flag_fail("--spp", "must be at least 1, got 0");
  if (o.passes && *o.passes < 1) flag_fail("--passes", "must be at least 1, got 0");
  if (o.spp && o.passes && *o.spp % *o.passes != 0)
    flag_fail("--spp", "must be a multiple of --passes (" + std::to_string(*o.passes) + "), got " +
                           std::to_string(*o.spp));
}

void apply_overrides(Scene& scene, const SceneOverrides& o) {
  check_overrides(o);
  // Work on copies so a rejected override leaves the scene untouched.
  FilmSettings film = scene.film;
  RenderSettings rs = scene.render;
  if (o.max_depth) rs.integrator.max_depth = *o.max_depth;
  if (o.integrator) set_integrator(rs.integrator, *o.integrator);
  apply_fixed_max_depth(rs.integrator);  // direct lighting: one bounce by definition
  if (o.width) film.width = *o.width;
  if (o.height) film.height = *o.height;
  if (o.filter && *o.filter != "" && filter_type(*o.filter) != film.filter.type) {
    film.filter.type = filter_type(*o.filter);
    film.filter.radius = default_filter_radius(film.filter.type);
  }
  if (o.sampler) rs.sampler = *o.sampler;
  if (o.light_selection) rs.light_selection = *o.light_selection;
  if (o.aovs) rs.aovs = parse_aovs(*o.aovs);
  if (o.noise_target) rs.noise_target = *o.noise_target;
  if (o.seed) rs.seed = *o.seed;
  override_passes(rs, o);
  if (o.shutter) parse_shutter(*o.shutter, scene.time.shutter_open, scene.time.shutter_close);
  scene.film = film;
  scene.render = rs;
}

namespace {

// A world-space copy of an object's mesh placed by instance i (the same placement as
// place_mesh: normals by the inverse transpose, winding swapped under mirroring so the front side
// stays the front side).
Mesh instanced_copy(const Mesh& m, const Instance& inst, size_t i, const std::string& object) {
  Mesh w = m;
  w.name = m.name + " (instance " + std::to_string(i) + " of " + object + ")";
  if (m.sphere) {
    const SphereShape& s = *m.sphere;
    SphereShape placed;
    if (place_sphere(s.center, s.radius, s.axis, inst.to_world, placed)) {
      w.sphere = placed;
      return w;
    }
    // Not a similarity: the sphere becomes an ellipsoid, a mesh (at the default tessellation).
    MeshData d = tessellate_sphere(s, kSphereThetaSteps, kSpherePhiSteps);
    w.sphere.reset();
    w.positions = std::move(d.positions);
    w.normals = std::move(d.normals);
    w.uvs = std::move(d.uvs);
    w.indices = std::move(d.indices);
  }
  for (Vec3& p : w.positions) p = inst.to_world.point(p);
  for (Vec3& n : w.normals) n = normalize(inst.to_world.normal(n));
  if (inst.to_world.det3() < 0)
    for (size_t t = 0; t + 2 < w.indices.size(); t += 3) std::swap(w.indices[t + 1], w.indices[t + 2]);
  return w;
}

// A moving instance's world copy of mesh m (an emitter: lights are sampled per world triangle)
// as a deforming mesh: its vertices placed by the instance's track at linear_sample_times (every
// key, and steps within a segment that turns or scales, so that vertices moving linearly between
// keys stay within 1e-4 of the track's size: a translation is exact); a sphere is tessellated
// first.
Mesh moving_copy(const Mesh& m, const Instance& inst, size_t i, const std::string& object) {
  Mesh w = m;
  w.name = m.name + " (instance " + std::to_string(i) + " of " + object + ")";
  if (m.sphere) {
    MeshData d = tessellate_sphere(*m.sphere, kSphereThetaSteps, kSpherePhiSteps);
    w.sphere.reset();
    w.positions = std::move(d.positions);
    w.normals = std::move(d.normals);
    w.uvs = std::move(d.uvs);
    w.indices = std::move(d.indices);
  }
  const std::vector<Vec3> positions = w.positions, normals = w.normals;
  const std::vector<Keyframe>& keys = inst.motion.keys();
  for (double t : linear_sample_times(inst.motion)) {
    const Mat4 xf = inst.motion.at(t);
    VertexKey key;
    key.time = t;
    for (const Vec3& p : positions) key.positions.push_back(xf.point(p));
    for (const Vec3& n : normals) key.normals.push_back(normalize(xf.normal(n)));
    w.deform.push_back(std::move(key));
  }
  w.positions = w.deform.front().positions;
  w.normals = w.deform.front().normals;
  if (keys.front().m.det3() < 0)
    for (size_t t = 0; t + 2 < w.indices.size(); t += 3)
      std::swap(w.indices[t + 1], w.indices[t + 2]);
  return w;
}

}  // namespace

bool geometry_moves(const Scene& scene) {
  return std::any_of(scene.instances.begin(), scene.instances.end(),
                     [](const Instance& i) { return i.moves(); }) ||
         std::any_of(scene.meshes.begin(), scene.meshes.end(),
                     [](const Mesh& m) { return m.deforms(); });
}

void deformed_vertices(const Mesh& m, double time, std::vector<Vec3>& positions,
                       std::vector<Vec3>& normals) {
  const std::vector<VertexKey>& keys = m.deform;
  RF_CHECK(!keys.empty(), "deformed_vertices of a mesh without keys");
  size_t b = 0;  // the first key after `time`
  while (b < keys.size() && keys[b].time <= time) ++b;
  if (b == 0 || b == keys.size()) {  // held before the first key and after the last
    const VertexKey& k = keys[b == 0 ? 0 : b - 1];
    positions = k.positions, normals = k.normals;
    return;
  }
  const VertexKey &ka = keys[b - 1], &kb = keys[b];
  const float f = float((time - ka.time) / (kb.time - ka.time));
  auto lerp = [f](const std::vector<Vec3>& a, const std::vector<Vec3>& c, std::vector<Vec3>& out) {
    out.resize(a.size());
    for (size_t i = 0; i < a.size(); ++i) out[i] = a[i] * (1 - f) + c[i] * f;
  };
  if (f == 0) {  // exactly at a key: its own vertices
    positions = ka.positions, normals = ka.normals;
    return;
  }
  lerp(ka.positions, kb.positions, positions);
  lerp(ka.normals, kb.normals, normals);
}

bool scene_moves(const Scene& scene) { return scene.camera.moves() || geometry_moves(scene); }

uint64_t scene_elements(const Scene& scene) {
  uint64_t n = scene.meshes.size() + scene.objects.size() + scene.instances.size() +
               scene.lights.size() + scene.materials.size() + scene.textures.size();
  for (const SceneObject& o : scene.objects) n += o.meshes.size();
  return n;
}

void prepare_instances(Scene& scene, uint64_t max_elements) {
  uint64_t elements = scene_elements(scene);
  auto over = [&](const std::string& what) {
    return SceneError(scene.path + ": " + what + "; the import limit elements is " +
                      std::to_string(max_elements) +
                      " (shapes, instances, lights, materials, textures, and the triangles of "
                      "instanced emitters copied to world space)");
  };
  if (elements > max_elements) throw over(std::to_string(elements) + " elements");
  for (size_t i = 0; i < scene.instances.size(); ++i) {
    const Instance& inst = scene.instances[i];
    const std::string where = "instance " + std::to_string(i);
    if (inst.object >= scene.objects.size())
      throw SceneError(scene.path + ": " + where + ": object " + std::to_string(inst.object) +
                       " does not exist (" + std::to_string(scene.objects.size()) + " objects)");
    auto bad = [](const Mat4& m) { return !m.is_finite() || !(std::fabs(m.det3()) > 0); };
    auto refuse = [&](const std::string& which) {
      throw SceneError(scene.path + ": " + where + " of '" + scene.objects[inst.object].name +
                       "': the transform must be finite and invertible" + which);
    };
    if (!inst.moves() && bad(inst.to_world)) refuse("");
    static const std::vector<Keyframe> kNoKeys;
    for (const Keyframe& k : inst.moves() ? inst.motion.keys() : kNoKeys)
      if (bad(k.m)) refuse(" (the key at " + std::to_string(k.time) + " s)");
  }
  for (uint32_t o = 0; o < scene.objects.size(); ++o) {
    SceneObject& obj = scene.objects[o];
    auto emissive = [](const Mesh& m) { return m.emission && !is_black(m.emission->radiance); };
    if (std::none_of(obj.meshes.begin(), obj.meshes.end(), emissive)) continue;
    uint64_t triangles = 0, placements = 0;
    for (const Mesh& m : obj.meshes)
      if (emissive(m)) triangles += m.primitive_count();
    for (size_t i = 0; i < scene.instances.size(); ++i) {
      const Instance& inst = scene.instances[i];
      placements += inst.object == o;
    }
    if (placements && triangles > (max_elements - elements) / placements)
      throw over("object '" + obj.name + "' holds " + std::to_string(triangles) +
                 " emissive triangles, placed " + std::to_string(placements) +
                 " times: that many world-space copies (area lights are sampled per triangle)");
    elements += triangles * placements;
    for (size_t i = 0; i < scene.instances.size(); ++i)
      if (scene.instances[i].object == o)
        for (const Mesh& m : obj.meshes)
          if (emissive(m))
            scene.meshes.push_back(scene.instances[i].moves()
                                       ? moving_copy(m, scene.instances[i], i, obj.name)
                                       : instanced_copy(m, scene.instances[i], i, obj.name));
    obj.meshes.erase(std::remove_if(obj.meshes.begin(), obj.meshes.end(), emissive),
                     obj.meshes.end());
  }
  // Deforming meshes (moving instances' emitters among them): world triangle meshes whose keys
  // match the mesh (first key its own vertices, every key as many positions and normals, times
  // increasing and finite, positions finite).
  for (size_t i = 0; i < scene.meshes.size(); ++i) {
    const Mesh& m = scene.meshes[i];
    if (m.deform.empty()) continue;
    auto refuse = [&](const std::string& why) {
      throw SceneError(scene.path + ": shape '" + m.name + "' deforms: " + why);
    };
    if (m.sphere) refuse("only triangle meshes deform");
    if (m.deform.size() < 2) refuse("give at least two keys");
    elements += m.deform.size() * m.positions.size();
    if (elements > max_elements)
      throw over(std::to_string(elements) + " elements with the deforming shapes' vertex keys");
    for (size_t k = 0; k < m.deform.size(); ++k) {
      const VertexKey& key = m.deform[k];
      const std::string at = " (key " + std::to_string(k) + ")";
      if (!std::isfinite(key.time)) refuse("a key's time is not finite" + at);
      if (k > 0 && !(key.time > m.deform[k - 1].time))
        refuse("keys must be in increasing time" + at);
      if (key.positions.size() != m.positions.size() || key.normals.size() != m.normals.size())
        refuse("every key must have the mesh's " + std::to_string(m.positions.size()) +
               " positions and " + std::to_string(m.normals.size()) + " normals" + at);
      for (const Vec3& q : key.positions)
        if (!std::isfinite(q.x) || !std::isfinite(q.y) || !std::isfinite(q.z))
          refuse("a position is not finite" + at);
    }
    if (m.deform.front().positions != m.positions || m.deform.front().normals != m.normals)
      refuse("the first key must be the mesh's own vertices");
  }
  for (const SceneObject& obj : scene.objects)
    for (const Mesh& m : obj.meshes)
      if (!m.deform.empty())
        throw SceneError(scene.path + ": shape '" + m.name + "' of object '" + obj.name +
                         "' deforms: only shapes placed in the world deform, not an instanced "
                         "object's");
}

void flatten_instances(Scene& scene) {
  RF_CHECK(std::none_of(scene.instances.begin(), scene.instances.end(),
                        [](const Instance& i) { return i.moves(); }),
           "flatten_instances of a scene whose instances move");
  for (size_t i = 0; i < scene.instances.size(); ++i) {
    const Instance& inst = scene.instances[i];
    const SceneObject& obj = scene.objects.at(inst.object);
    for (const Mesh& m : obj.meshes) scene.meshes.push_back(instanced_copy(m, inst, i, obj.name));
  }
  scene.instances.clear();
  scene.objects.clear();
}

void mesh_bounds(const Mesh& m, Vec3& lo, Vec3& hi) {
  if (m.sphere) {
    lo = vmin(lo, m.sphere->center - Vec3(m.sphere->radius));
    hi = vmax(hi, m.sphere->center + Vec3(m.sphere->radius));
  }
  for (Vec3 q : m.positions) lo = vmin(lo, q), hi = vmax(hi, q);
  for (const VertexKey& k : m.deform)  // linear between keys: the keys' box holds every time's
    for (Vec3 q : k.positions) lo = vmin(lo, q), hi = vmax(hi, q);
}

void scene_bounds(const Scene& scene, Vec3& lo, Vec3& hi) {
  lo = Vec3(kInf), hi = Vec3(-kInf);
  for (const Mesh& m : scene.meshes) mesh_bounds(m, lo, hi);
  std::vector<std::pair<Vec3, Vec3>> object_box(scene.objects.size(), {Vec3(kInf), Vec3(-kInf)});
  for (size_t o = 0; o < scene.objects.size(); ++o)
    for (const Mesh& m : scene.objects[o].meshes) mesh_bounds(m, object_box[o].first, object_box[o].second);
  for (const Instance& inst : scene.instances) {
    const Vec3 a = object_box.at(inst.object).first, b = object_box.at(inst.object).second;
    if (a.x > b.x) continue;
    auto place = [&](const Mat4& m, Vec3& box_lo, Vec3& box_hi) {  // grows the box by a placement
      for (int c = 0; c < 8; ++c) {
        Vec3 q = m.point({(c & 1) ? b.x : a.x, (c & 2) ? b.y : a.y, (c & 4) ? b.z : a.z});
        box_lo = vmin(box_lo, q), box_hi = vmax(box_hi, q);
      }
    };
    if (!inst.moves()) {
      place(inst.to_world, lo, hi);
      continue;
    }
    // A moving instance: its box at kBoundSteps times per key segment (the box swept between two
    // of them by a rotation leaves their union by at most 1 - cos(pi / kBoundSteps) of its
    // radius for a half turn per segment, 0.05% at 100), then grown by 1% of its extent.
    constexpr int kBoundSteps = 100;
    Vec3 mlo(kInf), mhi(-kInf);  // the swept box
    const std::vector<Keyframe>& keys = inst.motion.keys();
    for (size_t k = 0; k + 1 < keys.size(); ++k)
      for (int j = 0; j <= kBoundSteps; ++j)
        place(inst.motion.at(keys[k].time + (keys[k + 1].time - keys[k].time) * j / kBoundSteps),
              mlo, mhi);
    const Vec3 pad = (mhi - mlo) * 0.01f;
    lo = vmin(lo, mlo - pad), hi = vmax(hi, mhi + pad);
  }
}

}  // namespace rf
