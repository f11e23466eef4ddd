#include "engine/envmap.h"

#include <OpenImageIO/imageio.h>

#include <cmath>
#include <stdexcept>

#include "engine/sampling.h"

namespace rf {

namespace {

// IEC 61966-2-1 piecewise sRGB decode on [0, 1].
float srgb_decode(float e) {
  return e <= 0.04045f ? e / 12.92f : std::pow((e + 0.055f) / 1.055f, 2.4f);
}

float clean(float x) { return std::isfinite(x) && x > 0 ? x : 0.0f; }

// Reads the image as float RGB, row 0 at the top. Throws naming the file.
std::vector<RGB> read_rgb(const Environment& env, int& width, int& height) {
  const std::string path = env.resolved_path.empty() ? env.file : env.resolved_path;
  const std::string name = "environment map '" + env.file + "' (" + path + ")";
  auto in = OIIO::ImageInput::open(path);
  if (!in) throw std::runtime_error(name + ": cannot open: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  width = spec.width;
  height = spec.height;
  int nc = spec.nchannels;
  if (width <= 0 || height <= 0 || nc <= 0)
    throw std::runtime_error(name + ": image has no pixels or no channels");
  // A small file can declare a huge image (a decompression bomb): name it and the size asked for.
  const uint64_t pixels = uint64_t(width) * uint64_t(height);
  const uint64_t bytes = pixels * (uint64_t(nc) * 4 + 12 + 8);  // decoded, texels, sampling CDF
  if (pixels > (uint64_t(1) << 28))
    throw std::runtime_error(name + ": " + std::to_string(width) + "x" + std::to_string(height) +
                             " is over the limit of 268435456 pixels (16384x16384)");
  std::vector<float> buf;
  try {
    buf.resize(size_t(pixels) * size_t(nc));
  } catch (const std::bad_alloc&) {
    throw std::runtime_error(name + ": cannot allocate " + std::to_string(bytes >> 20) +
                             " MiB for its " + std::to_string(width) + "x" +
                             std::to_string(height) + " pixels");
  }
  if (!in->read_image(0, 0, 0, nc, OIIO::TypeDesc::FLOAT, buf.data()))
    throw std::runtime_error(name + ": cannot read: " + in->geterror());
  bool is_integer = !spec.format.is_floating_point();
  std::string colour_space = spec.get_string_attribute("oiio:ColorSpace");
  bool decode = is_integer && colour_space != "Linear" && colour_space != "linear";
  std::vector<RGB> texels(size_t(width) * size_t(height));
  for (size_t i = 0; i < texels.size(); ++i) {
    const float* px = &buf[i * size_t(nc)];
    RGB c = nc >= 3 ? RGB(px[0], px[1], px[2]) : RGB(px[0]);
    if (decode) c = RGB(srgb_decode(c.x), srgb_decode(c.y), srgb_decode(c.z));
    texels[i] = c;
  }
  return texels;
}

}  // namespace

EnvironmentMap::EnvironmentMap(const Environment& env) : map_to_world_(env.to_world) {
  try {
    world_to_map_ = env.to_world.inverse();
  } catch (const std::domain_error&) {
    throw std::runtime_error("environment: to_world is singular");
  }
  RGB scale(clean(env.scale.x), clean(env.scale.y), clean(env.scale.z));
  if (env.file.empty()) {
    constant_ = scale;
    power_integral_ = 4.0 * double(kPi) * double(selection_weight(scale));
    return;
  }
  try {
    build(env, scale);
  } catch (const std::bad_alloc&) {
    // The decoded image, its texels and the sampling distribution: about 40 bytes a pixel.
    throw std::runtime_error(
        "environment map '" + env.file + "': out of memory building its " + std::to_string(width_) +
        "x" + std::to_string(height_) + " pixels (about " +
        std::to_string((uint64_t(width_) * uint64_t(height_) * 40) >> 20) + " MiB)");
  }
}

void EnvironmentMap::build(const Environment& env, RGB scale) {
  texels_ = read_rgb(env, width_, height_);
  std::vector<float> weights(texels_.size());
  const double dtheta = double(kPi) / height_;
  for (int j = 0; j < height_; ++j) {
    // Mean of sin(theta) over the row: (cos(theta0) - cos(theta1)) / dtheta.
    double mean_sin = (std::cos(j * dtheta) - std::cos((j + 1) * dtheta)) / dtheta;
    for (int i = 0; i < width_; ++i) {
      RGB& c = texels_[size_t(j) * width_ + i];
      c = RGB(clean(c.x * scale.x), clean(c.y * scale.y), clean(c.z * scale.z));
      weights[size_t(j) * width_ + i] = float(selection_weight(c) * mean_sin);
    }
  }
  distribution_ = Distribution2D(weights, size_t(width_), size_t(height_));
  // Sum over texels of weight * solid angle = sum of w * (2pi / W) * (pi / H) = 2 pi^2 * mean(w).
  double sum = 0;
  for (float w : weights) sum += double(w);
  power_integral_ = 2.0 * double(kPi) * double(kPi) * sum / double(weights.size());
}

Vec2 EnvironmentMap::direction_to_uv(Vec3 d) {
  float u = 0.5f + std::atan2(d.x, -d.z) * (0.5f * kInvPi);
  if (u >= 1.0f) u -= 1.0f;  // atan2 = pi: the seam behind the viewer
  if (!(u >= 0.0f)) u = 0.0f;
  // theta = atan2(sin, cos) rather than acos(d.y): accurate near the poles, where d.y rounds to 1.
  float v = std::atan2(std::sqrt(d.x * d.x + d.z * d.z), d.y) * kInvPi;
  return {u, v};
}

Vec3 EnvironmentMap::uv_to_direction(Vec2 uv) {
  float theta = kPi * uv.y, phi = 2.0f * kPi * (uv.x - 0.5f);
  float sin_theta = std::sin(theta);
  return {sin_theta * std::sin(phi), std::cos(theta), -sin_theta * std::cos(phi)};
}

const RGB& EnvironmentMap::texel(Vec2 uv) const {
  int i = std::min(int(uv.x * float(width_)), width_ - 1);
  int j = std::min(int(uv.y * float(height_)), height_ - 1);
  return texels_[size_t(std::max(j, 0)) * width_ + size_t(std::max(i, 0))];
}

RGB EnvironmentMap::radiance(Vec3 dir_world) const {
  if (is_constant()) return constant_;
  return texel(direction_to_uv(to_map(dir_world)));
}

float EnvironmentMap::pdf(Vec3 dir_world) const {
  if (is_constant()) return power_integral_ > 0 ? 0.25f * kInvPi : 0.0f;
  Vec3 d = to_map(dir_world);
  float sin_theta = std::sqrt(d.x * d.x + d.z * d.z);  // not sqrt(1 - y^2): exact near the poles
  if (!(sin_theta > 0)) return 0.0f;
  Vec2 uv = direction_to_uv(d);
  return distribution_.pdf(uv.x, uv.y) / (2.0f * kPi * kPi * sin_theta);
}

bool EnvironmentMap::sample(Vec2 u, Vec3& dir_world, RGB& radiance_out, float& pdf_out) const {
  if (power_integral_ <= 0) return false;
  if (is_constant()) {
    dir_world = sample_uniform_sphere(u);
    radiance_out = constant_;
    pdf_out = 0.25f * kInvPi;
    return true;
  }
  Vec2 uv;
  float pdf_uv = 0;
  distribution_.sample(u.x, u.y, &uv.x, &uv.y, &pdf_uv);
  if (!(pdf_uv > 0)) return false;
  dir_world = normalize(map_to_world_.vector(uv_to_direction(uv)));
  // Evaluated from the direction, as pdf() and radiance() will for the same direction (MIS).
  pdf_out = pdf(dir_world);
  radiance_out = radiance(dir_world);
  return pdf_out > 0 && std::isfinite(pdf_out);
}

}  // namespace rf
