// Transforms that move over time: keyframes interpolated as pbrt-v4's AnimatedTransform
// interpolates two (Shoemake and Duff 1992, "Matrix animation and polar decomposition"). Each
// key's matrix M (affine, invertible) is decomposed once into M = T R S: a translation T, a
// rotation R (a unit quaternion, from the polar decomposition of M's upper 3x3) and a symmetric
// scale-and-shear matrix S. Between two keys the translation and S are interpolated linearly and
// the rotation by slerp along the shorter arc, then composed again. Interpolating the matrices
// instead would shrink a rotating object (the mean of two rotation matrices is not a rotation).
//
// Times are plain numbers (the scene's time unit, seconds); before the first key the transform
// is the first key's, after the last the last's; at a key's time it is that key's matrix, bit for
// bit, so a track that does not move, or a frame whose shutter sits on a key, gives the matrix a
// static scene writes.
#pragma once

#include <string>
#include <vector>

#include "engine/math.h"

namespace rf {

// A rotation as a unit quaternion w + (x, y, z); double precision, so that the decomposition and
// slerp add no error a float matrix would see.
struct Quaternion {
  double w = 1, x = 0, y = 0, z = 0;
};
// The rotation matrix of unit quaternion q, row-major.
void quaternion_to_matrix(const Quaternion& q, double r[3][3]);
// The unit quaternion of rotation matrix r (orthonormal, determinant +1).
Quaternion matrix_to_quaternion(const double r[3][3]);
// Spherical linear interpolation from a (t = 0) to b (t = 1) along the shorter arc.
Quaternion slerp(double t, const Quaternion& a, Quaternion b);

// M = T R S.
struct DecomposedTransform {
  double t[3] = {0, 0, 0};
  Quaternion r;
  double s[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
};
// Throws std::domain_error when M's upper 3x3 is singular or not finite, or when its bottom row is
// not (0, 0, 0, 1) (a projective matrix has no such decomposition).
DecomposedTransform decompose(const Mat4& m);
Mat4 compose(const DecomposedTransform& d);
// The interpolation of a and b at t in [0, 1].
DecomposedTransform interpolate(double t, const DecomposedTransform& a,
                                const DecomposedTransform& b);

struct Keyframe {
  double time = 0;
  Mat4 m;
};

class AnimatedTransform {
 public:
  AnimatedTransform() = default;  // the identity, not moving
  explicit AnimatedTransform(const Mat4& m) : keys_{{0.0, m}}, parts_{decompose_or_keep(m)} {}
  // Keys in strictly increasing time, each matrix affine, finite and invertible; throws
  // std::invalid_argument naming the key (its index and time) otherwise. A track whose keys all
  // hold the same matrix collapses to that one static key (a key equal to its neighbour is kept:
  // it holds the transform still between them).
  explicit AnimatedTransform(std::vector<Keyframe> keys);

  // Whether the transform changes over time (more than one key after collapsing).
  bool animated() const { return keys_.size() > 1; }
  const std::vector<Keyframe>& keys() const { return keys_; }
  // The transform at `time`.
  Mat4 at(double time) const;
  // Whether, around `time`, the transform only translates and rotates: the key segment holding
  // `time` keeps its scale-and-shear part (or the track is held still there).
  bool rigid_at(double time) const;

 private:
  static DecomposedTransform decompose_or_keep(const Mat4& m);
  std::vector<Keyframe> keys_{{0.0, Mat4{}}};
  std::vector<DecomposedTransform> parts_{DecomposedTransform{}};
};

// The times at which to sample `motion` so that interpolating the sampled matrices linearly (what
// vertex keys of a moving emitter or a skinned mesh do) stays within `tolerance` of the track,
// relative to the matrices' size (their largest linear and translation entries): every key, and
// in a key segment that turns or scales, 2^k equal steps with k the smallest that keeps every
// step's midpoint within it, at most kMaxLinearSteps. A translation needs no steps; a quarter
// turn needs 128 for 1e-4 (the chord of a turn of angle a falls short of its arc by 1 - cos(a/2),
// so the area a turning emitter sweeps shrinks by about twice that).
inline constexpr int kMaxLinearSteps = 128;
std::vector<double> linear_sample_times(const AnimatedTransform& motion, double tolerance = 1e-4);

}  // namespace rf
