// The glTF 2.0 importer (.gltf and .glb; docs/formats/gltf.md): tinygltf (Debian's shared
// library) parses the file and loads its buffers and images only through SceneFiles; this file
// checks what the model refers to, walks the node hierarchy of the default scene, and fills the
// Scene: meshes (a mesh placed by several nodes becomes an object with instances), the first
// camera, KHR_lights_punctual lights and the render defaults. Materials are in
// gltf_materials.cpp, accessors in gltf_accessors.cpp, embedded images in gltf_images.cpp.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <set>

#include "engine/formats/gltf/gltf_internal.h"
#include "engine/formats/importers.h"
#include "engine/formats/mesh_placement.h"
#include "engine/json_reader.h"

namespace rf {
namespace gltf {
namespace {

// What glTF does not carry (docs/formats/gltf.md "Defaults"); CLI overrides change them.
constexpr int kDefaultMaxDepth = 8;
constexpr uint64_t kDefaultSpp = 64;
constexpr int kLongerSide = 512;  // film pixels along the longer axis of the camera's aspectRatio
constexpr float kLumensPerWatt = 683.0f;  // photometric -> radiometric (555 nm, as glTF says)
constexpr float kDefaultEnvironmentRadiance = 1.0f;  // only for scenes without any light

const std::vector<std::string> kSupportedExtensions = {
    "KHR_lights_punctual",        "KHR_materials_emissive_strength",
    "KHR_texture_transform",      "KHR_materials_ior",
    "KHR_materials_transmission", "KHR_materials_volume",
    "KHR_materials_specular",     "KHR_mesh_quantization"};

// --------------------------------------------------------------------------------------------
// Loading through tinygltf, every file through SceneFiles.

struct LoadState {
  Context* c = nullptr;
  std::map<std::string, std::string> uri_where;  // decoded uri -> JSON pointer of its "uri"
  std::string error;                             // the first SceneError a callback caught
};

bool fs_exists(const std::string&, void*) { return true; }  // ReadWholeFile reports problems
std::string fs_expand(const std::string& p, void*) { return p; }
bool fs_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
  if (err) *err = "writing is not allowed";
  return false;
}

bool fs_read(std::vector<unsigned char>* out, std::string* err, const std::string& file,
             void* user) {
  auto* s = static_cast<LoadState*>(user);
  auto it = s->uri_where.find(file);
  std::string where = it != s->uri_where.end() ? it->second : "uri '" + file + "'";
  try {
    std::string bytes = s->c->files->read(file, where);
    out->assign(bytes.begin(), bytes.end());
    return true;
  } catch (const SceneError& e) {
    if (s->error.empty()) s->error = e.what();
    if (err) *err = e.what();
    return false;
  }
}

// Keeps the encoded bytes of data: URI images (to extract them later); external images are
// registered by fs_read and bufferView images are read, bounds checked, by image_file().
bool keep_image(tinygltf::Image* image, const int index, std::string*, std::string*, int, int,
                const unsigned char* bytes, int size, void* user) {
  auto* s = static_cast<LoadState*>(user);
  if (image->bufferView < 0 && image->uri.empty() && bytes && size > 0)
    s->c->data_uri_images[index].assign(reinterpret_cast<const char*>(bytes), size_t(size));
  return true;
}

uint32_t read_u32(const std::string& b, size_t at) {
  return uint32_t(uint8_t(b[at])) | uint32_t(uint8_t(b[at + 1])) << 8 |
         uint32_t(uint8_t(b[at + 2])) << 16 | uint32_t(uint8_t(b[at + 3])) << 24;
}

// The JSON chunk of a .glb, after checking the header (tinygltf checks it again).
std::string glb_json(const Context& c, const std::string& b) {
  const std::string w = "(GLB header)";
  if (b.size() < 20)
    c.fail(w, "truncated: " + std::to_string(b.size()) + " bytes (a GLB has at least 20)");
  if (read_u32(b, 4) != 2)
    c.fail(w, "GLB version " + std::to_string(read_u32(b, 4)) + " (expected 2)");
  if (read_u32(b, 8) != b.size())
    c.fail(w, "the header gives a length of " + std::to_string(read_u32(b, 8)) +
                  " bytes but the file has " + std::to_string(b.size()) +
                  (read_u32(b, 8) > b.size() ? " (truncated)" : ""));
  uint32_t json_len = read_u32(b, 12);
  if (read_u32(b, 16) != 0x4E4F534A) c.fail(w, "the first chunk is not JSON");
  if (json_len > b.size() - 20)
    c.fail(w, "the JSON chunk runs past the end of the file (truncated)");
  return b.substr(20, json_len);
}

// What tinygltf checks with a message that names no JSON path, and what it reads before checking
// (the address of an image's buffer-view bytes): checked here first, in the JSON (tinygltf makes
// each buffer exactly byteLength bytes long).
void precheck(const Context& c) {
  if (const json* views = c.at("/bufferViews"); views && views->is_array())
    for (size_t i = 0; i < views->size(); ++i) {
      const json* st = c.at(ptr(ptr("/bufferViews", i), "byteStride"));
      if (st && (!st->is_number_unsigned() || st->get<uint64_t>() < 4 ||
                 st->get<uint64_t>() > 252 || st->get<uint64_t>() % 4 != 0))
        c.fail(ptr(ptr("/bufferViews", i), "byteStride"),
               "must be a multiple of 4 in [4, 252], got " + describe_json(*st));
    }
  const json* images = c.at("/images");
  if (!images || !images->is_array()) return;
  auto uint_at = [&](const std::string& p, bool required) -> uint64_t {
    const json* v = c.at(p);
    if (!v && !required) return 0;
    if (!v || !v->is_number_unsigned()) c.fail(p, "expected an unsigned integer");
    return v->get<uint64_t>();
  };
  for (size_t i = 0; i < images->size(); ++i) {
    const std::string ip = ptr("/images", i);
    if (!c.at(ptr(ip, "bufferView"))) continue;
    const std::string vp = ptr("/bufferViews", uint_at(ptr(ip, "bufferView"), true));
    if (!c.at(vp)) c.fail(ptr(ip, "bufferView"), "the bufferView does not exist");
    const std::string bp = ptr("/buffers", uint_at(ptr(vp, "buffer"), true));
    if (!c.at(bp)) c.fail(ptr(vp, "buffer"), "the buffer does not exist");
    uint64_t off = uint_at(ptr(vp, "byteOffset"), false),
             len = uint_at(ptr(vp, "byteLength"), true);
    uint64_t size = uint_at(ptr(bp, "byteLength"), true);
    if (len == 0 || off > size || len > size - off)
      c.fail(vp, "bytes " + std::to_string(off) + " + " + std::to_string(len) + " of image " +
                     std::to_string(i) + " lie outside the buffer (" + std::to_string(size) +
                     " bytes)");
  }
}

void load_model(Context& c, const std::string& bytes, bool binary) {
  std::string text = binary ? glb_json(c, bytes) : bytes;
  c.root = parse_json_text(text, c.file);
  if (!c.root.is_object()) c.fail("/", "a glTF file is a JSON object");
  LoadState state;
  state.c = &c;
  for (const char* kind : {"buffers", "images"}) {
    const json* arr = c.at(std::string("/") + kind);
    if (!arr || !arr->is_array()) continue;
    for (size_t i = 0; i < arr->size(); ++i) {
      const json& e = (*arr)[i];
      if (e.is_object() && e.contains("uri") && e["uri"].is_string() &&
          e["uri"].get_ref<const std::string&>().compare(0, 5, "data:") != 0)
        state.uri_where[percent_decode(e["uri"].get<std::string>())] =
            ptr(ptr(std::string("/") + kind, i), "uri");
    }
  }
  precheck(c);
  if (bytes.size() > UINT32_MAX) c.fail("/", "files of 4 GiB or more are not supported");
  tinygltf::TinyGLTF loader;
  loader.SetFsCallbacks({&fs_exists, &fs_expand, &fs_read, &fs_write, &state});
  loader.SetImageLoader(&keep_image, &state);
  std::string err, warn;
  bool ok = false;
  try {
    ok = binary ? loader.LoadBinaryFromMemory(&c.model, &err, &warn,
                                              reinterpret_cast<const unsigned char*>(bytes.data()),
                                              unsigned(bytes.size()), "")
                : loader.LoadASCIIFromString(&c.model, &err, &warn, bytes.data(),
                                             unsigned(bytes.size()), "");
  } catch (const std::exception& e) {
    err = e.what();
    ok = false;
  }
  if (!state.error.empty()) throw SceneError(state.error);
  auto trim = [](std::string s) {
    while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
    for (char& ch : s)
      if (ch == '\n') ch = ';';
    return s;
  };
  if (!ok) c.fail("/", "the glTF parser (tinygltf) refused the file: " + trim(err));
  if (!trim(warn).empty()) c.warn("/", "the glTF parser (tinygltf) warns: " + trim(warn));
}

void check_asset_and_extensions(Context& c) {
  const std::string& v = c.model.asset.version;
  if (v.empty() || v[0] != '2')
    c.fail("/asset/version", "glTF version '" + v + "' (this importer reads 2.x)");
  const std::string& mv = c.model.asset.minVersion;
  if (!mv.empty() && mv != "2.0")
    c.fail("/asset/minVersion", "the file needs glTF " + mv + " (this importer reads 2.0)");
  for (size_t i = 0; i < c.model.extensionsRequired.size(); ++i)
    if (!contains_name(kSupportedExtensions, c.model.extensionsRequired[i]))
      c.fail(ptr("/extensionsRequired", i),
             "required extension " + c.model.extensionsRequired[i] +
                 " is not supported (supported: " + join_names(kSupportedExtensions) + ")");
  for (size_t i = 0; i < c.model.extensionsUsed.size(); ++i)
    if (!contains_name(kSupportedExtensions, c.model.extensionsUsed[i]) &&
        !contains_name(c.model.extensionsRequired, c.model.extensionsUsed[i]))
      c.warn(ptr("/extensionsUsed", i),
             "extension " + c.model.extensionsUsed[i] + " is not supported (ignored)");
}

// --------------------------------------------------------------------------------------------
// Nodes.

Mat4 node_matrix(const Context& c, size_t n) {
  const tinygltf::Node& node = c.model.nodes[n];
  const std::string p = ptr("/nodes", n);
  Mat4 m;
  if (!node.matrix.empty()) {
    if (node.matrix.size() != 16) c.fail(ptr(p, "matrix"), "expected 16 numbers");
    if (!node.translation.empty() || !node.rotation.empty() || !node.scale.empty())
      c.fail(p, "a node has either 'matrix' or translation/rotation/scale, not both");
    for (int col = 0; col < 4; ++col)
      for (int row = 0; row < 4; ++row) m.m[row][col] = float(node.matrix[size_t(col * 4 + row)]);
  } else {
    Vec3 t(0.0f), s(1.0f);
    double q[4] = {0, 0, 0, 1};  // x, y, z, w
    if (!node.translation.empty()) {
      if (node.translation.size() != 3) c.fail(ptr(p, "translation"), "expected 3 numbers");
      t = Vec3(float(node.translation[0]), float(node.translation[1]), float(node.translation[2]));
    }
    if (!node.scale.empty()) {
      if (node.scale.size() != 3) c.fail(ptr(p, "scale"), "expected 3 numbers");
      s = Vec3(float(node.scale[0]), float(node.scale[1]), float(node.scale[2]));
    }
    if (!node.rotation.empty()) {
      if (node.rotation.size() != 4)
        c.fail(ptr(p, "rotation"), "expected 4 numbers (a quaternion)");
      double len =
          std::sqrt(node.rotation[0] * node.rotation[0] + node.rotation[1] * node.rotation[1] +
                    node.rotation[2] * node.rotation[2] + node.rotation[3] * node.rotation[3]);
      if (!(len > 0) || !std::isfinite(len)) c.fail(ptr(p, "rotation"), "not a unit quaternion");
      for (int i = 0; i < 4; ++i) q[i] = node.rotation[size_t(i)] / len;
    }
    m = trs_matrix(t, q, s);
  }
  if (!m.is_finite()) c.fail(p, "the transform is not finite");
  return m;
}

// The nodes of the scene to render in depth-first order with their world transforms. A node
// reached twice (a cycle, or two parents) is an error; the walk uses its own stack, so a deep
// hierarchy cannot overflow the call stack.
std::vector<PlacedNode> walk_nodes(Context& c) {
  const auto& m = c.model;
  std::vector<int> roots;
  std::string roots_where;
  if (!m.scenes.empty()) {
    int s = m.defaultScene >= 0 ? m.defaultScene : 0;
    if (size_t(s) >= m.scenes.size())
      c.fail("/scene", "scene " + std::to_string(s) + " does not exist (the file has " +
                           std::to_string(m.scenes.size()) + ")");
    roots = m.scenes[size_t(s)].nodes;
    roots_where = ptr(ptr("/scenes", size_t(s)), "nodes");
  } else {
    std::vector<bool> child(m.nodes.size(), false);
    for (const auto& n : m.nodes)
      for (int k : n.children)
        if (k >= 0 && size_t(k) < m.nodes.size()) child[size_t(k)] = true;
    for (size_t i = 0; i < m.nodes.size(); ++i)
      if (!child[i]) roots.push_back(int(i));
    roots_where = "/nodes";
    if (!m.nodes.empty()) c.warn("/scenes", "the file has no scenes: every root node is rendered");
  }
  std::vector<PlacedNode> out;
  std::vector<bool> seen(m.nodes.size(), false);
  struct Item {
    int node;
    Mat4 parent;
    std::string where;
    int parent_index;
  };
  std::vector<Item> stack;
  for (size_t i = roots.size(); i-- > 0;)
    stack.push_back({roots[i], Mat4::identity(), ptr(roots_where, i), -1});
  while (!stack.empty()) {
    Item it = std::move(stack.back());
    stack.pop_back();
    if (it.node < 0 || size_t(it.node) >= m.nodes.size())
      c.fail(it.where, "node " + std::to_string(it.node) + " does not exist (the file has " +
                           std::to_string(m.nodes.size()) + ")");
    const size_t n = size_t(it.node);
    if (seen[n])
      c.fail(it.where, "node " + std::to_string(n) +
                           " is reached twice (a cycle, or a node with two parents)");
    seen[n] = true;
    Mat4 world = it.parent * node_matrix(c, n);
    if (!world.is_finite()) c.fail(ptr("/nodes", n), "the world transform is not finite");
    PlacedNode placed;
    placed.node = n, placed.to_world = world, placed.parent = it.parent_index;
    out.push_back(std::move(placed));
    const int index = int(out.size() - 1);
    const auto& ch = m.nodes[n].children;
    for (size_t k = ch.size(); k-- > 0;)
      stack.push_back({ch[k], world, ptr(ptr(ptr("/nodes", n), "children"), k), index});
  }
  return out;
}

// The motion of every placed node that an animation moves, itself or through an ancestor.
void animate_nodes(Context& c, const Animations& anim, std::vector<PlacedNode>& nodes) {
  if (c.model.animations.empty()) return;
  for (PlacedNode& pn : nodes) {
    std::vector<size_t> chain;  // root first
    bool moves = false;
    for (int i = int(&pn - nodes.data()); i >= 0; i = nodes[size_t(i)].parent) {
      chain.insert(chain.begin(), nodes[size_t(i)].node);
      moves |= anim.animates(nodes[size_t(i)].node);
    }
    if (!moves) continue;
    pn.motion = anim.world_motion(c, chain, ptr("/nodes", pn.node));
    pn.to_world = pn.motion.keys().front().m;  // a track that holds still: where it holds
  }
}

// --------------------------------------------------------------------------------------------
// Meshes.

// Triangles of a primitive by its mode (strips and fans converted), or empty for points/lines.
std::vector<uint32_t> triangles(Context& c, int mode, std::vector<uint32_t> idx,
                                const std::string& p) {
  std::vector<uint32_t> t;
  switch (mode) {
    case -1:
    case TINYGLTF_MODE_TRIANGLES:
      if (idx.size() % 3 != 0)
        c.fail(p, std::to_string(idx.size()) + " vertices/indices do not make whole triangles");
      return idx;
    case TINYGLTF_MODE_TRIANGLE_STRIP:
      for (size_t i = 0; i + 2 < idx.size(); ++i)  // every other triangle swaps its first two
        if (i % 2 == 0)
          t.insert(t.end(), {idx[i], idx[i + 1], idx[i + 2]});
        else
          t.insert(t.end(), {idx[i + 1], idx[i], idx[i + 2]});
      return t;
    case TINYGLTF_MODE_TRIANGLE_FAN:
      for (size_t i = 1; i + 1 < idx.size(); ++i) t.insert(t.end(), {idx[i], idx[i + 1], idx[0]});
      return t;
    case TINYGLTF_MODE_POINTS:
    case TINYGLTF_MODE_LINE:
    case TINYGLTF_MODE_LINE_LOOP:
    case TINYGLTF_MODE_LINE_STRIP:
      c.warn(ptr(p, "mode"), "points and lines are not rendered (primitive skipped)");
      return {};
    default:
      c.fail(ptr(p, "mode"), "unknown primitive mode " + std::to_string(mode));
  }
}

// The primitives of glTF mesh `index` (points and lines left out).
std::vector<Primitive> convert_mesh(Context& c, size_t index, const MaterialMap& mats) {
  const tinygltf::Mesh& gm = c.model.meshes[index];
  const std::string mp = ptr("/meshes", index);
  std::vector<Primitive> out;
  for (size_t k = 0; k < gm.primitives.size(); ++k) {
    const tinygltf::Primitive& pr = gm.primitives[k];
    const std::string p = ptr(ptr(mp, "primitives"), k);
    const std::string ap = ptr(p, "attributes");
    if (pr.targets.size() != gm.primitives[0].targets.size())
      c.fail(ptr(p, "targets"), std::to_string(pr.targets.size()) +
                                    " morph targets where primitive 0 has " +
                                    std::to_string(gm.primitives[0].targets.size()) +
                                    " (a mesh's primitives have the same targets)");
    if (pr.extensions.count("KHR_draco_mesh_compression"))
      c.warn(ptr(ptr(p, "extensions"), "KHR_draco_mesh_compression"),
             "Draco compression is not supported: the uncompressed accessors are read");
    auto pos = pr.attributes.find("POSITION");
    if (pos == pr.attributes.end()) c.fail(ap, "POSITION is missing");
    MeshData d;
    std::vector<float> v = read_floats(c, pos->second, 3, ptr(ap, "POSITION"));
    for (size_t i = 0; i < v.size(); i += 3) d.positions.emplace_back(v[i], v[i + 1], v[i + 2]);
    const size_t n = d.positions.size();
    auto attr = [&](const char* name, int comps) -> std::vector<float> {
      auto it = pr.attributes.find(name);
      if (it == pr.attributes.end()) return {};
      std::vector<float> a = read_floats(c, it->second, comps, ptr(ap, name));
      if (a.size() != n * size_t(comps))
        c.fail(ptr(ap, name), "has " + std::to_string(a.size() / size_t(comps)) + " elements for " +
                                  std::to_string(n) + " positions");
      return a;
    };
    std::vector<float> normals = attr("NORMAL", 3);
    for (size_t i = 0; i < normals.size(); i += 3)
      d.normals.emplace_back(normals[i], normals[i + 1], normals[i + 2]);
    std::vector<float> uv = attr("TEXCOORD_0", 2);
    for (size_t i = 0; i < uv.size(); i += 2) d.uvs.push_back({uv[i], 1.0f - uv[i + 1]});  // v up
    if (pr.attributes.count("COLOR_0"))
      c.warn(ptr(ap, "COLOR_0"), "vertex colours are not supported (ignored)");
    Primitive prim;
    read_deformation(c, pr, n, p, prim);
    std::vector<uint32_t> idx;
    if (pr.indices != -1) {  // read_indices refuses other negative values
      idx = read_indices(c, pr.indices, n, ptr(p, "indices"));
    } else {
      idx.resize(n);
      for (size_t i = 0; i < n; ++i) idx[i] = uint32_t(i);
    }
    d.indices = triangles(c, pr.mode, std::move(idx), p);
    if (d.indices.empty()) continue;
    Mesh mesh;
    mesh.name =
        (gm.name.empty() ? mp : gm.name + " (" + mp + ")") + ", primitive " + std::to_string(k);
    if (pr.material != -1) {
      if (pr.material < 0 || size_t(pr.material) >= mats.material.size())
        c.fail(ptr(p, "material"), "material " + std::to_string(pr.material) +
                                       " does not exist (the file has " +
                                       std::to_string(mats.material.size()) + ")");
      mesh.material = mats.material[size_t(pr.material)];
      mesh.emission = mats.emission[size_t(pr.material)];
    } else {
      mesh.material = mats.default_material;
    }
    const Material& mat = c.scene->materials[mesh.material];
    if (d.uvs.empty() && mats.uses_texcoord &&
        (mat.reflectance.texture >= 0 || mat.specular.texture >= 0 || mat.roughness.texture >= 0))
      c.warn(ap, "the material is textured but the primitive has no TEXCOORD_0 (uv 0 everywhere)");
    prim.data = std::move(d), prim.mesh = std::move(mesh), prim.where = p;
    out.push_back(std::move(prim));
  }
  return out;
}

void place_meshes(Context& c, const Animations& anim, const std::vector<PlacedNode>& nodes,
                  const MaterialMap& mats) {
  const auto& m = c.model;
  std::map<size_t, std::vector<const PlacedNode*>> users;  // mesh -> the nodes placing it
  for (const PlacedNode& pn : nodes) {
    const tinygltf::Node& node = m.nodes[pn.node];
    if (node.mesh == -1) continue;
    if (node.mesh < 0 || size_t(node.mesh) >= m.meshes.size())
      c.fail(ptr(ptr("/nodes", pn.node), "mesh"), "mesh " + std::to_string(node.mesh) +
                                                      " does not exist (the file has " +
                                                      std::to_string(m.meshes.size()) + ")");
    if (std::fabs(pn.to_world.det3()) == 0) {
      c.warn(ptr("/nodes", pn.node), "singular transform (a zero scale): its mesh is not rendered");
      continue;
    }
    users[size_t(node.mesh)].push_back(&pn);
  }
  for (const auto& [mesh, placements] : users) {
    std::vector<Primitive> prims = convert_mesh(c, mesh, mats);
    if (prims.empty()) continue;
    // A skinned or morphed mesh: world meshes of each placement's own, deforming where its
    // weights or joints move (gltf_deform.cpp).
    const bool skinned =
        std::any_of(placements.begin(), placements.end(),
                    [&](const PlacedNode* pn) { return m.nodes[pn->node].skin != -1; });
    if (skinned || !prims[0].targets.empty()) {
      for (const PlacedNode* pn : placements) place_deforming(c, anim, nodes, *pn, prims);
      continue;
    }
    if (placements.size() == 1 && !placements[0]->motion.animated()) {  // straight into world
      for (Primitive& pr : prims) {
        place_mesh(std::move(pr.data), placements[0]->to_world, c.file, pr.where, pr.mesh);
        c.scene->meshes.push_back(std::move(pr.mesh));
      }
      continue;
    }
    SceneObject obj;  // placed by several nodes, or moving: an object and its instances
    obj.name = m.meshes[mesh].name.empty() ? ptr("/meshes", mesh) : m.meshes[mesh].name;
    for (Primitive& pr : prims) {
      place_mesh(std::move(pr.data), Mat4::identity(), c.file, pr.where, pr.mesh);
      obj.meshes.push_back(std::move(pr.mesh));
    }
    c.scene->objects.push_back(std::move(obj));
    for (const PlacedNode* pn : placements) {
      Instance inst(uint32_t(c.scene->objects.size() - 1), pn->to_world);
      if (pn->motion.animated()) inst.motion = pn->motion, inst.to_world = pn->motion.keys()[0].m;
      c.scene->instances.push_back(inst);
    }
  }
}

// --------------------------------------------------------------------------------------------
// Camera, lights, defaults.

void set_camera(Context& c, const std::vector<PlacedNode>& nodes) {
  const auto& m = c.model;
  const PlacedNode* chosen = nullptr;
  size_t others = 0;
  for (const PlacedNode& pn : nodes) {
    int cam = m.nodes[pn.node].camera;
    if (cam == -1) continue;
    if (cam < 0 || size_t(cam) >= m.cameras.size())
      c.fail(ptr(ptr("/nodes", pn.node), "camera"), "camera " + std::to_string(cam) +
                                                        " does not exist (the file has " +
                                                        std::to_string(m.cameras.size()) + ")");
    if (chosen)
      ++others;
    else
      chosen = &pn;
  }
  Scene& s = *c.scene;
  if (!chosen) return;  // the default camera is placed after the meshes (import_gltf)
  if (others)
    c.warn("/nodes", std::to_string(others) + " other camera node(s) ignored: the first, /nodes/" +
                         std::to_string(chosen->node) + ", is used");
  const size_t ci = size_t(m.nodes[chosen->node].camera);
  const tinygltf::Camera& cam = m.cameras[ci];
  const std::string cp = ptr("/cameras", ci);
  if (cam.type != "perspective")
    c.fail(ptr(cp, "type"), "camera type '" + cam.type + "' is not supported (only perspective)");
  const double yfov = cam.perspective.yfov, aspect = cam.perspective.aspectRatio;
  if (!(yfov > 0 && yfov < M_PI))
    c.fail(ptr(ptr(cp, "perspective"), "yfov"),
           "must be in (0, pi) radians, got " + format_number(yfov));
  if (aspect < 0 || !std::isfinite(aspect) || (aspect > 0 && (aspect < 1e-3 || aspect > 1e3)))
    c.fail(ptr(ptr(cp, "perspective"), "aspectRatio"),
           "must be in [0.001, 1000], got " + format_number(aspect));
  if (aspect > 0) {
    int shorter = std::max(1, int(std::lround(kLongerSide / (aspect >= 1 ? aspect : 1 / aspect))));
    s.film.width = aspect >= 1 ? kLongerSide : shorter;
    s.film.height = aspect >= 1 ? shorter : kLongerSide;
  } else {
    s.film.width = s.film.height = kLongerSide;
  }
  // Our fov spans the shorter axis: yfov itself for a landscape (or square) film, else the
  // horizontal angle 2 atan(tan(yfov / 2) * width / height).
  double fov =
      s.film.width >= s.film.height
          ? yfov
          : 2 * std::atan(std::tan(yfov / 2) * double(s.film.width) / double(s.film.height));
  s.camera.fov_deg = float(fov * 180 / M_PI);
  // The node's rotation and translation (a scale would change nothing in glTF's camera model).
  auto camera_of = [&](const Mat4& w) {
    Vec3 x(w.m[0][0], w.m[1][0], w.m[2][0]), y(w.m[0][1], w.m[1][1], w.m[2][1]),
        z(w.m[0][2], w.m[1][2], w.m[2][2]);
    if (!(length(z) > 0) || !(length(y) > 0) || w.det3() == 0)
      c.fail(ptr("/nodes", chosen->node), "the camera node's transform is singular");
    if (w.det3() < 0)
      c.fail(ptr("/nodes", chosen->node), "the camera node's transform mirrors (det < 0)");
    z = normalize(z);
    y = normalize(y - z * dot(y, z));
    x = cross(y, z);
    Mat4 cw;
    for (int r = 0; r < 3; ++r)
      cw.m[r][0] = x[r], cw.m[r][1] = y[r], cw.m[r][2] = z[r], cw.m[r][3] = w.m[r][3];
    return cw;
  };
  s.camera.camera_to_world = camera_of(chosen->to_world);
  if (chosen->motion.animated()) {  // an animated camera: its keys, made camera transforms
    std::vector<Keyframe> keys;
    for (const Keyframe& k : chosen->motion.keys()) keys.push_back({k.time, camera_of(k.m)});
    s.camera.motion = AnimatedTransform(keys);
    s.camera.camera_to_world = s.camera.motion.keys()[0].m;
  }
}

// A documented default when the scene has no camera: 40 degrees, looking down -z at the centre
// of the geometry's bounds from where the bounding sphere fills the view.
void default_camera(Context& c) {
  Scene& s = *c.scene;
  Vec3 lo(kInf), hi(-kInf);
  auto grow = [&](const Vec3& p) { lo = vmin(lo, p), hi = vmax(hi, p); };
  for (const Mesh& mesh : s.meshes)
    for (const Vec3& p : mesh.positions) grow(p);
  for (const Instance& in : s.instances)
    for (const Mesh& mesh : s.objects[in.object].meshes)
      for (const Vec3& p : mesh.positions) grow(in.to_world.point(p));
  if (!(lo.x <= hi.x)) c.fail("/", "the scene has no camera and no geometry: nothing to render");
  Vec3 centre = (lo + hi) * 0.5f;
  float radius = std::max(length(hi - lo) * 0.5f, 1e-3f);
  s.camera.fov_deg = 40;
  float dist = radius / std::sin(20.0f * kPi / 180.0f);
  s.camera.camera_to_world = Mat4::translate(centre + Vec3(0, 0, dist));
  s.film.width = s.film.height = kLongerSide;
  c.warn(
      "/cameras",
      "the scene has no camera: a default one (40 degree fov, looking down -z) frames the bounds");
}

void add_lights(Context& c, const std::vector<PlacedNode>& nodes) {
  const auto& m = c.model;
  for (const PlacedNode& pn : nodes) {
    const std::string np = ptr("/nodes", pn.node);
    const json* ext = c.extension(np, "KHR_lights_punctual");
    if (!ext) continue;
    const std::string ep = ptr(ptr(np, "extensions"), "KHR_lights_punctual");
    auto li = ext->find("light");
    if (li == ext->end() || !li->is_number_integer())
      c.fail(ptr(ep, "light"), "expected a light index");
    int64_t idx = li->get<int64_t>();
    if (idx < 0 || size_t(idx) >= m.lights.size())
      c.fail(ptr(ep, "light"), "light " + std::to_string(idx) + " does not exist (the file has " +
                                   std::to_string(m.lights.size()) + ")");
    const tinygltf::Light& gl = m.lights[size_t(idx)];
    const std::string lp = ptr("/extensions/KHR_lights_punctual/lights", size_t(idx));
    if (pn.motion.animated())
      c.warn(np,
             "moving lights are not supported: the light stays where the node's rest pose "
             "puts it");
    RGB colour(1.0f);
    if (!gl.color.empty()) {
      if (gl.color.size() != 3) c.fail(ptr(lp, "color"), "expected 3 numbers");
      colour = RGB(float(gl.color[0]), float(gl.color[1]), float(gl.color[2]));
      if (!(colour.x >= 0 && colour.y >= 0 && colour.z >= 0) || !is_finite(colour))
        c.fail(ptr(lp, "color"), "must be finite and >= 0");
    }
    if (!(gl.intensity >= 0) || !std::isfinite(gl.intensity))
      c.fail(ptr(lp, "intensity"), "must be finite and >= 0, got " + format_number(gl.intensity));
    if (gl.range > 0)
      c.warn(ptr(lp, "range"),
             "light range is ignored (the light falls off as 1/d^2 without a cutoff)");
    // Candela (lm/sr) and lux (lm/m^2) to W/sr and W/m^2 at 683 lm/W.
    RGB radiometric = colour * float(gl.intensity / kLumensPerWatt);
    Light l;
    l.name = gl.name.empty() ? lp : gl.name;
    l.position = pn.to_world.point(Vec3(0.0f));
    Vec3 dir = pn.to_world.vector(Vec3(0, 0, -1));  // glTF lights point down their local -z
    if (gl.type == "point") {
      l.type = LightType::Point;
      l.intensity = radiometric;
    } else if (gl.type == "spot" || gl.type == "directional") {
      if (!(length(dir) > 0) || !is_finite(dir))
        c.fail(np, "the light's direction is degenerate (zero scale)");
      l.direction = normalize(dir);
      if (gl.type == "directional") {
        l.type = LightType::Directional;
        l.irradiance = radiometric;
      } else {
        l.type = LightType::Spot;
        l.intensity = radiometric;
        double outer = gl.spot.outerConeAngle, inner = gl.spot.innerConeAngle;
        if (!(outer > 0 && outer <= M_PI / 2))
          c.fail(ptr(ptr(lp, "spot"), "outerConeAngle"),
                 "must be in (0, pi/2], got " + format_number(outer));
        if (!(inner >= 0 && inner < outer))
          c.fail(ptr(ptr(lp, "spot"), "innerConeAngle"),
                 "must be in [0, outerConeAngle), got " + format_number(inner));
        l.cone_angle_deg = float(outer * 180 / M_PI);
        l.falloff_start_deg = float(inner * 180 / M_PI);
      }
    } else {
      c.fail(ptr(lp, "type"), "unknown light type '" + gl.type + "' (point, spot, directional)");
    }
    if (!is_black(l.type == LightType::Directional ? l.irradiance : l.intensity))
      c.scene->lights.push_back(l);
  }
}

}  // namespace

// --------------------------------------------------------------------------------------------
// Context helpers.

std::string ptr(const std::string& parent, const std::string& key) {
  std::string k;
  for (char ch : key) {
    if (ch == '~')
      k += "~0";
    else if (ch == '/')
      k += "~1";
    else
      k += ch;
  }
  return (parent == "/" ? "" : parent) + "/" + k;
}

std::string ptr(const std::string& parent, size_t index) {
  return ptr(parent, std::to_string(index));
}

void Context::fail(const std::string& where, const std::string& what) const {
  throw SceneError(file + ": " + where + ": " + what);
}

void Context::warn(const std::string& where, const std::string& what) const {
  std::string w = file + ": " + where + ": " + what;
  for (const std::string& e : scene->warnings)
    if (e == w) return;
  scene->warnings.push_back(std::move(w));
}

const json* Context::at(const std::string& pointer) const {
  const json* j = &root;
  size_t pos = 1;
  while (pos <= pointer.size() && pointer.size() > 1) {
    size_t end = pointer.find('/', pos);
    if (end == std::string::npos) end = pointer.size();
    std::string key;
    for (size_t i = pos; i < end; ++i) {
      if (pointer[i] == '~' && i + 1 < end) {
        key += pointer[i + 1] == '1' ? '/' : '~';
        ++i;
      } else {
        key += pointer[i];
      }
    }
    if (j->is_object()) {
      auto it = j->find(key);
      if (it == j->end()) return nullptr;
      j = &*it;
    } else if (j->is_array()) {
      if (key.empty() || key.find_first_not_of("0123456789") != std::string::npos || key.size() > 9)
        return nullptr;
      size_t i = std::stoul(key);
      if (i >= j->size()) return nullptr;
      j = &(*j)[i];
    } else {
      return nullptr;
    }
    pos = end + 1;
  }
  return j;
}

const json* Context::extension(const std::string& pointer, const std::string& name) const {
  const json* e = at(ptr(ptr(pointer, "extensions"), name));
  if (e && !e->is_object()) fail(ptr(ptr(pointer, "extensions"), name), "expected an object");
  return e;
}

}  // namespace gltf

