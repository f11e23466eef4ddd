// Tests of engine/texture: constant and checkerboard textures, image textures through
// OpenImageIO (sRGB decoding exactly once, v flip, footprint-driven mip levels, linear means) and
// the bounded memory of the texture cache.
#include "engine/texture.h"

#include <gtest/gtest.h>
#include <malloc.h>

#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/texture.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "engine/sampler.h"
#include "tests/support/test_support.h"

using rf::test::kAddressSanitizer;

namespace rf {
namespace {

// The sRGB decoding written out independently of engine/texture.cpp, in double.
double srgb_decode_ref(double e) {
  return e <= 0.04045 ? e / 12.92 : std::pow((e + 0.055) / 1.055, 2.4);
}

void write_png8(const std::string& path, int w, int h, int nch, const std::vector<uint8_t>& px) {
  OIIO::ImageSpec spec(w, h, nch, OIIO::TypeDesc::UINT8);
  auto out = OIIO::ImageOutput::create(path);
  ASSERT_TRUE(out && out->open(path, spec)) << OIIO::geterror();
  ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, px.data()));
  ASSERT_TRUE(out->close());
}

// A float OpenEXR written one scanline at a time (so writing it does not raise the peak RSS).
void write_exr(const std::string& path, int w, int h, int nch,
               const std::function<float(int, int, int)>& value, const char* compression = "zip") {
  OIIO::ImageSpec spec(w, h, nch, OIIO::TypeDesc::FLOAT);
  spec.attribute("compression", compression);
  auto out = OIIO::ImageOutput::create(path);
  ASSERT_TRUE(out && out->open(path, spec)) << OIIO::geterror();
  std::vector<float> row(size_t(w) * nch);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < nch; ++c) row[size_t(x) * nch + c] = value(x, y, c);
    ASSERT_TRUE(out->write_scanline(y, 0, OIIO::TypeDesc::FLOAT, row.data()));
  }
  ASSERT_TRUE(out->close());
}

Texture image_texture(const std::string& path, bool is_data = false) {
  Texture t;
  t.name = "img";
  t.type = TextureType::Image;
  t.file = path;
  t.resolved_path = path;
  t.is_data = is_data;
  return t;
}

Scene scene_with(std::vector<Texture> textures) {
  Scene s;
  s.textures = std::move(textures);
  return s;
}

// uv of the centre of texel (i, j), j counted from the top (first) scanline of the file.
Vec2 texel_centre(int i, int j, int w, int h) {
  return {(float(i) + 0.5f) / float(w), 1.0f - (float(j) + 0.5f) / float(h)};
}

ColorParam tex(int i) { return {RGB(0.0f), i}; }
FloatParam ftex(int i) { return {0.0f, i}; }

TEST(TextureTest, ConstantsAndPlainParameters) {
  Texture c;
  c.type = TextureType::Constant;
  c.value = RGB(0.25f, 0.5f, 0.75f);
  TextureEvaluator ev(scene_with({c}));
  EXPECT_EQ(ev.cache_megabytes(), 256u);
  RGB v = ev.eval(tex(0), {0.3f, 0.9f}, 0.0f);
  EXPECT_EQ(v, RGB(0.25f, 0.5f, 0.75f));
  // A parameter without a texture is its value; a float texture of a colour is its luminance.
  EXPECT_EQ(ev.eval(ColorParam{RGB(0.1f, 0.2f, 0.3f), -1}, {0, 0}, 0), RGB(0.1f, 0.2f, 0.3f));
  EXPECT_EQ(ev.eval(FloatParam{0.42f, -1}, {0, 0}, 0), 0.42f);
  EXPECT_FLOAT_EQ(ev.eval(ftex(0), {0.5f, 0.5f}, 0),
                  0.2126f * 0.25f + 0.7152f * 0.5f + 0.0722f * 0.75f);
}

