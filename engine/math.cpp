#include "engine/math.h"

#include <stdexcept>

namespace rf {

Mat4 operator*(const Mat4& a, const Mat4& b) {
  Mat4 r;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      float s = 0;
      for (int k = 0; k < 4; ++k) s += a.m[i][k] * b.m[k][j];
      r.m[i][j] = s;
    }
  return r;
}

Mat4 Mat4::rotate(Vec3 axis, float angle_deg) {
  Vec3 a = normalize(axis);
  float th = angle_deg * kPi / 180.0f;
  float s = std::sin(th), c = std::cos(th);
  Mat4 r;
  r.m[0][0] = a.x * a.x + (1 - a.x * a.x) * c;
  r.m[0][1] = a.x * a.y * (1 - c) - a.z * s;
  r.m[0][2] = a.x * a.z * (1 - c) + a.y * s;
  r.m[1][0] = a.x * a.y * (1 - c) + a.z * s;
  r.m[1][1] = a.y * a.y + (1 - a.y * a.y) * c;
  r.m[1][2] = a.y * a.z * (1 - c) - a.x * s;
  r.m[2][0] = a.x * a.z * (1 - c) - a.y * s;
  r.m[2][1] = a.y * a.z * (1 - c) + a.x * s;
  r.m[2][2] = a.z * a.z + (1 - a.z * a.z) * c;
  return r;
}

Mat4 Mat4::look_at(Vec3 eye, Vec3 target, Vec3 up) {
  Vec3 fwd = normalize(target - eye);
  Vec3 right = cross(fwd, up);
  if (length(right) < 1e-6f)
    throw std::domain_error("look_at: up is parallel to the view direction");
  right = normalize(right);
  Vec3 cam_up = cross(right, fwd);
  Mat4 r;
  // Columns: camera +x = right, +y = up, +z = -forward; translation = eye.
  Vec3 cols[4] = {right, cam_up, -fwd, eye};
  for (int c = 0; c < 4; ++c)
    for (int i = 0; i < 3; ++i) r.m[i][c] = cols[c][i];
  return r;
}

float Mat4::det3() const {
  return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
         m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
         m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

Vec3 Mat4::normal(Vec3 n) const {
  // Inverse transpose of the linear part equals the cofactor matrix divided by the determinant;
  // the scale does not matter for a normal, the sign does (mirroring transforms).
  float c[3][3];
  c[0][0] = m[1][1] * m[2][2] - m[1][2] * m[2][1];
  c[0][1] = m[1][2] * m[2][0] - m[1][0] * m[2][2];
  c[0][2] = m[1][0] * m[2][1] - m[1][1] * m[2][0];
  c[1][0] = m[0][2] * m[2][1] - m[0][1] * m[2][2];
  c[1][1] = m[0][0] * m[2][2] - m[0][2] * m[2][0];
  c[1][2] = m[0][1] * m[2][0] - m[0][0] * m[2][1];
  c[2][0] = m[0][1] * m[1][2] - m[0][2] * m[1][1];
  c[2][1] = m[0][2] * m[1][0] - m[0][0] * m[1][2];
  c[2][2] = m[0][0] * m[1][1] - m[0][1] * m[1][0];
  Vec3 r{c[0][0] * n.x + c[0][1] * n.y + c[0][2] * n.z,
         c[1][0] * n.x + c[1][1] * n.y + c[1][2] * n.z,
         c[2][0] * n.x + c[2][1] * n.y + c[2][2] * n.z};
  return det3() < 0 ? -r : r;
}

Mat4 Mat4::inverse() const {
  // Gauss-Jordan with partial pivoting, in double.
  double a[4][8];
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) {
      a[i][j] = m[i][j];
      a[i][j + 4] = (i == j) ? 1.0 : 0.0;
    }
  for (int col = 0; col < 4; ++col) {
    int piv = col;
    for (int r = col + 1; r < 4; ++r)
      if (std::fabs(a[r][col]) > std::fabs(a[piv][col])) piv = r;
    if (std::fabs(a[piv][col]) < 1e-12) throw std::domain_error("matrix is singular");
    if (piv != col)
      for (int j = 0; j < 8; ++j) std::swap(a[piv][j], a[col][j]);
    double inv = 1.0 / a[col][col];
    for (int j = 0; j < 8; ++j) a[col][j] *= inv;
    for (int r = 0; r < 4; ++r) {
      if (r == col) continue;
      double f = a[r][col];
      for (int j = 0; j < 8; ++j) a[r][j] -= f * a[col][j];
    }
  }
  Mat4 r;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) r.m[i][j] = static_cast<float>(a[i][j + 4]);
  return r;
}

bool Mat4::is_finite() const {
  for (auto& row : m)
    for (float v : row)
      if (!std::isfinite(v)) return false;
  return true;
}

}  // namespace rf