void import_gltf(const std::string& bytes, SceneFiles& files, Scene& scene) {
  const std::string& path = scene.path;
  gltf::Context c;
  c.file = path;
  c.files = &files;
  c.scene = &scene;
  const bool binary = bytes.size() >= 4 && bytes.compare(0, 4, "glTF") == 0;
  if (!binary && path.size() >= 4 && path.compare(path.size() - 4, 4, ".glb") == 0)
    c.fail("(GLB header)", "not a binary glTF (the file does not start with 'glTF')");
  gltf::load_model(c, bytes, binary);
  gltf::check_asset_and_extensions(c);
  gltf::MaterialMap mats = gltf::convert_materials(c);
  std::vector<gltf::PlacedNode> nodes = gltf::walk_nodes(c);
  const gltf::Animations anim(c);
  gltf::animate_nodes(c, anim, nodes);
  gltf::place_meshes(c, anim, nodes, mats);
  gltf::add_lights(c, nodes);
  gltf::set_camera(c, nodes);
  bool has_camera = false;
  for (const auto& pn : nodes) has_camera |= c.model.nodes[pn.node].camera >= 0;
  if (!has_camera) gltf::default_camera(c);
  bool emits = !scene.lights.empty();
  for (const Mesh& m : scene.meshes) emits |= m.emission.has_value();
  for (const SceneObject& o : scene.objects)
    for (const Mesh& m : o.meshes) emits |= m.emission.has_value();
  if (!emits) {  // glTF viewers light such files with an environment; so do we, and say so
    scene.environment = Environment{};
    scene.environment->scale = RGB(gltf::kDefaultEnvironmentRadiance);
    c.warn("/",
           "the scene has no lights (no KHR_lights_punctual light, no emissive material): a "
           "uniform white environment of radiance 1 lights it");
  }
  scene.render.integrator.max_depth = gltf::kDefaultMaxDepth;
  scene.render.spp = gltf::kDefaultSpp;
  scene.render.passes = default_passes(scene.render.spp);
}

}  // namespace rf
