// Perspective camera: a pinhole, or a thin lens (aperture radius R, focus distance f) when R > 0.
//
// Geometry: camera space looks down -z with +y up; the image plane at z = -1 spans
// [-half_w, half_w] x [-half_h, half_h], the field of view across the shorter axis (as pbrt).
// Thin lens: a ray starts at a point of the lens disk (z = 0) and passes through the point of the
// plane z = -f that the pinhole ray of the same raster position reaches, so that plane is sharp
// and a point at depth z0 spreads into a disk of radius R |1/f - 1/z0| on the image plane.
//
// Importance (for light tracing and BDPT's t = 1 strategies; pbrt-v4 PerspectiveCamera::We):
// with A = 4 half_w half_h the image-plane area at unit distance and A_lens = pi R^2 (1 for a
// pinhole), W_e(p_lens, w) = 1 / (A A_lens cos^4 theta) for w inside the frustum, so that W_e
// integrates to 1 over the film; pdf_pos = 1 / A_lens and pdf_dir = 1 / (A cos^3 theta).
#pragma once

#include <cmath>

#include "engine/accel.h"
#include "engine/sampling.h"
#include "engine/scene.h"

namespace rf {

// A point on the lens seen from a scene point, for connecting a light vertex to the camera.
struct CameraConnection {
  Vec3 p_lens;             // world
  Vec3 wi;                 // unit, from the scene point towards the lens
  float distance = 0;
  float pdf_solid_angle = 0;  // of choosing p_lens, as seen from the scene point
  float importance = 0;       // W_e(p_lens, -wi)
  Vec2 raster;                // where the contribution lands on the film (pixels)
};

class PerspectiveCamera {
 public:
  PerspectiveCamera(const Camera& c, int width, int height)
      : to_world_(c.camera_to_world), to_camera_(c.camera_to_world.inverse()), width_(width),
        height_(height), lens_radius_(c.lens_radius), focus_distance_(c.focus_distance) {
    float t = std::tan(0.5f * c.fov_deg * kPi / 180.0f);
    float shorter = float(std::min(width, height));
    half_w_ = t * float(width) / shorter;
    half_h_ = t * float(height) / shorter;
    origin_ = to_world_.point(Vec3(0.0f));
    forward_ = normalize(to_world_.vector({0, 0, -1}));
    image_area_ = 4 * half_w_ * half_h_;
    lens_area_ = lens_radius_ > 0 ? kPi * lens_radius_ * lens_radius_ : 1.0f;
  }

  // Ray through raster position (x, y) in pixels ((0, 0) = top-left corner of the film), through
  // the lens point chosen by u_lens (ignored by a pinhole).
  Ray generate_ray(float x, float y, Vec2 u_lens) const {
    return generate_ray(x, y, u_lens, to_world_, origin_);
  }
  // The same ray from the camera placed by `camera_to_world` (a moving camera at a sample's
  // time); the bits generate_ray gives when that is the camera's own transform.
  Ray generate_ray(float x, float y, Vec2 u_lens, const Mat4& camera_to_world) const {
    return generate_ray(x, y, u_lens, camera_to_world, camera_to_world.point(Vec3(0.0f)));
  }

  // Raster position a world-space ray from a lens point reaches; false outside the film.
  bool raster_of(Vec3 p_lens_world, Vec3 dir_world, Vec2& raster) const {
    Vec3 o = to_camera_.point(p_lens_world), d = to_camera_.vector(dir_world);
    if (d.z >= 0) return false;
    // The pinhole ray through the same raster point meets the focus plane where this ray does.
    float f = lens_radius_ > 0 ? focus_distance_ : 1.0f;
    float t = (-f - o.z) / d.z;
    Vec3 q = o + d * t;
    float px = q.x / f, py = q.y / f;  // on the image plane z = -1
    raster = {(px / half_w_ + 1.0f) * 0.5f * float(width_), (1.0f - py / half_h_) * 0.5f * float(height_)};
    return raster.x >= 0 && raster.x < float(width_) && raster.y >= 0 && raster.y < float(height_);
  }

  // W_e of a ray leaving the lens at p_lens in direction dir (0 outside the film).
  float importance(Vec3 p_lens, Vec3 dir, Vec2* raster = nullptr) const {
    Vec2 r;
    if (!raster_of(p_lens, dir, r)) return 0.0f;
    if (raster) *raster = r;
    float cos_t = dot(normalize(dir), forward_);
    return 1.0f / (image_area_ * lens_area_ * cos_t * cos_t * cos_t * cos_t);
  }

  // Spatial and directional pdfs of generate_ray's rays (per unit lens area, per solid angle).
  void pdf_ray(Vec3 dir, float& pdf_pos, float& pdf_dir) const {
    float cos_t = dot(normalize(dir), forward_);
    pdf_pos = 1.0f / lens_area_;
    pdf_dir = cos_t > 0 ? 1.0f / (image_area_ * cos_t * cos_t * cos_t) : 0.0f;
  }

  // Chooses a lens point to connect scene point p to (pbrt-v4 SampleWi).
  bool connect(Vec3 p, Vec2 u_lens, CameraConnection& c) const {
    Vec2 l = lens_radius_ > 0 ? sample_concentric_disk(u_lens) : Vec2{0, 0};
    c.p_lens = to_world_.point({lens_radius_ * l.x, lens_radius_ * l.y, 0.0f});
    Vec3 d = c.p_lens - p;
    c.distance = length(d);
    if (!(c.distance > 0)) return false;
    c.wi = d / c.distance;
    float cos_lens = std::fabs(dot(forward_, c.wi));
    c.importance = importance(c.p_lens, -c.wi, &c.raster);
    if (c.importance <= 0 || cos_lens <= 0) return false;
    c.pdf_solid_angle = c.distance * c.distance / (cos_lens * lens_area_);
    return true;
  }

  // The same camera placed by `camera_to_world` instead (a moving camera at a light path's
  // time): its rays are the bits generate_ray(x, y, u_lens, camera_to_world) gives.
  PerspectiveCamera placed(const Mat4& camera_to_world) const {
    PerspectiveCamera c = *this;
    c.to_world_ = camera_to_world;
    c.to_camera_ = camera_to_world.inverse();
    c.origin_ = camera_to_world.point(Vec3(0.0f));
    c.forward_ = normalize(camera_to_world.vector({0, 0, -1}));
    return c;
  }

  Vec3 forward() const { return forward_; }
  float lens_radius() const { return lens_radius_; }

 private:
  Ray generate_ray(float x, float y, Vec2 u_lens, const Mat4& to_world, Vec3 origin) const {
    Vec3 d{(2.0f * x / float(width_) - 1.0f) * half_w_,
           (1.0f - 2.0f * y / float(height_)) * half_h_, -1.0f};
    if (lens_radius_ <= 0) return {origin, normalize(to_world.vector(d)), kInf};
    Vec2 l = sample_concentric_disk(u_lens);
    Vec3 o{lens_radius_ * l.x, lens_radius_ * l.y, 0.0f};
    Vec3 focus = d * focus_distance_;  // d.z = -1, so this lies on z = -f
    return {to_world.point(o), normalize(to_world.vector(focus - o)), kInf};
  }

  Mat4 to_world_, to_camera_;
  int width_, height_;
  float lens_radius_, focus_distance_;
  float half_w_, half_h_;
  Vec3 origin_, forward_;
  float image_area_, lens_area_;
};

}  // namespace rf