TEST(TextureTest, CheckerboardPointValues) {
  Texture t;
  t.type = TextureType::Checkerboard;
  t.color_a = RGB(1, 0, 0);
  t.color_b = RGB(0, 0, 1);
  t.uv_scale = {4, 2};
  t.uv_offset = {0.5f, 0};
  TextureEvaluator ev(scene_with({t}));
  // u' = 4u + 0.5, v' = 2v: a where floor(u') + floor(v') is even.
  struct Case {
    Vec2 uv;
    bool a;
  };
  for (Case c : {Case{{0.0f, 0.1f}, true}, Case{{0.2f, 0.1f}, false}, Case{{0.2f, 0.6f}, true},
                 Case{{0.0f, 0.6f}, false}, Case{{-0.2f, 0.1f}, false}, Case{{-0.2f, -0.1f}, true},
                 Case{{0.99f, 0.99f}, false}}) {
    RGB expect = c.a ? t.color_a : t.color_b;
    EXPECT_EQ(ev.eval(tex(0), c.uv, 0.0f), expect) << c.uv.x << "," << c.uv.y;
  }
}

TEST(TextureTest, CheckerboardFootprintIsBoxFiltered) {
  Texture t;
  t.type = TextureType::Checkerboard;
  t.color_a = RGB(1.0f);
  t.color_b = RGB(0.0f);
  t.uv_scale = {8, 8};
  TextureEvaluator ev(scene_with({t}));
  // A footprint covering a whole number of checks averages to exactly one half.
  EXPECT_NEAR(ev.eval(tex(0), {0.5f, 0.5f}, 0.25f).x, 0.5f, 1e-6f);
  EXPECT_NEAR(ev.eval(tex(0), {0.37f, 0.11f}, 2.0f).x, 0.5f, 1e-6f);
  // Half a check wide, centred on the edge x' = 1 inside row v' in [0,1): half a, half b.
  EXPECT_NEAR(ev.eval(tex(0), {1.0f / 8, 0.5f / 8}, 0.5f / 8).x, 0.5f, 1e-6f);
  // Inside one check, a footprint smaller than the distance to its edges changes nothing.
  EXPECT_NEAR(ev.eval(tex(0), {0.5f / 8, 0.5f / 8}, 0.5f / 8).x, 1.0f, 1e-6f);
  // The box average equals a brute-force average of point values over the same square.
  Vec2 uv{0.3f, 0.71f};
  float w = 0.19f;
  double sum = 0;
  const int n = 400;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      sum += ev.eval(tex(0),
                     {uv.x + w * ((i + 0.5f) / n - 0.5f), uv.y + w * ((j + 0.5f) / n - 0.5f)}, 0.0f)
                 .x;
  EXPECT_NEAR(ev.eval(tex(0), uv, w).x, sum / (n * n), 3e-3);  // midpoint rule: O(1/n) at edges
}

// What OpenImageIO 2.4's TextureSystem returns for an 8-bit sRGB PNG: the stored value / 255,
// not linearised, although the file says "oiio:ColorSpace" = "sRGB". This is why the evaluator
// decodes such images itself; if OIIO ever starts linearising, this test fails first.
TEST(TextureTest, OiioTextureSystemReturnsEncodedValues) {
  std::string dir = test::make_temp_dir("texture");
  std::string path = dir + "/grey128.png";
  write_png8(path, 4, 4, 3, std::vector<uint8_t>(48, 128));
  OIIO::TextureSystem* ts = OIIO::TextureSystem::create(false);
  OIIO::TextureOpt opt;
  opt.interpmode = OIIO::TextureOpt::InterpBilinear;
  float r[3];
  ASSERT_TRUE(ts->texture(OIIO::ustring(path), opt, 0.375f, 0.375f, 0, 0, 0, 0, 3, r));
  EXPECT_NEAR(r[0], 128.0f / 255.0f, 1e-6f);
  const OIIO::ImageSpec* spec = ts->imagespec(OIIO::ustring(path));
  ASSERT_NE(spec, nullptr);
  EXPECT_EQ(spec->get_string_attribute("oiio:ColorSpace"), "sRGB");
  OIIO::TextureSystem::destroy(ts, true);
}

