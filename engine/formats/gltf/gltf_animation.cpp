// glTF node animations (docs/formats/gltf.md, "Animations"): the channels of /animations that
// move nodes' translation, rotation and scale, evaluated as the spec says (LINEAR: lerp, and
// slerp for rotations; STEP: the key's value until the next; CUBICSPLINE: the cubic Hermite
// spline through the keys with their tangents), and a moved node's world transform over time as
// keyframes of an AnimatedTransform.
#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "engine/animated_transform.h"
#include "engine/formats/gltf/gltf_internal.h"
#include "engine/json_reader.h"

namespace rf::gltf {

Mat4 trs_matrix(const Vec3& t, const double q[4], const Vec3& s) {
  const double x = q[0], y = q[1], z = q[2], w = q[3];
  const double r[3][3] = {{1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)},
                          {2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)},
                          {2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)}};
  const float sv[3] = {s.x, s.y, s.z};
  Mat4 m;
  for (int row = 0; row < 3; ++row)
    for (int col = 0; col < 3; ++col) m.m[row][col] = float(r[row][col]) * sv[col];  // T R S
  m.m[0][3] = t.x, m.m[1][3] = t.y, m.m[2][3] = t.z;
  return m;
}

namespace {

enum class Path { Translation, Rotation, Scale, Weights };
enum class Interp { Linear, Step, CubicSpline };

struct Channel {
  Path path;
  Interp interp;
  std::vector<float> times;
  std::vector<float> values;  // comps per element; CUBICSPLINE: in-tangent, value, out-tangent
  int comps;
  std::string where;  // the channel's pointer
};

// Element i's value of a sampler's output (for CUBICSPLINE the key's value, not a tangent).
const float* key_value(const Channel& ch, size_t i, int part = 1) {
  const size_t per = ch.interp == Interp::CubicSpline ? 3 : 1;
  const size_t slot = ch.interp == Interp::CubicSpline ? per * i + size_t(part) : i;
  return &ch.values[slot * size_t(ch.comps)];
}

// The channel's value at time t, comps numbers (a rotation normalised: x, y, z, w).
std::vector<double> evaluate(const Channel& ch, double t) {
  const size_t n = ch.times.size();
  std::vector<double> out(size_t(ch.comps));
  auto set = [&](const float* v) {
    for (int c = 0; c < ch.comps; ++c) out[size_t(c)] = v[c];
  };
  if (n == 1 || t <= ch.times.front()) {
    set(key_value(ch, 0));
  } else if (t >= ch.times.back()) {
    set(key_value(ch, n - 1));
  } else {
    // Compared in double: t just below the last key (a STEP hold) may round up to it as a
    // float, which would put k on the last key and k + 1 past the end.
    const size_t k = size_t(std::upper_bound(ch.times.begin(), ch.times.end(), t,
                                             [](double v, float key) { return v < double(key); }) -
                            ch.times.begin()) -
                     1;
    const double t0 = ch.times[k], t1 = ch.times[k + 1], td = t1 - t0, u = (t - t0) / td;
    if (ch.interp == Interp::Step) {
      set(key_value(ch, k));
    } else if (ch.interp == Interp::CubicSpline) {
      const double u2 = u * u, u3 = u2 * u;
      const double h00 = 2 * u3 - 3 * u2 + 1, h10 = u3 - 2 * u2 + u, h01 = -2 * u3 + 3 * u2,
                   h11 = u3 - u2;
      const float *v0 = key_value(ch, k), *b0 = key_value(ch, k, 2), *v1 = key_value(ch, k + 1),
                  *a1 = key_value(ch, k + 1, 0);
      for (int c = 0; c < ch.comps; ++c)
        out[size_t(c)] = h00 * v0[c] + h10 * td * b0[c] + h01 * v1[c] + h11 * td * a1[c];
    } else if (ch.path == Path::Rotation) {
      const float *a = key_value(ch, k), *b = key_value(ch, k + 1);
      const Quaternion q = slerp(u, {a[3], a[0], a[1], a[2]}, {b[3], b[0], b[1], b[2]});
      out = {q.x, q.y, q.z, q.w};
    } else {
      const float *a = key_value(ch, k), *b = key_value(ch, k + 1);
      for (int c = 0; c < ch.comps; ++c) out[size_t(c)] = (1 - u) * a[c] + u * b[c];
    }
  }
  if (ch.path == Path::Rotation) {
    const double len =
        std::sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2] + out[3] * out[3]);
    if (len > 0)
      for (double& v : out) v /= len;
  }
  return out;
}

}  // namespace

struct Animations::Impl {
  std::map<size_t, std::map<Path, Channel>> nodes;  // node -> its animated paths
};

