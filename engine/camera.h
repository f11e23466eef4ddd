// Perspective pinhole camera. The field of view spans the shorter image axis (as pbrt), so a
// square film and a wide film share the same vertical (or horizontal) framing.
#pragma once

#include <cmath>

#include "engine/accel.h"
#include "engine/scene.h"

namespace rf {

class PinholeCamera {
 public:
  PinholeCamera(const Camera& c, int width, int height)
      : to_world_(c.camera_to_world), width_(width), height_(height) {
    float t = std::tan(0.5f * c.fov_deg * kPi / 180.0f);
    float shorter = float(std::min(width, height));
    half_w_ = t * float(width) / shorter;
    half_h_ = t * float(height) / shorter;
    origin_ = to_world_.point(Vec3(0.0f));
  }

  // Ray through raster position (x, y) in pixels, (0, 0) the top-left corner of the film.
  Ray generate_ray(float x, float y) const {
    Vec3 d_cam{(2.0f * x / float(width_) - 1.0f) * half_w_, (1.0f - 2.0f * y / float(height_)) * half_h_,
               -1.0f};
    return {origin_, normalize(to_world_.vector(d_cam)), kInf};
  }

 private:
  Mat4 to_world_;
  int width_, height_;
  float half_w_, half_h_;
  Vec3 origin_;
};

}  // namespace rf