// An 8-bit sRGB PNG of known linear values (encoded to the nearest byte) reads back linear at
// texel centres, decoded exactly once; uv (0,0) is the bottom-left texel.
TEST(TextureTest, Srgb8BitPngTexelCentres) {
  std::string dir = test::make_temp_dir("texture");
  const int w = 4, h = 2;
  // Intended linear values per texel (row-major from the top scanline), one per channel.
  const double linear[h][w] = {{0.0, 0.002, 0.05, 0.18}, {0.2, 0.5, 0.8, 1.0}};
  std::vector<uint8_t> px;
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i)
      for (int c = 0; c < 3; ++c) {
        double l = c == 0 ? linear[j][i] : (c == 1 ? 1.0 - linear[j][i] : 0.5);
        double e = l <= 0.0031308 ? 12.92 * l : 1.055 * std::pow(l, 1 / 2.4) - 0.055;
        px.push_back(uint8_t(std::lround(e * 255)));
      }
  write_png8(dir + "/known.png", w, h, 3, px);
  TextureEvaluator ev(scene_with({image_texture(dir + "/known.png")}));
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      RGB got = ev.eval(tex(0), texel_centre(i, j, w, h), 0.0f);
      for (int c = 0; c < 3; ++c) {
        uint8_t b = px[(size_t(j) * w + i) * 3 + c];
        double exact = srgb_decode_ref(b / 255.0);
        // Stored as half float after decoding: relative error <= 2^-11.
        EXPECT_NEAR(got[c], exact, 5e-4 * exact + 1e-7) << i << "," << j << " c" << c;
        // Against the intended linear value: half an 8-bit code step, in linear units.
        double l = c == 0 ? linear[j][i] : (c == 1 ? 1.0 - linear[j][i] : 0.5);
        double step = srgb_decode_ref(std::min(255.0, b + 0.5) / 255) -
                      srgb_decode_ref(std::max(0.0, b - 0.5) / 255);
        EXPECT_NEAR(got[c], l, step + 5e-4 * l + 1e-7) << i << "," << j << " c" << c;
      }
    }
  // v runs up: the bottom-left texel (last scanline, linear 0.2) is centred at uv (1/8, 1/4), the
  // top-right one (first scanline, 0.18) at (7/8, 3/4).
  EXPECT_NEAR(ev.eval(tex(0), {0.125f, 0.25f}, 0).x, 0.2f, 0.01f);
  EXPECT_NEAR(ev.eval(tex(0), {0.875f, 0.75f}, 0).x, 0.18f, 0.01f);
}

TEST(TextureTest, DataImagesAreNotDecoded) {
  std::string dir = test::make_temp_dir("texture");
  std::vector<uint8_t> px = {0, 64, 128, 255};  // one channel, 2x2
  write_png8(dir + "/rough.png", 2, 2, 1, px);
  std::vector<uint8_t> rgb = {10, 100, 200, 50, 150, 250, 0, 0, 0, 255, 255, 255};
  write_png8(dir + "/rgb.png", 2, 2, 3, rgb);
  TextureEvaluator ev(
      scene_with({image_texture(dir + "/rough.png", true), image_texture(dir + "/rgb.png", true),
                  image_texture(dir + "/rgb.png", false)}));
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      Vec2 uv = texel_centre(i, j, 2, 2);
      int k = j * 2 + i;
      // Data: the stored value / 255, single channel as the float and replicated as colour. The
      // rewritten file stores half floats: relative error <= 2^-11 (1/8 of an 8-bit code step).
      EXPECT_NEAR(ev.eval(ftex(0), uv, 0), px[k] / 255.0f, 5e-4f * px[k] / 255.0f + 1e-7f);
      EXPECT_NEAR(ev.eval(tex(0), uv, 0).y, px[k] / 255.0f, 5e-4f * px[k] / 255.0f + 1e-7f);
      RGB data = ev.eval(tex(1), uv, 0), colour = ev.eval(tex(2), uv, 0);
      for (int c = 0; c < 3; ++c) {
        double e = rgb[k * 3 + c] / 255.0;
        EXPECT_NEAR(data[c], e, 5e-4 * e + 1e-7);
        EXPECT_NEAR(colour[c], srgb_decode_ref(e), 5e-4 * srgb_decode_ref(e) + 1e-7);
      }
      // A float parameter from a colour image is its luminance.
      EXPECT_NEAR(ev.eval(ftex(1), uv, 0), luminance(data), 1e-6f);
    }
}

