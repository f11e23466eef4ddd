#include "engine/formats/pbrt/pbrt_envmap.h"

#include <OpenImageIO/imageio.h>

#include <unistd.h>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "engine/digest.h"
#include "engine/envmap.h"
#include "engine/scene_error.h"

namespace rf::pbrt {

namespace fs = std::filesystem;

Vec2 equal_area_square(Vec3 d) {
  // Clarberg's mapping of the sphere onto the octahedron unfolded into [-1, 1]^2.
  float x = std::fabs(d.x), y = std::fabs(d.y), z = std::fabs(d.z);
  float r = std::sqrt(std::max(0.0f, 1.0f - z));
  float a = std::max(x, y), b = std::min(x, y);
  b = a == 0 ? 0 : b / a;
  float phi = std::atan(b) * 2.0f / kPi;
  if (x < y) phi = 1 - phi;
  float v = phi * r, u = r - v;
  if (d.z < 0) {
    std::swap(u, v);
    u = 1 - u;
    v = 1 - v;
  }
  u = std::copysign(u, d.x);
  v = std::copysign(v, d.y);
  return {0.5f * (u + 1), 0.5f * (v + 1)};
}

namespace {

float srgb_decode(float e) {
  return e <= 0.04045f ? e / 12.92f : std::pow((e + 0.055f) / 1.055f, 2.4f);
}

std::vector<RGB> read_square(const std::string& path, const std::string& what, int& n) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) throw SceneError(what + ": cannot open the image: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  int w = spec.width, h = spec.height, nc = spec.nchannels;
  if (w <= 0 || h <= 0 || nc <= 0) throw SceneError(what + ": the image has no pixels");
  if (w != h)
    throw SceneError(
        what + ": pbrt-v4 image lights are equal-area octahedral maps and must be square, got " +
        std::to_string(w) + "x" + std::to_string(h));
  std::vector<float> buf(size_t(w) * size_t(h) * size_t(nc));
  if (!in->read_image(0, 0, 0, nc, OIIO::TypeDesc::FLOAT, buf.data()))
    throw SceneError(what + ": cannot read the image: " + in->geterror());
  bool decode = !spec.format.is_floating_point();
  std::vector<RGB> px(size_t(w) * size_t(h));
  for (size_t i = 0; i < px.size(); ++i) {
    const float* p = &buf[i * size_t(nc)];
    RGB c = nc >= 3 ? RGB(p[0], p[1], p[2]) : RGB(p[0]);
    if (decode) c = RGB(srgb_decode(c.x), srgb_decode(c.y), srgb_decode(c.z));
    px[i] = c;
  }
  n = w;
  return px;
}

}  // namespace

std::string octahedral_to_latlong(const std::string& path, const std::string& what) {
  std::ifstream f(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << f.rdbuf();
  if (!f) throw SceneError(what + ": cannot read " + path);
  fs::path dir = fs::temp_directory_path() / "rayfarm-pbrt-envmaps";
  fs::path out = dir / (sha256_hex(bytes.str()) + "-latlong.exr");
  std::error_code ec;
  if (fs::exists(out, ec)) return out.string();

  int n = 0;
  std::vector<RGB> square = read_square(path, what, n);
  const int width = 2 * n, height = n, kSub = 4;
  std::vector<float> latlong(size_t(width) * size_t(height) * 3);
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i) {
      RGB sum(0.0f);
      for (int sj = 0; sj < kSub; ++sj)
        for (int si = 0; si < kSub; ++si) {
          Vec2 uv{(i + (si + 0.5f) / kSub) / float(width),
                  (j + (sj + 0.5f) / kSub) / float(height)};
          Vec2 st = equal_area_square(EnvironmentMap::uv_to_direction(uv));
          int x = std::clamp(int(st.x * float(n)), 0, n - 1),
              y = std::clamp(int(st.y * float(n)), 0, n - 1);
          sum = sum + square[size_t(y) * size_t(n) + size_t(x)];
        }
      RGB c = sum / float(kSub * kSub);
      float* o = &latlong[(size_t(j) * size_t(width) + size_t(i)) * 3];
      o[0] = c.x, o[1] = c.y, o[2] = c.z;
    }

  fs::create_directories(dir, ec);
  // Written under a unique name and renamed, so a concurrent import never reads half a file.
  fs::path tmp = dir / (out.filename().string() + "." + std::to_string(::getpid()) + ".tmp.exr");
  auto o = OIIO::ImageOutput::create(tmp.string());
  OIIO::ImageSpec spec(width, height, 3, OIIO::TypeDesc::FLOAT);
  if (!o || !o->open(tmp.string(), spec) ||
      !o->write_image(OIIO::TypeDesc::FLOAT, latlong.data()) || !o->close())
    throw SceneError(what + ": cannot write the converted lat-long map " + tmp.string() + ": " +
                     (o ? o->geterror() : OIIO::geterror()));
  fs::rename(tmp, out, ec);
  if (ec)
    throw SceneError(what + ": cannot write the converted lat-long map " + out.string() + ": " +
                     ec.message());
  return out.string();
}

}  // namespace rf::pbrt
