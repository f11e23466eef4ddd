#include "engine/texture.h"

#include <OpenImageIO/imageio.h>
#include <OpenImageIO/strutil.h>
#include <OpenImageIO/texture.h>

#include <cassert>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <system_error>

namespace rf {

namespace {

OIIO::TextureSystem* as_ts(void* p) { return static_cast<OIIO::TextureSystem*>(p); }

SceneError texture_error(const Texture& t, const std::string& what) {
  return SceneError("texture '" + t.name + "' (" + t.file + "): " + what);
}

// Colour channels of an image with n channels: the first, or the first three.
int colour_channels(int n) { return n >= 3 ? 3 : 1; }

bool tagged_linear(const OIIO::ImageSpec& spec) {
  std::string cs = spec.get_string_attribute("oiio:ColorSpace");
  for (const char* name : {"linear", "scene_linear", "lin_srgb", "lin_rec709", "raw"})
    if (OIIO::Strutil::iequals(cs, name)) return true;
  return false;
}

// Box-filters rows of a w x h image (nch floats per pixel), streamed top to bottom, down to
// nw x nh: each output texel is the exact mean of the input area it covers (fractional edges for
// odd sizes), so every level has the same mean as the image. Coverage is computed in integers.
class BoxDownsampler {
 public:
  BoxDownsampler(int w, int h, int nw, int nh, int nch, std::function<void(const float*)> emit)
      : w_(w), h_(h), nw_(nw), nh_(nh), nch_(nch), emit_(std::move(emit)) {
    // Input texel x covers [x*nw, (x+1)*nw), output i covers [i*w, (i+1)*w) (units of 1/(w*nw)).
    for (int i = 0; i < nw; ++i) {
      long lo = long(i) * w, hi = long(i + 1) * w;
      for (long x = lo / nw; x < w && x * nw < hi; ++x) {
        long overlap = std::min(hi, (x + 1) * nw) - std::max(lo, x * nw);
        if (overlap > 0) taps_.push_back({i, int(x), float(double(overlap) / double(w))});
      }
    }
    hrow_.resize(size_t(nw) * nch);
    acc_.assign(2, std::vector<float>(size_t(nw) * nch, 0.0f));
  }

  void add_row(const float* row) {
    std::fill(hrow_.begin(), hrow_.end(), 0.0f);
    for (const Tap& t : taps_)
      for (int c = 0; c < nch_; ++c)
        hrow_[size_t(t.out) * nch_ + c] += t.weight * row[size_t(t.in) * nch_ + c];
    // Input row y covers [y*nh, (y+1)*nh), output row j covers [j*h, (j+1)*h).
    long lo = long(y_) * nh_, hi = long(y_ + 1) * nh_;
    for (int k = 0; k < 2 && j_ + k < nh_; ++k) {
      long jlo = long(j_ + k) * h_, jhi = long(j_ + k + 1) * h_;
      long overlap = std::min(hi, jhi) - std::max(lo, jlo);
      if (overlap <= 0) continue;
      float wgt = float(double(overlap) / double(h_));
      for (size_t i = 0; i < hrow_.size(); ++i) acc_[k][i] += wgt * hrow_[i];
    }
    ++y_;
    if (long(y_) * nh_ >= long(j_ + 1) * h_) {  // output row j_ is complete
      emit_(acc_[0].data());
      std::swap(acc_[0], acc_[1]);
      std::fill(acc_[1].begin(), acc_[1].end(), 0.0f);
      ++j_;
    }
  }

 private:
  struct Tap {
    int out, in;
    float weight;
  };
  int w_, h_, nw_, nh_, nch_;
  std::function<void(const float*)> emit_;
  std::vector<Tap> taps_;
  std::vector<float> hrow_;
  std::vector<std::vector<float>> acc_;
  int y_ = 0, j_ = 0;
};

// A scratch file of raw float rows, read back in order.
struct RowFile {
  std::string path;
  std::FILE* f = nullptr;
  RowFile(std::string p) : path(std::move(p)), f(std::fopen(path.c_str(), "w+b")) {}
  ~RowFile() {
    if (f) std::fclose(f);
    std::remove(path.c_str());
  }
};

// Reads rows [y0, y1) of an image's first level as float, in increasing order. Tiled files are
// read a row of tiles at a time (OIIO 2.4's read_scanlines faults on tiled files).
class RowReader {
 public:
  RowReader(const Texture& t, OIIO::ImageInput& in) : t_(t), in_(in), spec_(in.spec()) {
    if (spec_.tile_width > 0)
      tiles_.resize(size_t(spec_.width) * spec_.tile_height * spec_.nchannels);
  }
  void read(int y0, int y1, float* dst) {
    const int nch = spec_.nchannels;
    if (spec_.tile_width <= 0) {
      if (!in_.read_scanlines(0, 0, spec_.y + y0, spec_.y + y1, 0, 0, nch, OIIO::TypeDesc::FLOAT,
                              dst))
        throw error();
      return;
    }
    const size_t row = size_t(spec_.width) * nch;
    for (int y = y0; y < y1; ++y) {
      int tile_row = y / spec_.tile_height;
      if (tile_row != loaded_) {
        int ty0 = tile_row * spec_.tile_height;
        int ty1 = std::min(spec_.height, ty0 + spec_.tile_height);
        if (!in_.read_tiles(0, 0, spec_.x, spec_.x + spec_.width, spec_.y + ty0, spec_.y + ty1,
                            spec_.z, spec_.z + 1, 0, nch, OIIO::TypeDesc::FLOAT, tiles_.data()))
          throw error();
        loaded_ = tile_row;
      }
      const float* src = tiles_.data() + size_t(y - tile_row * spec_.tile_height) * row;
      std::copy(src, src + row, dst + size_t(y - y0) * row);
    }
  }

