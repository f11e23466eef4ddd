#include "engine/formats/pbrt/pbrt_images.h"

#include <OpenImageIO/imageio.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "engine/digest.h"
#include "engine/json_reader.h"
#include "engine/scene_error.h"

namespace rf::pbrt {

namespace fs = std::filesystem;

std::string bake_image(const std::string& path, float scale, bool invert, bool data,
                       const std::string& what) {
  std::ifstream f(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << f.rdbuf();
  if (!f) throw SceneError(what + ": cannot read " + path);
  fs::path dir = fs::temp_directory_path() / "rayfarm-pbrt-textures";
  std::string key = sha256_hex(bytes.str() + "\n" + format_number(scale) +
                               (invert ? " invert" : "") + (data ? " data" : ""));
  fs::path out = dir / (key + ".exr");
  std::error_code ec;
  if (fs::exists(out, ec)) return out.string();

  auto in = OIIO::ImageInput::open(path);
  if (!in) throw SceneError(what + ": cannot open the image: " + OIIO::geterror());
  OIIO::ImageSpec spec = in->spec();
  const int w = spec.width, h = spec.height, nc = spec.nchannels;
  if (w <= 0 || h <= 0 || nc <= 0) throw SceneError(what + ": the image has no pixels");
  std::vector<float> px(size_t(w) * size_t(h) * size_t(nc));
  if (!in->read_image(0, 0, 0, nc, OIIO::TypeDesc::FLOAT, px.data()))
    throw SceneError(what + ": cannot read the image: " + in->geterror());
  std::string cs = spec.get_string_attribute("oiio:ColorSpace");
  const bool decode = !data && !spec.format.is_floating_point() && cs != "Linear" && cs != "linear";
  for (size_t i = 0; i < px.size(); ++i) {
    if (nc == 4 && i % 4 == 3) continue;  // alpha as it is
    float v = px[i];
    if (decode) v = v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
    v *= scale;
    px[i] = std::max(0.0f, invert ? 1.0f - v : v);
  }
  fs::create_directories(dir, ec);
  fs::path tmp = dir / (key + "." + std::to_string(::getpid()) + ".tmp.exr");
  auto o = OIIO::ImageOutput::create(tmp.string());
  OIIO::ImageSpec out_spec(w, h, nc, OIIO::TypeDesc::FLOAT);
  if (!o || !o->open(tmp.string(), out_spec) || !o->write_image(OIIO::TypeDesc::FLOAT, px.data()) ||
      !o->close())
    throw SceneError(what + ": cannot write the baked texture " + tmp.string() + ": " +
                     (o ? o->geterror() : OIIO::geterror()));
  fs::rename(tmp, out, ec);
  if (ec)
    throw SceneError(what + ": cannot write the baked texture " + out.string() + ": " +
                     ec.message());
  return out.string();
}

}  // namespace rf::pbrt
