// Shapes: pbrt-v4's meshes and analytic shapes as the engine's triangle meshes, their front side,
// and area lights on them (docs/formats/pbrt.md "Shapes" and "Lights").
#include <algorithm>
#include <cmath>
#include <map>

#include "engine/formats/mesh_placement.h"
#include "engine/formats/pbrt/pbrt_builder.h"
#include "engine/shapes.h"
#include "engine/formats/pbrt/pbrt_shapes.h"

namespace rf::pbrt {

namespace {

constexpr double kPiD = 3.14159265358979323846;

std::vector<Vec3> to_vec3(const std::vector<double>& v) {
  std::vector<Vec3> out;
  for (size_t i = 0; i + 2 < v.size(); i += 3)
    out.emplace_back(float(v[i]), float(v[i + 1]), float(v[i + 2]));
  return out;
}

std::vector<Vec2> uvs_of(const ParamList& params) {
  for (const char* name : {"uv", "st"}) {
    const Param* p = params.find(name);
    if (!p) continue;
    std::vector<Vec2> out;
    for (size_t i = 0; i + 1 < p->numbers.size(); i += 2)
      out.push_back({float(p->numbers[i]), float(p->numbers[i + 1])});
    if (p->numbers.size() % 2 != 0 || (p->type != "point2" && p->type != "float"))
      fail(p->at, "parameter " + p->decl() + ": expected \"point2 " + name +
                      "\" with 2 values per vertex");
    return out;
  }
  return {};
}

std::vector<uint32_t> indices_of(const ParamList& params, size_t vertices, size_t per,
                                 const Location& at, const std::string& d) {
  std::vector<double> v = params.numbers("indices", "integer", 1);
  if (v.empty()) {
    if (vertices == per) {
      std::vector<uint32_t> out(per);
      for (size_t i = 0; i < per; ++i) out[i] = uint32_t(i);
      return out;
    }
    fail(at,
         d + ": needs \"integer indices\" (there are " + std::to_string(vertices) + " vertices)");
  }
  if (v.size() % per != 0)
    fail(params.find("indices")->at, d + ": \"integer indices\" must hold " + std::to_string(per) +
                                         " indices per " + (per == 3 ? "triangle" : "patch") +
                                         ", got " + std::to_string(v.size()));
  std::vector<uint32_t> out;
  for (double x : v) {
    if (x < 0 || x >= double(vertices))
      fail(params.find("indices")->at, d + ": index " + format_number(x) + " out of range (" +
                                           std::to_string(vertices) + " vertices)");
    out.push_back(uint32_t(x));
  }
  return out;
}

}  // namespace

MeshData Builder::shape_mesh(const std::string& type, const ParamList& params, const Location& at,
                             std::vector<uint32_t>& element_of_triangle, bool& whole_shape) {
  const std::string d = "Shape \"" + type + "\"";
  whole_shape = false;
  exact_sphere_radius_ = 0;
  if (type == "trianglemesh" || type == "bilinearmesh") {
    std::vector<Vec3> p = to_vec3(params.numbers("P", "point3", 3));
    if (p.empty()) fail(at, d + ": needs \"point3 P\"");
    std::vector<Vec3> n = to_vec3(params.numbers("N", "normal3", 3));
    std::vector<Vec2> uv = uvs_of(params);
    if (!n.empty() && n.size() != p.size())
      fail(at, d + ": \"normal N\" has " + std::to_string(n.size()) + " normals for " +
                   std::to_string(p.size()) + " vertices");
    if (!uv.empty() && uv.size() != p.size())
      fail(at, d + ": \"point2 uv\" has " + std::to_string(uv.size()) + " uvs for " +
                   std::to_string(p.size()) + " vertices");
    if (type == "trianglemesh") {
      MeshData m;
      m.indices = indices_of(params, p.size(), 3, at, d);
      m.positions = std::move(p);
      m.normals = std::move(n);
      m.uvs = std::move(uv);
      return m;
    }
    std::vector<uint32_t> idx = indices_of(params, p.size(), 4, at, d);
    return make_bilinear_patches(p, idx, n, uv, 16, element_of_triangle);
  }
  if (type == "plymesh") {
    std::string file = params.string("filename", "");
    if (file.empty()) fail(at, d + ": needs \"string filename\"");
    if (file.size() > 3 && file.compare(file.size() - 3, 3, ".gz") == 0)
      fail(at, d + " \"" + file + "\": gzip-compressed PLY files are not supported");
    return files_call(at, d + " \"" + file + "\"",
                      [&] { return files_.mesh(file, "ply", "filename"); });
  }
  if (type == "sphere") {
    float r = float(params.number("radius", 1));
    if (!(r > 0)) fail(at, d + ": \"float radius\" must be > 0");
    float zmin = float(params.number("zmin", -r)), zmax = float(params.number("zmax", r));
    float phimax = float(params.number("phimax", 360));
    if (!(phimax > 0)) fail(at, d + ": \"float phimax\" must be > 0");
    whole_shape = true;
    if (zmin <= -r && zmax >= r && phimax >= 360) exact_sphere_radius_ = r;
    return make_pbrt_sphere(r, zmin, zmax, phimax, 64, 128);
  }
  if (type == "disk") {
    float h = float(params.number("height", 0)), r = float(params.number("radius", 1));
    float ri = float(params.number("innerradius", 0)), phimax = float(params.number("phimax", 360));
    if (!(r > 0) || ri < 0 || !(ri < r)) fail(at, d + ": needs 0 <= innerradius < radius");
    if (!(phimax > 0)) fail(at, d + ": \"float phimax\" must be > 0");
    whole_shape = true;
    return make_pbrt_disk(h, r, ri, phimax, 128);
  }
  if (type == "loopsubdiv") {
    // The control mesh, flat: Loop subdivision is not implemented.
    std::vector<Vec3> p = to_vec3(params.numbers("P", "point3", 3));
    if (p.empty()) fail(at, d + ": needs \"point3 P\"");
    MeshData m;
    m.indices = indices_of(params, p.size(), 3, at, d);
    m.positions = std::move(p);
    warn(at, d + ": Loop subdivision is not supported; the control mesh (" +
                 std::to_string(m.indices.size() / 3) + " triangles, \"levels\" " +
                 std::to_string(params.integer("levels", 3)) + ") is rendered flat");
    return m;
  }
  static const char* unsupported[] = {"cylinder", "cone",  "paraboloid", "hyperboloid",
                                      "curve",    "nurbs", "heightfield"};
  for (const char* u : unsupported)
    if (type == u)
      fail(at,
           d + ": shape not supported (known: trianglemesh, plymesh, bilinearmesh, sphere, disk)");
  fail(at, d + ": unknown shape (known: trianglemesh, plymesh, bilinearmesh, sphere, disk)");
}

void Builder::shape(const std::string& type, const ParamList& params, const Location& at) {
  const std::string d = "Shape \"" + type + "\"";
  bool interface = false, pending = false;
  uint32_t material = material_for_shape(at, d, interface, pending);
  std::vector<uint32_t> element_of_triangle;
  bool whole = false;
  MeshData data = shape_mesh(type, params, at, element_of_triangle, whole);
  if (const Param* a = params.find("alpha")) {
    if (a->type == "float" && a->numbers.size() == 1 && a->numbers[0] <= 0) {
      warn(at, d + ": \"float alpha\" 0 makes the shape invisible; it is left out");
      return;
    }
    if (!(a->type == "float" && a->numbers.size() == 1 && a->numbers[0] >= 1))
      warn(a->at, d + ": alpha cut-outs are not supported (the shape is opaque)");
  }
  warn_unused(params, d);
  if (interface) {
    warn(at, d + ": its material (\"interface\") has no surface; the shape is left out");
    return;
  }
  if (type == "sphere" || type == "disk") {
    if (gs_.reverse_orientation)
      for (Vec3& n : data.normals) n = -n;
  }
  // pbrt's front side: with vertex normals, the side they point to (pbrt turns the geometric
  // normal towards the shading normal); without, the winding's, flipped by ReverseOrientation.
  if (!data.normals.empty()) {
    for (size_t t = 0; t + 2 < data.indices.size(); t += 3) {
      uint32_t* i = &data.indices[t];
      if (i[0] >= data.positions.size() || i[1] >= data.positions.size() ||
          i[2] >= data.positions.size())
        continue;
      Vec3 gn = cross(data.positions[i[1]] - data.positions[i[0]],
                      data.positions[i[2]] - data.positions[i[0]]);
      if (dot(gn, data.normals[i[0]] + data.normals[i[1]] + data.normals[i[2]]) < 0)
        std::swap(i[1], i[2]);
    }
  } else if (gs_.reverse_orientation) {
    for (size_t t = 0; t + 2 < data.indices.size(); t += 3)
      std::swap(data.indices[t + 1], data.indices[t + 2]);
  }
  // A shape whose two transforms differ moves (pbrt-v4's animated shape): an object of its own,
  // in its own space, placed by one moving instance along the transform pair. (Inside
  // ObjectBegin the object's instances move, not its shapes: the start transform places them.)
  const bool moving = gs_.moving() && current_object_ < 0;
  if (gs_.moving() && current_object_ >= 0)
    warn(at, d + ": inside ObjectBegin its motion (ActiveTransform) is ignored: the start "
                 "transform places it; ObjectInstance may move");
  const Mat4 ctm = gs_.ctm, ctm_end = gs_.ctm_end;
  std::optional<AnimatedTransform> motion;
  if (moving) {
    motion = ctm_motion(at, d);
    SceneObject obj;
    obj.name = d + " at " + at.str();
    scene_.objects.push_back(std::move(obj));
    object_lights_.emplace_back();  // (indexed as the objects)
    current_object_ = int(scene_.objects.size() - 1);
    gs_.ctm = gs_.ctm_end = Mat4::identity();
  }
  std::vector<Mesh>& target =
      current_object_ >= 0 ? scene_.objects[size_t(current_object_)].meshes : scene_.meshes;
  size_t first = target.size();
  add_mesh(std::move(data), element_of_triangle, whole, type, at, material);
  if (pending)
    for (size_t i = first; i < target.size(); ++i)
      pending_materials_.push_back({current_object_, i, gs_.material_name, gs_.material_at, at, d});
  if (moving) {
    Instance inst(uint32_t(current_object_), motion->keys().front().m);
    inst.motion = *motion;
    scene_.instances.push_back(inst);
    current_object_ = -1;
    gs_.ctm = ctm, gs_.ctm_end = ctm_end;
  }
}

void Builder::add_mesh(MeshData data, const std::vector<uint32_t>& element_of_triangle,
                       bool whole_shape, const std::string& type, const Location& at,
                       uint32_t material) {
  const std::string d = "Shape \"" + type + "\"";
  std::vector<Mesh>& target =
      current_object_ >= 0 ? scene_.objects[size_t(current_object_)].meshes : scene_.meshes;
  const Mat4& ctm = gs_.ctm;
  // pbrt's sphere: pole on +z, u = phi / 2pi from +x towards +y, v = 1 - theta / pi; as axes of
  // make_sphere's parametrisation (pole on axis 1, phi from axis 0 towards -axis 2).
  static const Vec3 kPbrtSphereAxes[3] = {{1, 0, 0}, {0, 0, 1}, {0, -1, 0}};
  SphereShape sphere;
  bool exact = exact_sphere_radius_ > 0 && !gs_.reverse_orientation &&
               place_sphere(Vec3(0.0f), exact_sphere_radius_, kPbrtSphereAxes, ctm, sphere);
  auto place = [&](MeshData m, std::optional<Emission> e) {
    Mesh mesh;
    mesh.name = d + " at " + at.str();
    mesh.material = material;
    mesh.emission = e;
    if (exact) {
      mesh.sphere = sphere;
      target.push_back(std::move(mesh));
      return;
    }
    place_mesh(std::move(m), ctm, at.str(), d, mesh);
    target.push_back(std::move(mesh));
  };
  if (!gs_.area_light) {
    place(std::move(data), std::nullopt);
    return;
  }
  const AreaLight& a = *gs_.area_light;
  Emission e;
  e.two_sided = a.two_sided;
  e.radiance = a.L * a.scale;
  if (is_black(e.radiance)) {
    place(std::move(data), std::nullopt);
    return;
  }
  if (a.power <= 0) {
    place(std::move(data), e);
    return;
  }
  // pbrt-v4's "power" sets each light's power, and a mesh is one light per triangle (per patch
  // for bilinear meshes): L = power / (pi area sides) with that element's world-space area.
  auto tri_area = [&](size_t t) {
    const uint32_t* i = &data.indices[t * 3];
    if (i[0] >= data.positions.size() || i[1] >= data.positions.size() ||
        i[2] >= data.positions.size())
      return 0.0;
    Vec3 p0 = ctm.point(data.positions[i[0]]), p1 = ctm.point(data.positions[i[1]]),
         p2 = ctm.point(data.positions[i[2]]);
    return 0.5 * double(length(cross(p1 - p0, p2 - p0)));
  };
  const size_t tris = data.indices.size() / 3;
  const double sides = a.two_sided ? 2.0 : 1.0;
  auto radiance_for = [&](double area) {
    return e.radiance * float(a.power / (kPiD * area * sides));
  };
  if (whole_shape) {
    double area = 0;
    for (size_t t = 0; t < tris; ++t) area += tri_area(t);
    if (exact) area = 4 * kPiD * double(sphere.radius) * double(sphere.radius);
    if (area > 0) e.radiance = radiance_for(area);
    place(std::move(data), e);
    return;
  }
  std::vector<double> element_area;
  for (size_t t = 0; t < tris; ++t) {
    size_t el = element_of_triangle.empty() ? t : element_of_triangle[t];
    if (element_area.size() <= el) element_area.resize(el + 1, 0.0);
    element_area[el] += tri_area(t);
  }
  // Elements of equal area (to 1e-4) share a mesh.
  std::map<long long, std::vector<size_t>> groups;  // key: rounded log area -> triangles
  for (size_t t = 0; t < tris; ++t) {
    double area = element_area[element_of_triangle.empty() ? t : element_of_triangle[t]];
    if (!(area > 0)) continue;
    groups[std::llround(std::log(area) * 1e4)].push_back(t);
  }
  if (groups.size() > 64) {
    double total = 0;
    for (double x : element_area) total += x;
    warn(a.at,
         d + ": \"power\" on a mesh of " + std::to_string(groups.size()) +
             " different element areas: the mean element area is used for all (pbrt-v4 gives each "
             "triangle its own radiance)");
    e.radiance = radiance_for(total / double(element_area.size()));
    place(std::move(data), e);
    return;
  }
  for (auto& [key, list] : groups) {
    MeshData sub;
    sub.positions = data.positions;
    sub.normals = data.normals;
    sub.uvs = data.uvs;
    for (size_t t : list)
      sub.indices.insert(sub.indices.end(), &data.indices[t * 3], &data.indices[t * 3] + 3);
    Emission ge = e;
    size_t el = element_of_triangle.empty() ? list[0] : element_of_triangle[list[0]];
    ge.radiance = radiance_for(element_area[el]);
    place(std::move(sub), ge);
  }
}

}  // namespace rf::pbrt