Animations::Animations(Context& c) : impl_(std::make_unique<Impl>()) {
  const auto& m = c.model;
  for (size_t a = 0; a < m.animations.size(); ++a) {
    const tinygltf::Animation& anim = m.animations[a];
    const std::string ap = ptr("/animations", a);
    for (size_t k = 0; k < anim.channels.size(); ++k) {
      const tinygltf::AnimationChannel& ch = anim.channels[k];
      const std::string cp = ptr(ptr(ap, "channels"), k);
      const std::string tp = ptr(cp, "target");
      if (ch.target_node < 0 || size_t(ch.target_node) >= m.nodes.size())
        c.fail(ptr(tp, "node"), "the channel's node " + std::to_string(ch.target_node) +
                                    " does not exist (the file has " +
                                    std::to_string(m.nodes.size()) + ")");
      if (ch.sampler < 0 || size_t(ch.sampler) >= anim.samplers.size())
        c.fail(ptr(cp, "sampler"), "sampler " + std::to_string(ch.sampler) +
                                       " does not exist (the animation has " +
                                       std::to_string(anim.samplers.size()) + ")");
      Channel out;
      const size_t node = size_t(ch.target_node);
      if (ch.target_path == "weights") {
        // As many weights per key as the node's mesh has morph targets.
        const tinygltf::Node& n = m.nodes[node];
        const size_t targets = n.mesh >= 0 && size_t(n.mesh) < m.meshes.size() &&
                                       !m.meshes[size_t(n.mesh)].primitives.empty()
                                   ? m.meshes[size_t(n.mesh)].primitives[0].targets.size()
                                   : 0;
        if (targets == 0)
          c.fail(ptr(tp, "node"), "the channel animates the morph weights of node " +
                                      std::to_string(node) + ", whose mesh has no morph targets");
        out.path = Path::Weights, out.comps = int(targets);
      } else if (ch.target_path == "translation")
        out.path = Path::Translation, out.comps = 3;
      else if (ch.target_path == "rotation")
        out.path = Path::Rotation, out.comps = 4;
      else if (ch.target_path == "scale")
        out.path = Path::Scale, out.comps = 3;
      else
        c.fail(ptr(tp, "path"), "unknown path '" + ch.target_path +
                                    "' (known: translation, rotation, scale, weights)");
      if (out.path != Path::Weights && !m.nodes[node].matrix.empty())
        c.fail(ptr(tp, "node"), "node " + std::to_string(node) +
                                    " has a 'matrix': an animated node must use translation, "
                                    "rotation and scale (glTF 2.0, 5.25)");
      const tinygltf::AnimationSampler& s = anim.samplers[size_t(ch.sampler)];
      const std::string sp = ptr(ptr(ap, "samplers"), size_t(ch.sampler));
      const std::string interp = s.interpolation.empty() ? "LINEAR" : s.interpolation;
      if (interp == "LINEAR")
        out.interp = Interp::Linear;
      else if (interp == "STEP")
        out.interp = Interp::Step;
      else if (interp == "CUBICSPLINE")
        out.interp = Interp::CubicSpline;
      else
        c.fail(ptr(sp, "interpolation"),
               "unknown interpolation '" + interp + "' (known: LINEAR, STEP, CUBICSPLINE)");
      out.times = read_floats(c, s.input, 1, ptr(sp, "input"));
      if (out.times.empty()) c.fail(ptr(sp, "input"), "no key times");
      for (size_t i = 0; i < out.times.size(); ++i)
        if (!std::isfinite(out.times[i]) || (i > 0 && !(out.times[i] > out.times[i - 1])))
          c.fail(ptr(sp, "input"), "key times must be finite and increasing: key " +
                                       std::to_string(i) + " is " + format_number(out.times[i]));
      // Weights are SCALAR accessors, targets per key (glTF 2.0, 3.11).
      out.values =
          read_floats(c, s.output, out.path == Path::Weights ? 1 : out.comps, ptr(sp, "output"));
      const size_t want =
          out.times.size() * (out.interp == Interp::CubicSpline ? 3 : 1) * size_t(out.comps);
      if (out.values.size() != want)
        c.fail(ptr(sp, "output"),
               std::to_string(out.values.size() / size_t(out.comps)) +
                   (out.path == Path::Weights ? " sets of " + std::to_string(out.comps) + " weights"
                                              : std::string()) +
                   " values for " + std::to_string(out.times.size()) + " key times (" + interp +
                   " needs " + std::to_string(want / size_t(out.comps)) + ")");
      for (float v : out.values)
        if (!std::isfinite(v)) c.fail(ptr(sp, "output"), "a value is not finite");
      out.where = cp;
      auto& paths = impl_->nodes[node];
      if (paths.count(out.path))
        c.warn(cp, "node " + std::to_string(node) + "'s " + ch.target_path +
                       " is animated by an earlier channel too: this one is used");
      paths[out.path] = std::move(out);
    }
  }
}

Animations::~Animations() = default;

bool Animations::animates(size_t node) const {
  auto it = impl_->nodes.find(node);
  if (it == impl_->nodes.end()) return false;
  for (const auto& entry : it->second)
    if (entry.first != Path::Weights) return true;
  return false;
}

