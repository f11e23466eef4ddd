// What the glTF importer's files share (docs/formats/gltf.md): the loaded model, the scene being
// filled and the error helpers. Every message starts with the file and a JSON pointer
// ("/materials/3/pbrMetallicRoughness/metallicRoughnessTexture") and names the feature.
#pragma once

#include <tiny_gltf.h>

#include <array>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "engine/formats/scene_files.h"
#include "engine/mesh_io.h"
#include "engine/scene.h"

namespace rf::gltf {

using json = nlohmann::json;

// JSON pointer child: "/a" + "b" -> "/a/b" (RFC 6901 escaping of '~' and '/').
std::string ptr(const std::string& parent, const std::string& key);
std::string ptr(const std::string& parent, size_t index);

struct Context {
  std::string file;       // the scene file as given (messages)
  tinygltf::Model model;  // as tinygltf parsed it (indices unchecked: check before use)
  json root;              // the same JSON, for extension objects tinygltf keeps as Values
  SceneFiles* files = nullptr;
  Scene* scene = nullptr;
  std::map<int, std::string> data_uri_images;  // image index -> bytes of a data: URI image
  std::map<int, std::string> image_paths;      // image index -> file OpenImageIO reads

  [[noreturn]] void fail(const std::string& where, const std::string& what) const;
  void warn(const std::string& where, const std::string& what) const;
  // The JSON object at a pointer made of keys and indices, or nullptr.
  const json* at(const std::string& pointer) const;
  // The extension object `name` of the JSON object at `pointer`, or nullptr.
  const json* extension(const std::string& pointer, const std::string& name) const;
};

// The bytes of a buffer view, checked to lie inside its buffer (gltf_accessors.cpp).
struct ViewBytes {
  const unsigned char* data = nullptr;
  size_t size = 0, stride = 0;
};
ViewBytes view_bytes(const Context& c, int view, const std::string& where);

// Accessors (gltf_accessors.cpp). Every read checks the accessor, its buffer view and buffer
// bounds, the stride, the component type, and sparse substitutions before touching a byte.
// Values of an accessor as floats, `components` per element (normalized integers mapped to
// [0, 1] or [-1, 1] as the spec says); the accessor's type must have that many components.
std::vector<float> read_floats(const Context& c, int accessor, int components,
                               const std::string& where);
// Vertex indices (SCALAR, unsigned byte/short/int), each checked < vertex_count.
std::vector<uint32_t> read_indices(const Context& c, int accessor, size_t vertex_count,
                                   const std::string& where);

// Node animations (gltf_animation.cpp; docs/formats/gltf.md "Animations"). The matrix
// T R S of a translation, a unit quaternion (x, y, z, w) and a scale, as a node's TRS makes it.
Mat4 trs_matrix(const Vec3& t, const double q[4], const Vec3& s);
// Every channel of /animations that moves a node's translation, rotation or scale, checked (a
// channel on a missing node, a missing sampler, key times out of order, a wrong number of
// values, a node with a 'matrix' are errors naming the pointer), and the channels of morph
// target weights (a node whose mesh has no morph targets is an error); all animations play
// together from time 0 (seconds).
class Animations {
 public:
  explicit Animations(Context& c);
  ~Animations();
  // Whether a channel moves the node (translation, rotation, scale) / sets its morph weights.
  bool animates(size_t node) const;
  bool animates_weights(size_t node) const;
  // The times at which a chain of nodes (root first) is sampled: every key of their transform
  // channels (with `weights`: of their weight channels instead), plus for STEP a key just before
  // each next one (kStepHold of the gap before it) holding the value, and for CUBICSPLINE
  // kSplineSteps steps per segment (the AnimatedTransform interpolates the rest: exactly for
  // LINEAR keys of one node under similarity parents).
  std::vector<double> key_times(const std::vector<size_t>& chain, bool weights = false) const;
  // Node `node`'s morph weights at time t (`targets` of them): its channel's, else the node's
  // own, else its mesh's, else zeros.
  std::vector<double> weights_at(const Context& c, size_t node, size_t targets, double t) const;
  // A node's local transform at time t: its own TRS with the animated paths evaluated (a still
  // node's matrix if it has one).
  Mat4 local_at(const Context& c, size_t node, double t) const;
  // The world transform over time of the last node of `chain` (root first); a track that does
  // not move collapses to one key (AnimatedTransform). `where` names it in errors.
  AnimatedTransform world_motion(const Context& c, const std::vector<size_t>& chain,
                                 const std::string& where) const;
  static constexpr double kStepHold = 1e-6;
  static constexpr int kSplineSteps = 8;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// A node of the rendered scene (gltf_scene.cpp's walk_nodes, depth first).
struct PlacedNode {
  size_t node;
  Mat4 to_world;
  int parent = -1;           // the parent's index among the placed nodes, -1 for a root
  AnimatedTransform motion;  // world over time where an animation moves it or an ancestor
};

// A primitive's geometry in its mesh's space and the engine Mesh it becomes once placed, with
// what deforms it: morph targets (deltas per vertex) and a skin's joints and weights.
struct MorphTarget {
  std::vector<Vec3> positions, normals;  // per vertex, each empty when the target lacks it
};
struct Primitive {
  MeshData data;
  Mesh mesh;  // name, material, emission
  std::string where;
  std::vector<MorphTarget> targets;
  std::vector<std::array<uint32_t, 4>> joints;  // JOINTS_0: indices into the skin's joints
  std::vector<std::array<float, 4>> weights;    // WEIGHTS_0
};

// Skins and morph targets (gltf_deform.cpp; docs/formats/gltf.md "Skins and morph targets").
// Reads a primitive's morph targets and JOINTS_0 / WEIGHTS_0 (n vertices; `where` its pointer).
void read_deformation(Context& c, const tinygltf::Primitive& pr, size_t n, const std::string& where,
                      Primitive& out);
// Places node pn's skinned or morphed mesh as world meshes of its own: its vertices evaluated
// (morph weights, then the skin's joints, or else the node's world transform) at every key time
// of its weights and of the joints (or the node) that move it, deforming between them (a mesh
// whose vertices never change is still).
void place_deforming(Context& c, const Animations& anim, const std::vector<PlacedNode>& nodes,
                     const PlacedNode& pn, const std::vector<Primitive>& prims);

// Materials and textures (gltf_materials.cpp): fills scene.materials (one per glTF material, plus
// the spec's default material at the end when a primitive has none), scene.textures and the
// emission of each material (nullopt when black).
struct MaterialMap {
  std::vector<uint32_t> material;                 // glTF material -> Scene::materials index
  std::vector<std::optional<Emission>> emission;  // glTF material -> its area-light emission
  uint32_t default_material = 0;
  bool uses_texcoord = false;  // some material reads a texture (meshes then need TEXCOORD_0)
};
MaterialMap convert_materials(Context& c);

// Embedded images (gltf_images.cpp): the file OpenImageIO reads for image `index` (external
// files are registered through SceneFiles; data: URI and bufferView images are extracted into
// the content-addressed cache directory).
std::string image_file(Context& c, int index, const std::string& where);
// The cache directory for extracted images: $XDG_CACHE_HOME/rayfarm/gltf-images, or
// ~/.cache/rayfarm/gltf-images, or $TMPDIR/rayfarm-gltf-images without a home.
std::string image_cache_dir();
// RFC 3986 percent-decoding of a relative URI ("my%20image.png" -> "my image.png").
std::string percent_decode(const std::string& uri);

}  // namespace rf::gltf
