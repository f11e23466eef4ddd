// Keyframed transforms: see animated_transform.h.
#include "engine/animated_transform.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

namespace rf {

namespace {
double det3(const double a[3][3]) {
  return a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) -
         a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
         a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0]);
}

// The inverse transpose of a (det != 0).
void inverse_transpose(const double a[3][3], double out[3][3]) {
  const double d = det3(a);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      // cofactor (i, j) / det: the inverse's (j, i) entry, i.e. the inverse transpose's (i, j).
      const int i1 = (i + 1) % 3, i2 = (i + 2) % 3, j1 = (j + 1) % 3, j2 = (j + 2) % 3;
      out[i][j] = (a[i1][j1] * a[i2][j2] - a[i1][j2] * a[i2][j1]) / d;
    }
}

std::string key_name(size_t i, double time) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "key %zu (time %.17g)", i, time);
  return buf;
}
}  // namespace

void quaternion_to_matrix(const Quaternion& q, double r[3][3]) {
  const double w = q.w, x = q.x, y = q.y, z = q.z;
  r[0][0] = 1 - 2 * (y * y + z * z), r[0][1] = 2 * (x * y - w * z), r[0][2] = 2 * (x * z + w * y);
  r[1][0] = 2 * (x * y + w * z), r[1][1] = 1 - 2 * (x * x + z * z), r[1][2] = 2 * (y * z - w * x);
  r[2][0] = 2 * (x * z - w * y), r[2][1] = 2 * (y * z + w * x), r[2][2] = 1 - 2 * (x * x + y * y);
}

// Shepperd's method: the largest of w, x, y, z from the trace and diagonal, the rest from the
// off-diagonal sums and differences (no cancellation in the pivot).
Quaternion matrix_to_quaternion(const double r[3][3]) {
  Quaternion q;
  const double trace = r[0][0] + r[1][1] + r[2][2];
  if (trace > 0) {
    const double s = 2 * std::sqrt(trace + 1);
    q.w = s / 4, q.x = (r[2][1] - r[1][2]) / s, q.y = (r[0][2] - r[2][0]) / s;
    q.z = (r[1][0] - r[0][1]) / s;
  } else if (r[0][0] > r[1][1] && r[0][0] > r[2][2]) {
    const double s = 2 * std::sqrt(1 + r[0][0] - r[1][1] - r[2][2]);
    q.w = (r[2][1] - r[1][2]) / s, q.x = s / 4, q.y = (r[0][1] + r[1][0]) / s;
    q.z = (r[0][2] + r[2][0]) / s;
  } else if (r[1][1] > r[2][2]) {
    const double s = 2 * std::sqrt(1 + r[1][1] - r[0][0] - r[2][2]);
    q.w = (r[0][2] - r[2][0]) / s, q.x = (r[0][1] + r[1][0]) / s, q.y = s / 4;
    q.z = (r[1][2] + r[2][1]) / s;
  } else {
    const double s = 2 * std::sqrt(1 + r[2][2] - r[0][0] - r[1][1]);
    q.w = (r[1][0] - r[0][1]) / s, q.x = (r[0][2] + r[2][0]) / s, q.y = (r[1][2] + r[2][1]) / s;
    q.z = s / 4;
  }
  const double n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  q.w /= n, q.x /= n, q.y /= n, q.z /= n;
  return q;
}

Quaternion slerp(double t, const Quaternion& a, Quaternion b) {
  double d = a.w * b.w + a.x * b.x + a.y * b.y + a.z * b.z;
  if (d < 0) d = -d, b = {-b.w, -b.x, -b.y, -b.z};  // q and -q are one rotation: the shorter arc
  double wa, wb;
  if (d > 0.9995) {  // nearly equal: linear, then normalised (slerp's weights lose precision)
    wa = 1 - t, wb = t;
  } else {
    const double theta = std::acos(d), s = std::sin(theta);
    wa = std::sin((1 - t) * theta) / s, wb = std::sin(t * theta) / s;
  }
  Quaternion q{wa * a.w + wb * b.w, wa * a.x + wb * b.x, wa * a.y + wb * b.y, wa * a.z + wb * b.z};
  const double n = std::sqrt(q.w * q.w + q.x * q.x + q.y * q.y + q.z * q.z);
  return {q.w / n, q.x / n, q.y / n, q.z / n};
}

DecomposedTransform decompose(const Mat4& m) {
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j)
      if (!std::isfinite(m.m[i][j])) throw std::domain_error("the matrix is not finite");
  if (m.m[3][0] != 0 || m.m[3][1] != 0 || m.m[3][2] != 0 || m.m[3][3] != 1)
    throw std::domain_error("the matrix is projective (its last row is not 0 0 0 1)");
  DecomposedTransform d;
  double a[3][3];
  for (int i = 0; i < 3; ++i) {
    d.t[i] = m.m[i][3];
    for (int j = 0; j < 3; ++j) a[i][j] = m.m[i][j];
  }
  const double det = det3(a);
  if (!(std::fabs(det) > 1e-30)) throw std::domain_error("the matrix is singular");
  // The polar decomposition A = R S: R the limit of R <- (R + R^-T) / 2 (Higham's iteration,
  // quadratic once close), S = R^T A. A reflection (det < 0) is taken as -R times -S, so that R
  // is a rotation a quaternion can hold.
  double r[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r[i][j] = a[i][j];
  for (int iteration = 0; iteration < 100; ++iteration) {
    double it[3][3], change = 0;
    inverse_transpose(r, it);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        const double next = 0.5 * (r[i][j] + it[i][j]);
        change = std::max(change, std::fabs(next - r[i][j]));
        r[i][j] = next;
      }
    if (change < 1e-15) break;
  }
  const double sign = det < 0 ? -1.0 : 1.0;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) r[i][j] *= sign;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double s = 0;
      for (int k = 0; k < 3; ++k) s += r[k][i] * a[k][j];  // R^T A
      d.s[i][j] = s;
    }
  d.r = matrix_to_quaternion(r);
  return d;
}