// Texture::scale, channel and squared (glTF's factor x texture and its packed metallic-roughness
// maps: roughness in G, metallic in B). Tolerance: the rewritten file stores half floats, relative
// error <= 2^-11 (1/8 of an 8-bit code step), doubled where the value is squared.
TEST(TextureTest, ScaleChannelAndSquaredRemapTheLookup) {
  std::string dir = test::make_temp_dir("texture");
  std::vector<uint8_t> rgba = {10, 100, 200, 50, 150, 250, 0, 128, 0, 0, 0, 255, 255, 255, 255, 0};
  {  // stored as given: OIIO would otherwise treat the values as premultiplied and divide by alpha
    OIIO::ImageSpec spec(2, 2, 4, OIIO::TypeDesc::UINT8);
    spec.attribute("oiio:UnassociatedAlpha", 1);
    auto out = OIIO::ImageOutput::create(dir + "/rgba.png");
    ASSERT_TRUE(out && out->open(dir + "/rgba.png", spec)) << OIIO::geterror();
    ASSERT_TRUE(out->write_image(OIIO::TypeDesc::UINT8, rgba.data()));
    ASSERT_TRUE(out->close());
  }
  std::vector<uint8_t> grey = {0, 64, 128, 255};
  write_png8(dir + "/grey.png", 2, 2, 1, grey);
  std::vector<Texture> ts;
  for (int c = -1; c < 4; ++c) {  // 0..4: channel -1, 0, 1, 2, 3 of the RGBA image, scaled
    Texture t = image_texture(dir + "/rgba.png", true);
    t.scale = RGB(0.5f, 0.25f, 2.0f);
    t.channel = int8_t(c);
    ts.push_back(t);
  }
  Texture sq = image_texture(dir + "/rgba.png", true);  // 5: G, squared, scaled by 0.5
  sq.channel = 1, sq.squared = true, sq.scale = RGB(0.5f);
  ts.push_back(sq);
  Texture g = image_texture(dir + "/grey.png", true);  // 6: B of a grey image, alpha (7)
  g.channel = 2;
  ts.push_back(g);
  g.channel = 3;
  ts.push_back(g);
  Texture k;  // 8: constant, channel 1 scaled
  k.type = TextureType::Constant, k.value = RGB(0.2f, 0.4f, 0.6f), k.scale = RGB(2.0f),
  k.channel = 1;
  ts.push_back(k);
  TextureEvaluator ev(scene_with(ts));
  const RGB scale(0.5f, 0.25f, 2.0f);
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      Vec2 uv = texel_centre(i, j, 2, 2);
      int k4 = (j * 2 + i) * 4;
      RGB raw(rgba[k4] / 255.0f, rgba[k4 + 1] / 255.0f, rgba[k4 + 2] / 255.0f);
      float a = rgba[k4 + 3] / 255.0f;
      auto near = [](float got, float want, float rel) {
        EXPECT_NEAR(got, want, rel * want + 1e-6f);
      };
      RGB col = ev.eval(tex(0), uv, 0);
      for (int c = 0; c < 3; ++c) near(col[c], raw[c] * scale[c], 5e-4f);
      near(ev.eval(ftex(0), uv, 0), luminance(raw * scale), 5e-4f);
      for (int c = 0; c < 3; ++c) near(ev.eval(ftex(1 + c), uv, 0), raw[c] * scale[c], 5e-4f);
      near(ev.eval(ftex(4), uv, 0), a, 5e-4f);  // alpha is never scaled
      near(ev.eval(ftex(5), uv, 0), (0.5f * raw.y) * (0.5f * raw.y), 1e-3f);
      float gv = grey[j * 2 + i] / 255.0f;
      near(ev.eval(ftex(6), uv, 0), gv, 5e-4f);
      EXPECT_EQ(ev.eval(ftex(7), uv, 0), 1.0f);  // no alpha channel: opaque
      EXPECT_FLOAT_EQ(ev.eval(ftex(8), uv, 0), 0.8f);
    }
}

TEST(TextureTest, FloatExrTexelCentresAreExact) {
  std::string dir = test::make_temp_dir("texture");
  const int w = 5, h = 3;
  auto value = [](int x, int y, int c) {
    return 0.37f * float(x) - 1.1f * float(y) + 3.0f * c + 0.01f;
  };
  write_exr(dir + "/f.exr", w, h, 3, value);
  TextureEvaluator ev(scene_with({image_texture(dir + "/f.exr")}));
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i) {
      RGB got = ev.eval(tex(0), texel_centre(i, j, w, h), 0.0f);
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(got[c], value(i, j, c), 2e-6f * std::fabs(value(i, j, c)) + 1e-6f)
            << i << "," << j << " c" << c;  // float storage: only the bilinear weights' rounding
    }
}

