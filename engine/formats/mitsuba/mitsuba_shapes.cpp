// The Mitsuba 3 importer's shapes and their area emitters (mitsuba_parser.h).
#include "engine/formats/mitsuba/mitsuba_parser.h"

namespace rf::mitsuba {

void MitsubaParser::parse_shape(const Node& n, std::vector<Mesh>& out, bool in_group) {
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

MeshData MitsubaParser::mitsuba_sphere() {
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

std::optional<Emission> MitsubaParser::area_emission(const Node& n) {
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

}  // namespace rf::mitsuba