Mat4 compose(const DecomposedTransform& d) {
  double r[3][3];
  quaternion_to_matrix(d.r, r);
  Mat4 m;
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      double v = 0;
      for (int k = 0; k < 3; ++k) v += r[i][k] * d.s[k][j];
      m.m[i][j] = float(v);
    }
    m.m[i][3] = float(d.t[i]);
  }
  return m;
}

DecomposedTransform interpolate(double t, const DecomposedTransform& a,
                                const DecomposedTransform& b) {
  DecomposedTransform d;
  for (int i = 0; i < 3; ++i) {
    d.t[i] = (1 - t) * a.t[i] + t * b.t[i];
    for (int j = 0; j < 3; ++j) d.s[i][j] = (1 - t) * a.s[i][j] + t * b.s[i][j];
  }
  d.r = slerp(t, a.r, b.r);
  return d;
}

DecomposedTransform AnimatedTransform::decompose_or_keep(const Mat4& m) {
  try {
    return decompose(m);
  } catch (const std::domain_error&) {
    return DecomposedTransform{};  // a static key is only ever returned as its matrix
  }
}

AnimatedTransform::AnimatedTransform(std::vector<Keyframe> keys) {
  if (keys.empty()) throw std::invalid_argument("an animated transform needs at least one key");
  bool all_equal = true;
  for (size_t i = 0; i < keys.size(); ++i) {
    if (!std::isfinite(keys[i].time))
      throw std::invalid_argument(key_name(i, keys[i].time) + ": the time is not finite");
    if (i > 0 && !(keys[i].time > keys[i - 1].time))
      throw std::invalid_argument(key_name(i, keys[i].time) + ": times must increase, and " +
                                  key_name(i - 1, keys[i - 1].time) + " is not before it");
    if (i > 0)
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) all_equal &= keys[i].m.m[r][c] == keys[0].m.m[r][c];
  }
  if (all_equal) keys.resize(1);
  parts_.clear();
  for (size_t i = 0; i < keys.size(); ++i) {
    try {
      parts_.push_back(keys.size() == 1 ? decompose_or_keep(keys[i].m) : decompose(keys[i].m));
    } catch (const std::domain_error& e) {
      throw std::invalid_argument(key_name(i, keys[i].time) + ": " + e.what());
    }
  }
  keys_ = std::move(keys);
}

Mat4 AnimatedTransform::at(double time) const {
  if (keys_.size() == 1 || !(time > keys_.front().time)) return keys_.front().m;
  if (!(time < keys_.back().time)) return keys_.back().m;
  // keys_[i].time <= time < keys_[i + 1].time (a binary search: camera rays ask per ray).
  const size_t i = size_t(std::upper_bound(keys_.begin(), keys_.end(), time,
                                           [](double t, const Keyframe& k) { return t < k.time; }) -
                          keys_.begin()) -
                   1;
  if (time == keys_[i].time) return keys_[i].m;
  const double u = (time - keys_[i].time) / (keys_[i + 1].time - keys_[i].time);
  return compose(interpolate(u, parts_[i], parts_[i + 1]));
}

bool AnimatedTransform::rigid_at(double time) const {
  if (keys_.size() == 1 || !(time > keys_.front().time) || !(time < keys_.back().time)) return true;
  const size_t i = size_t(std::upper_bound(keys_.begin(), keys_.end(), time,
                                           [](double t, const Keyframe& k) { return t < k.time; }) -
                          keys_.begin()) -
                   1;
  // The polar decomposition's S of equal matrices agrees to rounding: 1e-6 of S's largest entry.
  const auto& a = parts_[i].s;
  const auto& b = parts_[i + 1].s;
  double largest = 0, diff = 0;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      largest = std::max(largest, std::fabs(a[r][c])),
      diff = std::max(diff, std::fabs(a[r][c] - b[r][c]));
  return diff <= 1e-6 * largest;
}

std::vector<double> linear_sample_times(const AnimatedTransform& motion, double tolerance) {
  const std::vector<Keyframe>& keys = motion.keys();
  std::vector<double> times;
  // The chord error at the midpoint of [t0, t1], relative to the midpoint matrix's size.
  auto chord_error = [&](double t0, double t1) {
    const Mat4 a = motion.at(t0), b = motion.at(t1), m = motion.at(0.5 * (t0 + t1));
    double size = 0, err = 0;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 4; ++c) {
        size = std::max(size, std::fabs(double(m.m[r][c])));
        err = std::max(err, std::fabs(0.5 * (double(a.m[r][c]) + double(b.m[r][c])) - m.m[r][c]));
      }
    return size > 0 ? err / size : err;
  };
  for (size_t k = 0; k < keys.size(); ++k) {
    times.push_back(keys[k].time);
    if (k + 1 == keys.size()) break;
    const double t0 = keys[k].time, t1 = keys[k + 1].time;
    int n = 1;
    for (; n < kMaxLinearSteps; n *= 2) {
      double worst = 0;
      for (int j = 0; j < n; ++j)
        worst = std::max(worst, chord_error(t0 + (t1 - t0) * j / n, t0 + (t1 - t0) * (j + 1) / n));
      if (worst <= tolerance) break;
    }
    for (int j = 1; j < n; ++j) times.push_back(t0 + (t1 - t0) * j / n);
  }
  return times;
}

}  // namespace rf
