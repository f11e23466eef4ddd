// glTF skins and morph targets (docs/formats/gltf.md, "Skins and morph targets"): a primitive's
// vertices at time t are its base plus its morph targets' deltas times the node's weights at t,
// then, for a skinned node, the blend of its joints' matrices (each joint's world transform at t
// times its inverse bind matrix) weighted by WEIGHTS_0, else the node's world transform at t. The
// importer evaluates them at the key times that the weights and the moving nodes need and hands
// the engine a deforming world mesh (Mesh::deform), linear between those keys.
#include <algorithm>
#include <cmath>
#include <functional>
#include <set>

#include "engine/formats/gltf/gltf_internal.h"
#include "engine/formats/mesh_placement.h"
#include "engine/json_reader.h"

namespace rf::gltf {

void read_deformation(Context& c, const tinygltf::Primitive& pr, size_t n, const std::string& p,
                      Primitive& out) {
  auto vec3s = [&](int accessor, const std::string& where) {
    const std::vector<float> v = read_floats(c, accessor, 3, where);
    if (v.size() != 3 * n)
      c.fail(where, "has " + std::to_string(v.size() / 3) + " elements for " + std::to_string(n) +
                        " positions");
    std::vector<Vec3> o;
    o.reserve(n);
    for (size_t i = 0; i < v.size(); i += 3) o.emplace_back(v[i], v[i + 1], v[i + 2]);
    return o;
  };
  for (size_t t = 0; t < pr.targets.size(); ++t) {
    const std::string tp = ptr(ptr(p, "targets"), t);
    MorphTarget target;
    for (const auto& [name, accessor] : pr.targets[t]) {
      if (name == "POSITION")
        target.positions = vec3s(accessor, ptr(tp, name));
      else if (name == "NORMAL")
        target.normals = vec3s(accessor, ptr(tp, name));
      else
        c.warn(ptr(tp, name), "morph target attribute " + name + " is not supported (ignored)");
    }
    out.targets.push_back(std::move(target));
  }
  const std::string ap = ptr(p, "attributes");
  auto joints = pr.attributes.find("JOINTS_0");
  auto weights = pr.attributes.find("WEIGHTS_0");
  if ((joints == pr.attributes.end()) != (weights == pr.attributes.end()))
    c.fail(ap, "JOINTS_0 and WEIGHTS_0 go together");
  if (joints == pr.attributes.end()) return;
  if (pr.attributes.count("JOINTS_1"))
    c.warn(ptr(ap, "JOINTS_1"), "a fifth to eighth joint per vertex is not supported (ignored)");
  const std::vector<float> j = read_floats(c, joints->second, 4, ptr(ap, "JOINTS_0"));
  const std::vector<float> w = read_floats(c, weights->second, 4, ptr(ap, "WEIGHTS_0"));
  if (j.size() != 4 * n || w.size() != 4 * n)
    c.fail(ap, "JOINTS_0 and WEIGHTS_0 need one element per position (" + std::to_string(n) + ")");
  for (size_t v = 0; v < n; ++v) {
    std::array<uint32_t, 4> jv;
    std::array<float, 4> wv;
    for (size_t k = 0; k < 4; ++k) {
      const float jf = j[4 * v + k], wf = w[4 * v + k];
      if (!(jf >= 0) || jf != std::floor(jf) || jf > 65535)
        c.fail(ptr(ap, "JOINTS_0"), "vertex " + std::to_string(v) + ": joint " + format_number(jf) +
                                        " is not a joint index");
      if (!std::isfinite(wf) || wf < 0)
        c.fail(ptr(ap, "WEIGHTS_0"), "vertex " + std::to_string(v) + ": weight " +
                                         format_number(wf) + " is not a finite weight >= 0");
      jv[k] = uint32_t(jf), wv[k] = wf;
    }
    out.joints.push_back(jv);
    out.weights.push_back(wv);
  }
}

namespace {

// A skin's joint: the chain of nodes down to it (root first) and its inverse bind matrix.
struct Joint {
  std::vector<size_t> chain;
  Mat4 inverse_bind;
};

// The product of the chain's local transforms at time t: the last node's world transform.
Mat4 world_at(const Context& c, const Animations& anim, const std::vector<size_t>& chain,
              double t) {
  Mat4 w;
  for (size_t node : chain) w = w * anim.local_at(c, node, t);
  return w;
}

// The skin of node pn (checked: joints in the rendered scene, inverse bind matrices one per
// joint and finite).
std::vector<Joint> read_skin(const Context& c, const std::vector<PlacedNode>& nodes,
                             const PlacedNode& pn,
                             const std::function<std::vector<size_t>(size_t)>& chain_of) {
  const auto& m = c.model;
  const int index = m.nodes[pn.node].skin;
  const std::string np = ptr("/nodes", pn.node);
  if (index < 0 || size_t(index) >= m.skins.size())
    c.fail(ptr(np, "skin"), "skin " + std::to_string(index) + " does not exist (the file has " +
                                std::to_string(m.skins.size()) + ")");
  const tinygltf::Skin& skin = m.skins[size_t(index)];
  const std::string sp = ptr("/skins", size_t(index));
  if (skin.joints.empty()) c.fail(ptr(sp, "joints"), "a skin needs at least one joint");
  std::vector<int> placed(m.nodes.size(), -1);
  for (size_t i = 0; i < nodes.size(); ++i) placed[nodes[i].node] = int(i);
  std::vector<float> ibm;
  if (skin.inverseBindMatrices != -1) {
    ibm = read_floats(c, skin.inverseBindMatrices, 16, ptr(sp, "inverseBindMatrices"));
    if (ibm.size() != 16 * skin.joints.size())
      c.fail(ptr(sp, "inverseBindMatrices"), std::to_string(ibm.size() / 16) + " matrices for " +
                                                 std::to_string(skin.joints.size()) + " joints");
  }
  std::vector<Joint> joints;
  for (size_t k = 0; k < skin.joints.size(); ++k) {
    const int j = skin.joints[k];
    const std::string jp = ptr(ptr(sp, "joints"), k);
    if (j < 0 || size_t(j) >= m.nodes.size())
      c.fail(jp, "node " + std::to_string(j) + " does not exist (the file has " +
                     std::to_string(m.nodes.size()) + ")");
    if (placed[size_t(j)] < 0)
      c.fail(jp, "joint node " + std::to_string(j) + " is not in the rendered scene");
    Joint joint;
    joint.chain = chain_of(size_t(placed[size_t(j)]));
    if (!ibm.empty()) {
      for (int col = 0; col < 4; ++col)
        for (int row = 0; row < 4; ++row)
          joint.inverse_bind.m[row][col] = ibm[16 * k + size_t(col * 4 + row)];
      if (!joint.inverse_bind.is_finite())
        c.fail(ptr(sp, "inverseBindMatrices"), "matrix " + std::to_string(k) + " is not finite");
    }
    joints.push_back(std::move(joint));
  }
  return joints;
}

}  // namespace

void place_deforming(Context& c, const Animations& anim, const std::vector<PlacedNode>& nodes,
                     const PlacedNode& pn, const std::vector<Primitive>& prims) {
  const auto& m = c.model;
  const std::string np = ptr("/nodes", pn.node);
  auto chain_of = [&](size_t placed) {
    std::vector<size_t> chain;  // root first
    for (int i = int(placed); i >= 0; i = nodes[size_t(i)].parent)
      chain.insert(chain.begin(), nodes[size_t(i)].node);
    return chain;
  };
  const std::vector<size_t> own = chain_of(size_t(&pn - nodes.data()));
  const bool skinned = m.nodes[pn.node].skin != -1;
  const std::vector<Joint> joints =
      skinned ? read_skin(c, nodes, pn, chain_of) : std::vector<Joint>();
  for (const Primitive& pr : prims)
    for (size_t v = 0; skinned && v < pr.joints.size(); ++v)
      for (uint32_t j : pr.joints[v])
        if (j >= joints.size())
          c.fail(ptr(ptr(pr.where, "attributes"), "JOINTS_0"),
                 "vertex " + std::to_string(v) + ": joint index " + std::to_string(j) +
                     " is out of range (the skin has " + std::to_string(joints.size()) +
                     " joints)");
  if (skinned && std::any_of(prims.begin(), prims.end(),
                             [](const Primitive& pr) { return pr.joints.empty(); }))
    c.fail(np, "the node has a skin but its mesh has no JOINTS_0 / WEIGHTS_0");

  // The key times: the weights' keys, and the moving nodes' (the joints', or the node's own);
  // rotations are baked into the vertices, which move linearly between keys, so a moving node's
  // world track is sampled at linear_sample_times (its keys, and within a turning segment steps
  // that keep the chord within 1e-4 of the track's size).
  std::set<double> times;
  const std::vector<double> weight_times = anim.key_times({pn.node}, /*weights=*/true);
  times.insert(weight_times.begin(), weight_times.end());
  auto add_moving = [&](const std::vector<size_t>& chain) {
    if (anim.key_times(chain).empty()) return;  // nothing on the chain moves
    const std::vector<double> t = linear_sample_times(anim.world_motion(c, chain, np));
    times.insert(t.begin(), t.end());
  };
  if (skinned)
    for (const Joint& j : joints) add_moving(j.chain);
  else
    add_moving(own);
  if (times.empty()) times.insert(0.0);
  uint64_t vertices = 0;
  for (const Primitive& pr : prims) vertices += pr.data.positions.size();
  const uint64_t limit = c.files->limits().elements;
  if (vertices && times.size() > limit / vertices)
    c.fail(np, "its skinned or morphed mesh would take " + std::to_string(times.size()) +
                   " keys of " + std::to_string(vertices) +
                   " vertices, over the import limit elements (" + std::to_string(limit) + ")");

  const size_t targets = prims[0].targets.size();
  std::vector<std::vector<VertexKey>> keys(prims.size());
  for (double t : times) {
    const std::vector<double> w =
        targets ? anim.weights_at(c, pn.node, targets, t) : std::vector<double>();
    std::vector<Mat4> joint_matrix;
    for (const Joint& j : joints)
      joint_matrix.push_back(world_at(c, anim, j.chain, t) * j.inverse_bind);
    const Mat4 node_world = skinned ? Mat4() : world_at(c, anim, own, t);
    for (size_t k = 0; k < prims.size(); ++k) {
      const Primitive& pr = prims[k];
      VertexKey key;
      key.time = t;
      key.positions = pr.data.positions;
      key.normals = pr.data.normals;
      for (size_t i = 0; i < targets; ++i) {  // morph: the base plus weighted deltas
        const float wi = float(w[i]);
        if (wi == 0) continue;
        const MorphTarget& mt = pr.targets[i];
        for (size_t v = 0; v < mt.positions.size(); ++v) key.positions[v] += mt.positions[v] * wi;
        for (size_t v = 0; v < mt.normals.size() && v < key.normals.size(); ++v)
          key.normals[v] += mt.normals[v] * wi;
      }
      for (size_t v = 0; v < key.positions.size(); ++v) {
        Mat4 xf = node_world;
        if (skinned) {  // the joints' matrices blended by the vertex's weights
          xf = Mat4();
          for (int r = 0; r < 3; ++r)
            for (int col = 0; col < 4; ++col) xf.m[r][col] = 0;
          for (size_t a = 0; a < 4; ++a) {
            const float wa = pr.weights[v][a];
            if (wa == 0) continue;
            const Mat4& jm = joint_matrix[pr.joints[v][a]];
            for (int r = 0; r < 3; ++r)
              for (int col = 0; col < 4; ++col) xf.m[r][col] += wa * jm.m[r][col];
          }
        }
        key.positions[v] = xf.point(key.positions[v]);
        if (!is_finite(key.positions[v]))
          c.fail(np, "a skinned or morphed vertex is not finite at time " + format_number(t));
        if (v < key.normals.size()) {
          const Vec3 nv = xf.normal(key.normals[v]);
          const float len = length(nv);
          key.normals[v] = len > 0 && std::isfinite(len) ? nv / len : Vec3(0, 0, 1);
        }
      }
      keys[k].push_back(std::move(key));
    }
  }
  for (size_t k = 0; k < prims.size(); ++k) {
    const Primitive& pr = prims[k];
    std::vector<VertexKey>& ks = keys[k];
    MeshData first = pr.data;
    first.positions = ks.front().positions;
    first.normals = ks.front().normals;
    Mesh mesh = pr.mesh;
    place_mesh(std::move(first), Mat4::identity(), c.file, pr.where, mesh);
    const bool changes = std::any_of(ks.begin() + 1, ks.end(), [&](const VertexKey& key) {
      return key.positions != ks.front().positions || key.normals != ks.front().normals;
    });
    if (changes) {  // the first key is the mesh's own vertices (place_mesh may drop normals)
      for (VertexKey& key : ks)
        if (mesh.normals.empty()) key.normals.clear();
      ks.front().positions = mesh.positions, ks.front().normals = mesh.normals;
      mesh.deform = std::move(ks);
    }
    c.scene->meshes.push_back(std::move(mesh));
  }
}

}  // namespace rf::gltf