TEST(TextureTest, UvScaleOffsetAndPeriodicWrap) {
  std::string dir = test::make_temp_dir("texture");
  auto value = [](int x, int y, int) { return float(10 * y + x); };
  write_exr(dir + "/g.exr", 4, 4, 1, value);
  Texture t = image_texture(dir + "/g.exr");
  t.uv_scale = {2, 3};
  t.uv_offset = {0.25f, 0.5f};
  TextureEvaluator ev(scene_with({image_texture(dir + "/g.exr"), t}));
  Vec2 uv{0.3f, 0.45f};
  Vec2 mapped{uv.x * 2 + 0.25f, uv.y * 3 + 0.5f};
  float direct = ev.eval(ftex(0), {mapped.x - 1.0f, mapped.y - 1.0f}, 0);  // wrapped by one period
  EXPECT_NEAR(ev.eval(ftex(1), uv, 0), direct, 1e-4f);
  EXPECT_NEAR(ev.eval(ftex(0), {0.125f + 3.0f, 0.875f - 2.0f}, 0), value(0, 0, 0), 1e-5f);
}

// Writes a w x h RGB 8-bit sRGB noise PNG and returns its per-channel linear mean.
RGB write_noise_png(const std::string& path, int w, int h, uint64_t seed) {
  std::vector<uint8_t> px(size_t(w) * h * 3);
  double sum[3] = {0, 0, 0};
  std::mt19937_64 rng(seed);
  for (size_t k = 0; k < px.size(); ++k) {
    px[k] = uint8_t(rng() >> 56);
    sum[k % 3] += srgb_decode_ref(px[k] / 255.0);
  }
  write_png8(path, w, h, 3, px);
  double n = double(w) * h;
  return RGB(float(sum[0] / n), float(sum[1] / n), float(sum[2] / n));
}

// Filtering and mip-mapping average linear values: the mean of lookups over a fine uniform grid
// is the image's linear mean at every footprint (bilinear interpolation and box mip levels of a
// periodic image preserve the mean). Filtering the encoded values instead would be 5-25% dark.
TEST(TextureTest, MeanOverFineGridIsLinearMean) {
  std::string dir = test::make_temp_dir("texture");
  const int w = 64, h = 32;
  RGB mean = write_noise_png(dir + "/noise.png", w, h, 7);
  TextureEvaluator ev(scene_with({image_texture(dir + "/noise.png")}));
  for (float fp : {0.0f, 2.0f / w, 8.0f / w, 1.0f}) {
    const int n = 8;  // lookups per texel and axis
    double sum[3] = {0, 0, 0};
    for (int j = 0; j < h * n; ++j)
      for (int i = 0; i < w * n; ++i) {
        RGB c = ev.eval(tex(0), {(i + 0.5f) / (w * n), (j + 0.5f) / (h * n)}, fp);
        for (int k = 0; k < 3; ++k) sum[k] += c[k];
      }
    for (int k = 0; k < 3; ++k)
      EXPECT_NEAR(sum[k] / (double(w) * h * n * n), mean[k], 0.01 * mean[k]) << "fp " << fp;
  }
  // A footprint twice as wide as the texture reads its mean everywhere (the 1x1 mip level).
  for (Vec2 uv : {Vec2{0.1f, 0.2f}, Vec2{0.77f, 0.5f}}) {
    RGB c = ev.eval(tex(0), uv, 2.0f);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(c[k], mean[k], 0.01 * mean[k]);
  }
}

