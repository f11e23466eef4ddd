// The environment light: radiance arriving from infinitely far away, a lat-long (equirectangular)
// image or a constant.
//
// Mapping (scene.h's Environment): for a unit direction d in map space,
//   u = 0.5 + atan2(d.x, -d.z) / 2pi,  v = acos(d.y) / pi,  theta = pi v,  phi = 2pi (u - 0.5),
// texel (floor(u W), floor(v H)) with row 0 the image's top scanline; world = to_world * map.
//
// Lookup is NEAREST (as pbrt-v4's ImageInfiniteLight): the radiance is constant over each texel,
// exactly like the sampling density, so light samples carry no variance from the map within a
// texel and no region with radiance can have sampling density 0.
//
// Sampling (pbrt-v3 InfiniteAreaLight): a 2D piecewise-constant distribution in (u, v) with
// texel weights w = luminance(L) * (mean of sin(theta) over the texel's row); u, v are uniform
// inside the chosen texel, so the solid-angle density is
//   pdf(w) = pdf_uv(u, v) / (2 pi^2 sin(theta)),   0 where sin(theta) = 0.
// The row mean of sin(theta), (cos(theta_top) - cos(theta_bottom)) / dtheta, rather than its
// value at the row centre, makes 2 pi^2 * (integral of w) exactly the integral over the sphere of
// the nearest-lookup luminance, which is what power_integral() returns.
// A constant environment (no file) is sampled uniformly over the sphere, pdf 1 / 4pi.
//
// Images: OpenImageIO, read as float. 1 or 2 channels are grey; otherwise the first three are
// RGB. Integer-stored images not tagged "Linear" are sRGB-decoded (the texture rule); float/half
// images are used as they are. Each texel is multiplied by `scale`; negative and non-finite
// values become 0.
#pragma once

#include <string>
#include <vector>

#include "engine/distribution.h"
#include "engine/math.h"
#include "engine/scene.h"

namespace rf {

class EnvironmentMap {
 public:
  // Loads the image now. Throws std::runtime_error naming the file when it cannot be read.
  explicit EnvironmentMap(const Environment& env);

  bool is_constant() const { return width_ == 0; }
  int width() const { return width_; }
  int height() const { return height_; }

  // Radiance arriving along -dir, i.e. seen when looking in world direction dir (unit).
  RGB radiance(Vec3 dir_world) const;
  // Solid-angle density of sample() producing dir_world (unit); no selection probability.
  float pdf(Vec3 dir_world) const;
  // Samples a world direction; radiance and pdf are evaluated from the returned direction by
  // radiance() and pdf(), so they agree with those exactly. False when the pdf is 0.
  bool sample(Vec2 u, Vec3& dir_world, RGB& radiance, float& pdf) const;
  // Integral over the sphere of the selection weight (luminance) of the radiance, in sr times
  // radiance units: 4 pi L for a constant, the exact sum over texels for a map.
  double power_integral() const { return power_integral_; }

  // The mapping above, in map space (exposed for tests).
  static Vec2 direction_to_uv(Vec3 d_map);
  static Vec3 uv_to_direction(Vec2 uv);

 private:
  void build(const Environment& env, RGB scale);  // the image's texels and distribution
  Vec3 to_map(Vec3 dir_world) const { return normalize(world_to_map_.vector(dir_world)); }
  const RGB& texel(Vec2 uv) const;

  RGB constant_{0.0f};
  Mat4 map_to_world_, world_to_map_;
  int width_ = 0, height_ = 0;
  std::vector<RGB> texels_;  // row-major, row 0 at the top (v = 0)
  Distribution2D distribution_;
  double power_integral_ = 0;
};

// Selection weight of a colour: its luminance, or for a colour of zero luminance that is not
// black, its largest component, so every light that emits something can be chosen.
inline float selection_weight(RGB c) {
  float lum = luminance(c);
  if (lum > 0) return lum;
  return std::max(0.0f, max_component(c));
}

}  // namespace rf