 private:
  SceneError error() { return texture_error(t_, "cannot read: " + in_.geterror()); }
  const Texture& t_;
  OIIO::ImageInput& in_;
  OIIO::ImageSpec spec_;
  std::vector<float> tiles_;
  int loaded_ = -1;
};

// Rewrites an image as a tiled (64x64), MIP-mapped OpenEXR with box-filtered levels down to 1x1,
// optionally sRGB-decoding its colour channels (alpha stays as it is). Streams 64 rows at a time:
// level l is read back from a scratch file of raw rows written while level l-1 was written, so
// memory stays a few strips whatever the image size.
void write_mipmapped(const Texture& t, OIIO::ImageInput& in, bool decode_srgb,
                     OIIO::TypeDesc format, const std::string& out_path) {
  const OIIO::ImageSpec spec = in.spec();
  const int nch = spec.nchannels, ncolour = colour_channels(nch);
  constexpr int kStrip = 64;
  auto out = OIIO::ImageOutput::create(out_path);
  if (!out || !out->supports("mipmap") || !out->supports("tiles"))
    throw texture_error(t, "cannot write texture cache file " + out_path);
  std::vector<float> strip(size_t(spec.width) * kStrip * nch);
  // Level 0 comes from the input, decoded; later levels from the previous level's scratch file.
  std::unique_ptr<RowFile> source, next;
  RowReader input(t, in);
  auto read_rows = [&](int w, int y0, int y1) {
    if (!source) {
      input.read(y0, y1, strip.data());
      if (!decode_srgb) return;
      for (size_t i = 0, n = size_t(w) * (y1 - y0); i < n; ++i)
        for (int c = 0; c < ncolour; ++c)
          if (c != spec.alpha_channel) strip[i * nch + c] = srgb_to_linear(strip[i * nch + c]);
      return;
    }
    size_t n = size_t(w) * (y1 - y0) * nch;
    if (std::fread(strip.data(), sizeof(float), n, source->f) != n)
      throw texture_error(t, "cannot read scratch file " + source->path);
  };
  int w = spec.width, h = spec.height;
  for (int level = 0;; ++level) {
    OIIO::ImageSpec ls(w, h, nch, format);
    ls.tile_width = ls.tile_height = kStrip;
    ls.channelnames = spec.channelnames;
    ls.alpha_channel = spec.alpha_channel;
    ls.attribute("compression", "none");
    ls.attribute("oiio:ColorSpace", "Linear");
    ls.attribute("textureformat", "Plain Texture");
    ls.attribute("openexr:levelmode", 1);     // Imf::MIPMAP_LEVELS
    ls.attribute("openexr:roundingmode", 0);  // Imf::ROUND_DOWN: level sizes max(1, n/2)
    auto mode = level == 0 ? OIIO::ImageOutput::Create : OIIO::ImageOutput::AppendMIPLevel;
    if (!out->open(out_path, ls, mode))
      throw texture_error(t, "cannot write texture cache file: " + out->geterror());
    bool last = w == 1 && h == 1;
    int nw = std::max(1, w / 2), nh = std::max(1, h / 2);  // OpenEXR's round-down level sizes
    std::unique_ptr<BoxDownsampler> down;
    if (!last) {
      next = std::make_unique<RowFile>(out_path + ".level" + std::to_string(level + 1));
      if (!next->f) throw texture_error(t, "cannot write scratch file " + next->path);
      std::FILE* f = next->f;
      down = std::make_unique<BoxDownsampler>(w, h, nw, nh, nch, [f, nw, nch](const float* row) {
        std::fwrite(row, sizeof(float), size_t(nw) * nch, f);
      });
    }
    for (int y = 0; y < h; y += kStrip) {
      int y1 = std::min(h, y + kStrip);
      read_rows(w, y, y1);
      if (!out->write_tiles(0, w, y, y1, 0, 1, OIIO::TypeDesc::FLOAT, strip.data()))
        throw texture_error(t, "cannot write texture cache file: " + out->geterror());
      if (down)
        for (int r = 0; r < y1 - y; ++r) down->add_row(strip.data() + size_t(r) * w * nch);
    }
    if (last) break;
    if (std::fflush(next->f) != 0 || std::ferror(next->f))
      throw texture_error(t, "cannot write scratch file " + next->path);
    std::rewind(next->f);
    source = std::move(next);
    w = nw, h = nh;
  }
  if (!out->close()) throw texture_error(t, "cannot write texture cache file: " + out->geterror());
}

// Integral of the odd-cell indicator s(x) = floor(x) mod 2 from 0 to x.
double odd_cells_integral(double x) {
  double h = std::floor(0.5 * x);
  return h + std::max(0.0, x - 2.0 * h - 1.0);
}

// Fraction of [x - w/2, x + w/2] on odd cells (w > 0), or the indicator itself (w == 0).
double odd_fraction(double x, double w) {
  if (!(w > 1e-12)) return std::fmod(std::floor(x), 2.0) != 0.0 ? 1.0 : 0.0;
  return (odd_cells_integral(x + 0.5 * w) - odd_cells_integral(x - 0.5 * w)) / w;
}

}  // namespace

float srgb_to_linear(float e) {
  if (e <= 0.04045f) return e * (1.0f / 12.92f);
  return float(std::pow((double(e) + 0.055) / 1.055, 2.4));
}

float linear_to_srgb(float l) {
  if (l <= 0.0031308f) return l * 12.92f;
  return float(1.055 * std::pow(double(l), 1.0 / 2.4) - 0.055);
}

struct TextureEvaluator::Image {
  OIIO::TextureSystem::TextureHandle* handle = nullptr;
  int channels = 0;
};

TextureEvaluator::TextureEvaluator(const Scene& scene, size_t cache_megabytes)
    : textures_(scene.textures), cache_megabytes_(cache_megabytes) {
  images_.resize(textures_.size());
  bool any_image = false;
  for (const Texture& t : textures_) any_image |= t.type == TextureType::Image;
  if (!any_image) return;
  // A private TextureSystem (and ImageCache): its memory bound is this evaluator's alone.
  OIIO::TextureSystem* ts = OIIO::TextureSystem::create(/*shared=*/false);
  texture_system_ = ts;
  ts->attribute("max_memory_MB", float(cache_megabytes));
  // Every file the TextureSystem sees is tiled and MIP-mapped (see open_image); these two are a
  // fallback. OIIO 2.4 raises its cache to twice the largest image it must MIP-map itself.
  ts->attribute("autotile", 64);
  ts->attribute("automip", 1);
  ts->attribute("accept_untiled", 1);
  ts->attribute("accept_unmipped", 1);
  ts->attribute("unassociatedalpha", 1);  // colours as stored, never multiplied by alpha
  try {
    for (size_t i = 0; i < textures_.size(); ++i)
      if (textures_[i].type == TextureType::Image) open_image(int(i));
  } catch (...) {
    release();  // the destructor does not run for a throwing constructor
    throw;
  }
}

TextureEvaluator::~TextureEvaluator() { release(); }

void TextureEvaluator::release() {
  if (texture_system_) OIIO::TextureSystem::destroy(as_ts(texture_system_), true);
  texture_system_ = nullptr;
  if (!temp_dir_.empty()) {
    std::error_code ec;  // best effort: a leftover temporary directory is harmless
    std::filesystem::remove_all(temp_dir_, ec);
    temp_dir_.clear();
  }
}

void TextureEvaluator::open_image(int index) {
  const Texture& t = textures_[index];
  OIIO::TextureSystem* ts = as_ts(texture_system_);
  std::string path = t.resolved_path.empty() ? t.file : t.resolved_path;
  // Colour channels as stored: OIIO would otherwise multiply PNG/TIFF colours by their alpha
  // (associate it), darkening the colour wherever alpha < 1; no material reads alpha as coverage.
  OIIO::ImageSpec config;
  config.attribute("oiio:UnassociatedAlpha", 1);
  auto in = OIIO::ImageInput::open(path, &config);
  if (!in) throw texture_error(t, "cannot open image: " + OIIO::geterror());
  const OIIO::ImageSpec spec = in->spec();
  bool decode = !t.is_data && !spec.format.is_floating_point() && !tagged_linear(spec);
  bool mipmapped = spec.tile_width > 0 && in->seek_subimage(0, 1);
  if (!in->seek_subimage(0, 0)) throw texture_error(t, "cannot read: " + in->geterror());
  if (decode || !mipmapped) {
    if (temp_dir_.empty()) {
      std::string tmpl = (std::filesystem::temp_directory_path() / "rayfarm-tex-XXXXXX").string();
      if (!::mkdtemp(tmpl.data())) throw texture_error(t, "cannot create a temporary directory");
      temp_dir_ = tmpl;
    }
    // Half keeps 8-bit sources to 1/8 of a code step (and half ones exact); deeper ones get float.
    bool half = spec.format.size() == 1 || spec.format == OIIO::TypeDesc::HALF;
    std::string converted = temp_dir_ + "/" + std::to_string(index) + ".exr";
    write_mipmapped(t, *in, decode, half ? OIIO::TypeDesc::HALF : OIIO::TypeDesc::FLOAT, converted);
    path = converted;
  }
  in.reset();
  Image& img = images_[index];
  img.handle = ts->get_texture_handle(OIIO::ustring(path));
  const OIIO::ImageSpec* opened = img.handle ? ts->imagespec(img.handle, nullptr) : nullptr;
  if (!opened) throw texture_error(t, "cannot read image: " + ts->geterror());
  img.channels = opened->nchannels;
}

void TextureEvaluator::lookup(int index, Vec2 uv, float fp, bool want_scalar, float* out) const {
  const Texture& t = textures_[index];
  float u = uv.x * t.uv_scale.x + t.uv_offset.x;
  float v = uv.y * t.uv_scale.y + t.uv_offset.y;
  float c[3] = {0, 0, 0}, alpha = 1;
  bool grey = false;  // a one-channel image: its scalar is that channel, not a luminance
  switch (t.type) {
    case TextureType::Constant:
      c[0] = t.value.x, c[1] = t.value.y, c[2] = t.value.z;
      break;
    case TextureType::Checkerboard: {
      double fu = odd_fraction(u, double(fp) * std::fabs(t.uv_scale.x));
      double fv = odd_fraction(v, double(fp) * std::fabs(t.uv_scale.y));
      float b = float(fu * (1.0 - fv) + fv * (1.0 - fu));  // fraction of b cells (odd sum)
      RGB col = t.color_a * (1.0f - b) + t.color_b * b;
      c[0] = col.x, c[1] = col.y, c[2] = col.z;
      break;
    }
    case TextureType::Image: {
      const Image& img = images_[index];
      OIIO::TextureSystem* ts = as_ts(texture_system_);
      OIIO::TextureOpt opt;
      opt.swrap = opt.twrap = OIIO::TextureOpt::WrapPeriodic;
      opt.mipmode = OIIO::TextureOpt::MipModeTrilinear;
      opt.interpmode = OIIO::TextureOpt::InterpBilinear;
      // OIIO's t runs down the image; ours (v) runs up. The footprint becomes the s/t derivatives
      // of an isotropic square lookup, scaled like the coordinates.
      float ds = fp * std::fabs(t.uv_scale.x), dt = fp * std::fabs(t.uv_scale.y);
      int n = colour_channels(img.channels);
      if (!ts->texture(img.handle, ts->get_perthread_info(), opt, u, 1.0f - v, ds, 0, 0, dt, n, c))
        ts->geterror();  // clear the message; the lookup reads black (the file opened at start)
      int alpha_channel = img.channels == 2 ? 1 : img.channels >= 4 ? 3 : -1;
      if (want_scalar && t.channel == 3 && alpha_channel >= 0) {
        opt.firstchannel = alpha_channel;
        if (!ts->texture(img.handle, ts->get_perthread_info(), opt, u, 1.0f - v, ds, 0, 0, dt, 1,
                         &alpha))
          ts->geterror();
      }
      if (n == 1) c[1] = c[2] = c[0];
      grey = n == 1;
      break;
    }
  }
  for (int k = 0; k < 3; ++k) c[k] *= t.scale[k];
  if (!want_scalar) {
    out[0] = c[0], out[1] = c[1], out[2] = c[2];
    return;
  }
  float s = t.channel == 3                    ? alpha
            : t.channel >= 0 && t.channel < 3 ? c[t.channel]
            : grey                            ? c[0]
                                              : luminance(RGB(c[0], c[1], c[2]));
  out[0] = t.squared ? s * s : s;
}

RGB TextureEvaluator::eval(const ColorParam& p, Vec2 uv, float uv_footprint) const {
  if (p.texture < 0) return p.value;
  assert(size_t(p.texture) < textures_.size());
  float c[3];
  lookup(p.texture, uv, uv_footprint, false, c);
  return {c[0], c[1], c[2]};
}

float TextureEvaluator::eval(const FloatParam& p, Vec2 uv, float uv_footprint) const {
  if (p.texture < 0) return p.value;
  assert(size_t(p.texture) < textures_.size());
  float c[3];
  lookup(p.texture, uv, uv_footprint, true, c);
  return c[0];
}

}  // namespace rf