// Odd sizes: the rewritten levels (18x11, 9x5, ...) are exact box filters with fractional edges,
// so they keep the mean too. Float data: the 1% is the fine grid's misalignment with coarse levels.
TEST(TextureTest, OddSizedImageKeepsItsMeanAtEveryLevel) {
  std::string dir = test::make_temp_dir("texture");
  const int w = 37, h = 23;
  std::mt19937_64 rng(3);
  std::vector<float> px(size_t(w) * h);
  double sum = 0;
  for (float& p : px) sum += p = float(rng() >> 40) * 0x1p-24f;
  double mean = sum / px.size();
  write_exr(dir + "/odd.exr", w, h, 1, [&](int x, int y, int) { return px[size_t(y) * w + x]; });
  TextureEvaluator ev(scene_with({image_texture(dir + "/odd.exr")}));
  for (int j = 0; j < h; ++j)
    for (int i = 0; i < w; ++i)
      ASSERT_NEAR(ev.eval(ftex(0), texel_centre(i, j, w, h), 0), px[size_t(j) * w + i], 1e-5f)
          << i << "," << j;  // (i + 0.5) / 37 * 37 - 0.5 is not exactly i: a 1e-6 neighbour blend
  for (float fp : {0.0f, 2.0f / w, 8.0f / w, 2.0f}) {
    const int n = 16;
    double s = 0;
    for (int j = 0; j < h * n; ++j)
      for (int i = 0; i < w * n; ++i)
        s += ev.eval(ftex(0), {(i + 0.5f) / (w * n), (j + 0.5f) / (h * n)}, fp);
    EXPECT_NEAR(s / (double(w) * h * n * n), mean, 0.01 * mean) << "fp " << fp;
  }
}

// A file that is already tiled and MIP-mapped (maketx output) is read as it is, and a tiled file
// without MIP levels is rewritten like a scanline one; both read back their texels.
TEST(TextureTest, TiledInputs) {
  std::string dir = test::make_temp_dir("texture");
  const int w = 80, h = 48;
  auto value = [](int x, int y, int c) { return float(x + 100 * y) + 0.25f * c; };
  write_exr(dir + "/plain.exr", w, h, 3, value);
  OIIO::ImageSpec config;
  config.tile_width = config.tile_height = 32;
  ASSERT_TRUE(OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture,
                                               dir + "/plain.exr", dir + "/mip.tx", config));
  config.attribute("maketx:nomipmap", 1);
  ASSERT_TRUE(OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture,
                                               dir + "/plain.exr", dir + "/tiled.exr", config));
  TextureEvaluator ev(
      scene_with({image_texture(dir + "/mip.tx"), image_texture(dir + "/tiled.exr")}));
  for (int t = 0; t < 2; ++t)
    for (int j = 0; j < h; j += 7)
      for (int i = 0; i < w; i += 5) {
        RGB got = ev.eval(tex(t), texel_centre(i, j, w, h), 0);
        for (int c = 0; c < 3; ++c)
          ASSERT_NEAR(got[c], value(i, j, c), 1e-6f * value(i, j, c) + 1e-4f)
              << t << " " << i << "," << j;
      }
}

TEST(TextureTest, MissingImageIsASceneErrorNamingIt) {
  Texture t = image_texture("/nonexistent/dir/albedo.png");
  t.name = "wall_albedo";
  try {
    TextureEvaluator ev(scene_with({t}));
    FAIL() << "no exception";
  } catch (const SceneError& e) {
    std::string msg = e.what();
    EXPECT_NE(msg.find("wall_albedo"), std::string::npos) << msg;
    EXPECT_NE(msg.find("albedo.png"), std::string::npos) << msg;
  }
}

TEST(TextureTest, ConcurrentLookupsMatchSerialOnes) {
  std::string dir = test::make_temp_dir("texture");
  write_noise_png(dir + "/a.png", 256, 128, 1);
  write_exr(dir + "/b.exr", 300, 200, 3,
            [](int x, int y, int c) { return float((x * 7 + y * 13 + c) % 17); });
  TextureEvaluator ev(scene_with({image_texture(dir + "/a.png"), image_texture(dir + "/b.exr")}));
  const int n = 20000;
  auto lookup = [&](int k) {
    IndependentSampler s;
    s.start_light_path(1, 0, 0, uint64_t(k));
    Vec2 uv = s.get_2d();
    float fp = s.get_1d() < 0.5f ? 0.0f : 0.05f * s.get_1d();
    return ev.eval(tex(k % 2), uv, fp);
  };
  std::vector<RGB> serial(n), parallel(n);
  for (int k = 0; k < n; ++k) serial[k] = lookup(k);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t)
    threads.emplace_back([&, t] {
      for (int k = t; k < n; k += 4) parallel[k] = lookup(k);
    });
  for (auto& th : threads) th.join();
  for (int k = 0; k < n; ++k) ASSERT_EQ(serial[k], parallel[k]) << k;
}

// Peak resident set (VmHWM) and current resident set (VmRSS) of this process, in MB.
double proc_status_mb(const char* key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind(key, 0) == 0) return std::stod(line.substr(std::string(key).size())) / 1024.0;
  return -1;
}