bool Animations::animates_weights(size_t node) const {
  auto it = impl_->nodes.find(node);
  return it != impl_->nodes.end() && it->second.count(Path::Weights) != 0;
}

std::vector<double> Animations::key_times(const std::vector<size_t>& chain, bool weights) const {
  std::set<double> times;
  for (size_t node : chain) {
    auto it = impl_->nodes.find(node);
    if (it == impl_->nodes.end()) continue;
    for (const auto& [path, ch] : it->second) {
      if ((path == Path::Weights) != weights) continue;
      const size_t n = ch.times.size();
      for (size_t k = 0; k < n; ++k) {
        times.insert(ch.times[k]);
        if (k + 1 == n) break;
        const double t0 = ch.times[k], t1 = ch.times[k + 1];
        if (ch.interp == Interp::Step)  // the key's value held until just before the next
          times.insert(t1 - kStepHold * (t1 - t0));
        else if (ch.interp == Interp::CubicSpline)  // the curve sampled between keys
          for (int j = 1; j < kSplineSteps; ++j) times.insert(t0 + (t1 - t0) * j / kSplineSteps);
      }
    }
  }
  return {times.begin(), times.end()};
}

std::vector<double> Animations::weights_at(const Context& c, size_t node, size_t targets,
                                           double t) const {
  auto it = impl_->nodes.find(node);
  if (it != impl_->nodes.end()) {
    auto w = it->second.find(Path::Weights);
    if (w != it->second.end()) return evaluate(w->second, t);
  }
  // The node's weights, else its mesh's, else zeros (glTF 2.0, 3.7.2.2).
  const tinygltf::Node& n = c.model.nodes[node];
  std::vector<double> out(targets, 0.0);
  const std::vector<double>* given = &n.weights;
  if (given->empty() && n.mesh >= 0 && size_t(n.mesh) < c.model.meshes.size())
    given = &c.model.meshes[size_t(n.mesh)].weights;
  if (!given->empty() && given->size() != targets)
    c.fail(ptr("/nodes", node), std::to_string(given->size()) + " morph weights for " +
                                    std::to_string(targets) + " morph targets");
  for (size_t i = 0; i < given->size(); ++i) {
    if (!std::isfinite((*given)[i])) c.fail(ptr("/nodes", node), "a morph weight is not finite");
    out[i] = (*given)[i];
  }
  return out;
}

Mat4 Animations::local_at(const Context& c, size_t node, double t) const {
  const tinygltf::Node& n = c.model.nodes[node];
  if (n.matrix.size() == 16) {  // a still node given by its matrix (an animated one has TRS)
    Mat4 m;
    for (int col = 0; col < 4; ++col)
      for (int row = 0; row < 4; ++row) m.m[row][col] = float(n.matrix[size_t(col * 4 + row)]);
    return m;
  }
  Vec3 tr(0.0f), sc(1.0f);
  double q[4] = {0, 0, 0, 1};
  if (n.translation.size() == 3)
    tr = Vec3(float(n.translation[0]), float(n.translation[1]), float(n.translation[2]));
  if (n.scale.size() == 3) sc = Vec3(float(n.scale[0]), float(n.scale[1]), float(n.scale[2]));
  if (n.rotation.size() == 4) {
    const double len = std::sqrt(n.rotation[0] * n.rotation[0] + n.rotation[1] * n.rotation[1] +
                                 n.rotation[2] * n.rotation[2] + n.rotation[3] * n.rotation[3]);
    if (len > 0)
      for (int i = 0; i < 4; ++i) q[i] = n.rotation[size_t(i)] / len;
  }
  auto it = impl_->nodes.find(node);
  if (it != impl_->nodes.end())
    for (const auto& [path, ch] : it->second) {
      if (path == Path::Weights) continue;
      const std::vector<double> v = evaluate(ch, t);
      if (path == Path::Translation) tr = Vec3(float(v[0]), float(v[1]), float(v[2]));
      if (path == Path::Scale) sc = Vec3(float(v[0]), float(v[1]), float(v[2]));
      if (path == Path::Rotation)
        for (int i = 0; i < 4; ++i) q[i] = v[size_t(i)];
    }
  return trs_matrix(tr, q, sc);
}

AnimatedTransform Animations::world_motion(const Context& c, const std::vector<size_t>& chain,
                                           const std::string& where) const {
  std::vector<Keyframe> keys;
  for (double t : key_times(chain)) {
    Mat4 w;
    for (size_t node : chain) w = w * local_at(c, node, t);
    if (!w.is_finite()) c.fail(where, "the animated world transform is not finite");
    keys.push_back({t, w});
  }
  try {
    return AnimatedTransform(keys);
  } catch (const std::invalid_argument& e) {
    c.fail(where, std::string("its animation: ") + e.what());
  }
}

}  // namespace rf::gltf