// Resets VmHWM to the current RSS (Linux >= 4.0), so earlier tests' peaks do not hide ours.
bool reset_peak_rss() {
  std::ofstream out("/proc/self/clear_refs");
  out << "5";
  out.flush();
  return bool(out);
}

// Writes `count` RGB float scanline EXRs of size x size, then looks every one of them up all over,
// twice, through an evaluator with a cache of cache_mb, and returns the growth of the peak RSS in
// MB (construction included). Lookups sweep a grid of 1/4 the resolution in scanline order, as
// coherent rays would, half at the finest level and half a few levels up.
double peak_rss_growth_mb(int count, int size, size_t cache_mb) {
  if (kAddressSanitizer) return -1;  // its quarantine keeps freed memory resident
  std::string dir = test::make_temp_dir("texture-memory");
  std::vector<Texture> textures;
  for (int i = 0; i < count; ++i) {
    std::string path = dir + "/big" + std::to_string(i) + ".exr";
    write_exr(
        path, size, size, 3,
        [i](int x, int y, int c) { return float((x ^ (y * 3)) + c + i) * 1e-3f; }, "none");
    textures.push_back(image_texture(path));
  }
  ::malloc_trim(0);  // return freed heap to the system, so the reset peak is what is live now
  EXPECT_TRUE(reset_peak_rss());
  double before = proc_status_mb("VmHWM:");
  {
    auto t0 = std::chrono::steady_clock::now();
    TextureEvaluator ev(scene_with(textures), cache_mb);
    auto t1 = std::chrono::steady_clock::now();
    const int g = size / 4;
    double sink = 0;
    for (int round = 0; round < 2; ++round)
      for (int t = 0; t < count; ++t)
        for (int j = 0; j < g; ++j)
          for (int i = 0; i < g; ++i) {
            float fp = (i + j) % 2 == 0 ? 8.0f / float(size) : 0.0f;
            sink += ev.eval(tex(t), {(i + 0.5f) / g, (j + 0.5f) / g}, fp).x;
          }
    EXPECT_GT(sink, 0.0);
    std::printf("%d x %d^2: rewriting as tiled MIP-maps %.2f s, %d lookups %.2f s\n", count, size,
                std::chrono::duration<double>(t1 - t0).count(), 2 * count * g * g,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count());
  }
  double after = proc_status_mb("VmHWM:");
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  return after - before;
}

// 4 x 1024^2 RGB float (48 MB at the finest level, 64 MB with mip levels) through an 8 MB cache:
// the peak RSS grows by at most the cache plus 16 MB (OIIO per-thread state, file buffers, the
// rewriting's strips), well below the data's size. Measured: 9.5 MB; 50 MB with a 1 GB cache.
TEST(TextureTest, CacheBoundsMemorySmall) {
  if (kAddressSanitizer) GTEST_SKIP() << "RSS is meaningless under AddressSanitizer";
  double growth = peak_rss_growth_mb(4, 1024, 8);
  std::printf("peak RSS growth: %.1f MB (data 48 MB, cache 8 MB)\n", growth);
  EXPECT_LT(growth, 8 + 16);
  // Control: with a cache larger than the data the same lookups do exceed that bound, so the
  // lookups touch enough of the data for the bound to mean something.
  double unbounded = peak_rss_growth_mb(4, 1024, 1024);
  std::printf("peak RSS growth with a 1 GB cache: %.1f MB\n", unbounded);
  EXPECT_GT(unbounded, 8 + 16);
}

// 8 x 2048^2 RGB float (384 MB, 512 MB with mip levels) through a 32 MB cache: the peak RSS grows
// by at most the cache plus 32 MB. Measured: 34 MB. About 12 s, and 900 MB written to $TMPDIR.
TEST(LongTextureTest, CacheBoundsMemoryLarge) {
  if (kAddressSanitizer) GTEST_SKIP() << "RSS is meaningless under AddressSanitizer";
  double growth = peak_rss_growth_mb(8, 2048, 32);
  std::printf("peak RSS growth: %.1f MB (data 384 MB, cache 32 MB)\n", growth);
  EXPECT_LT(growth, 32 + 32);
}

}  // namespace
}  // namespace rf
