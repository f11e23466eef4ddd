// Tests of engine/image_io: the EXR (channels, pixels, data window, provenance) and the PNG
// preview, reading images back, and the image-error figures of `rayfarm compare`.
#include "engine/image_io.h"

#include <gtest/gtest.h>

#include <OpenImageIO/imageio.h>
#include <cmath>
#include <filesystem>
#include <string>

#include "engine/buffer_merge.h"
#include "tests/support/fixtures.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

SampleBuffer image_buffer(Rect rect) {
  BufferHeader h = test::test_header(PassSet{}, 8, 6);
  SampleBuffer acc(h, rect, false);
  for (uint32_t k = 0; k < 4; ++k) {
    SampleBuffer p(test::test_header(PassSet::range(k, k + 1), 8, 6), rect, false);
    for (int y = rect.y0; y < rect.y1(); ++y) {
      for (int x = rect.x0; x < rect.x1(); ++x) {
        p.add_sample(x, y, RGB(0.1f * x + k, 0.05f * y, 0.3f + 0.01f * k));
        p.add_sample(x, y, RGB(0.1f * x + k, 0.05f * y, 0.3f - 0.01f * k));
      }
    }
    p.finish_pass();
    merge_into(acc, p);
  }
  acc.nonfinite_samples = 3;
  return acc;
}

std::string string_attr(const OIIO::ImageSpec& spec, const char* name) {
  return spec.get_string_attribute(name, "(missing)");
}

TEST(ImageIO, ExrHasChannelsPixelsAndProvenance) {
  std::string dir = test::make_temp_dir("film-exr");
  std::string path = dir + "/frame.exr";
  SampleBuffer b = image_buffer(Rect{0, 0, 8, 6});
  write_exr(path, b, {{"job", "job-17"}, {"spp", "not me"}});
  // Nothing else left in the directory: the temporary file was renamed.
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 1);

  auto in = OIIO::ImageInput::open(path);
  ASSERT_TRUE(in) << OIIO::geterror();
  const OIIO::ImageSpec& spec = in->spec();
  ASSERT_EQ(spec.nchannels, 7);
  EXPECT_EQ(spec.width, 8);
  EXPECT_EQ(spec.height, 6);
  EXPECT_EQ(spec.format, OIIO::TypeDesc::FLOAT);
  std::vector<float> px(size_t(8 * 6 * 7));
  ASSERT_TRUE(in->read_image(0, 0, 0, 7, OIIO::TypeDesc::FLOAT, px.data()));
  auto chan = [&](const char* name) {
    auto it = std::find(spec.channelnames.begin(), spec.channelnames.end(), name);
    EXPECT_NE(it, spec.channelnames.end()) << name;
    return int(it - spec.channelnames.begin());
  };
  int R = chan("R"), G = chan("G"), B = chan("B"), A = chan("A");
  int VR = chan("variance.R"), VB = chan("variance.B");
  for (int y = 0; y < 6; ++y) {
    for (int x = 0; x < 8; ++x) {
      const float* p = &px[size_t(y * 8 + x) * 7];
      RGB e = b.estimate(x, y), v = b.variance_of_mean(x, y);
      // Floats written and read back unchanged: equality up to one float rounding.
      EXPECT_FLOAT_EQ(p[R], e.x);
      EXPECT_FLOAT_EQ(p[G], e.y);
      EXPECT_FLOAT_EQ(p[B], e.z);
      EXPECT_EQ(p[A], 1.0f);
      EXPECT_FLOAT_EQ(p[VR], v.x);
      EXPECT_FLOAT_EQ(p[VB], v.z);
    }
  }
  // Pass estimates of R are base + k, k = 0..3: Var(mean) = (5/3) / 4.
  EXPECT_NEAR(px[size_t(VR)], 5.0 / 12.0, 1e-6);
  EXPECT_EQ(string_attr(spec, "rayfarm:scene_digest"), std::string(64, 'a'));
  EXPECT_EQ(string_attr(spec, "rayfarm:seed"), "42");
  EXPECT_EQ(spec.get_int_attribute("rayfarm:frame", -1), 7);
  EXPECT_EQ(string_attr(spec, "rayfarm:integrator"), "path");
  EXPECT_EQ(string_attr(spec, "rayfarm:settings"), "max_depth=5 spp=4 filter=box");
  EXPECT_EQ(string_attr(spec, "rayfarm:passes"), "0-3");
  EXPECT_EQ(spec.get_int_attribute("rayfarm:spp", -1), 8);  // built-ins win over extras
  EXPECT_EQ(string_attr(spec, "rayfarm:build_id"), "test-build");
  EXPECT_EQ(string_attr(spec, "rayfarm:isa"), "x86_64-avx2");
  EXPECT_NEAR(spec.get_float_attribute("rayfarm:core_seconds", -1), b.header.core_seconds, 1e-6);
  EXPECT_NEAR(spec.get_float_attribute("rayfarm:rel_mse", -1), b.rel_mse(), 1e-6 * b.rel_mse());
  EXPECT_GT(b.rel_mse(), 0.0);
  EXPECT_EQ(string_attr(spec, "rayfarm:variance_estimator"), "batch means over 4 passes");
  EXPECT_EQ(spec.get_int_attribute("rayfarm:nonfinite_samples", -1), 3);
  EXPECT_EQ(string_attr(spec, "rayfarm:job"), "job-17");
}

TEST(ImageIO, ExrOfATileUsesTheDataWindow) {
  std::string dir = test::make_temp_dir("film-exr-tile");
  std::string path = dir + "/tile.exr";
  SampleBuffer b = image_buffer(Rect{2, 1, 4, 3});
  write_exr(path, b);
  auto in = OIIO::ImageInput::open(path);
  ASSERT_TRUE(in) << OIIO::geterror();
  const OIIO::ImageSpec& spec = in->spec();
  EXPECT_EQ(spec.x, 2);
  EXPECT_EQ(spec.y, 1);
  EXPECT_EQ(spec.width, 4);
  EXPECT_EQ(spec.height, 3);
  EXPECT_EQ(spec.full_width, 8);
  EXPECT_EQ(spec.full_height, 6);
  std::vector<float> px(size_t(4 * 3 * 7));
  ASSERT_TRUE(in->read_image(0, 0, 0, 7, OIIO::TypeDesc::FLOAT, px.data()));
  EXPECT_FLOAT_EQ(px[0], b.estimate(2, 1).x);
}

TEST(ImageIO, ExrErrorNamesThePath) {
  SampleBuffer b = image_buffer(Rect{0, 0, 8, 6});
  std::string m = test::error_of([&] { write_exr("/nonexistent-dir/x/frame.exr", b); });
  EXPECT_NE(m.find("/nonexistent-dir/x/frame.exr"), std::string::npos) << m;
  EXPECT_THROW(write_exr("/nonexistent-dir/x/frame.exr", b), ImageIOError);
}

TEST(ImageIO, PngIsSrgbEncoded) {
  std::string dir = test::make_temp_dir("film-png");
  BufferHeader h = test::test_header(PassSet::range(0, 1), 5, 2);
  SampleBuffer b(h, test::full_frame(h), false);
  // Expected bytes from the piecewise sRGB curve: 0.5 -> 0.7354 * 255 = 187.5 -> 188;
  // 0.001 is on the linear segment: 12.92e-3 * 255 = 3.29 -> 3; 2.0 clamps to 255.
  b.add_sample(0, 0, RGB(0.5f, 0.0f, 1.0f));
  b.add_sample(1, 0, RGB(0.001f, 2.0f, 0.18f));
  b.add_sample(2, 0, RGB(std::nanf(""), 0.0f, 0.0f));  // dropped: counts as 0
  b.add_sample(0, 1, RGB(0.25f));
  std::string path = dir + "/preview.png";
  write_png(path, b);
  auto read = [](const std::string& p, int w, int hh) {
    auto in = OIIO::ImageInput::open(p);
    EXPECT_TRUE(in) << OIIO::geterror();
    EXPECT_EQ(in->spec().width, w);
    EXPECT_EQ(in->spec().height, hh);
    EXPECT_EQ(in->spec().nchannels, 3);
    std::vector<uint8_t> px(size_t(w * hh * 3));
    EXPECT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, px.data()));
    return px;
  };
  std::vector<uint8_t> px = read(path, 5, 2);
  EXPECT_EQ(px[0], 188);
  EXPECT_EQ(px[1], 0);
  EXPECT_EQ(px[2], 255);
  EXPECT_EQ(px[3], 3);
  EXPECT_EQ(px[4], 255);
  EXPECT_EQ(px[5], 118);  // 0.18 -> 0.4614 * 255 = 117.7
  EXPECT_EQ(px[6], 0);
  EXPECT_EQ(px[15], 137);  // 0.25 -> 0.5371 * 255 = 137.0
  // One stop up turns 0.25 into 0.5.
  write_png(path, b, 1.0f);
  px = read(path, 5, 2);
  EXPECT_EQ(px[15], 188);
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 1);
}

// The monitor's preview: the estimate averaged over boxes of whole pixels, sRGB-encoded, and a
// PNG in memory that decodes to the same bytes.
TEST(ImageIO, PreviewAveragesBoxesOfPixelsAndEncodesAPng) {
  BufferHeader h = test::test_header(PassSet::range(0, 1), 5, 3);
  SampleBuffer b(h, test::full_frame(h), false);
  // 5x3 at most 2 on a side: boxes of 3x3 pixels, a 2x1 preview; the left box averages 9
  // pixels, the right one the 6 of the last two columns.
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 5; ++x)
      b.add_sample(x, y, RGB(x < 3 ? 0.18f : (x == 4 && y == 2 ? 0.25f : 0.5f), 0.0f, 2.0f));
  Preview p = make_preview(WholeFrame(b), 2);
  EXPECT_EQ(p.box, 3);
  ASSERT_EQ(p.width, 2);
  ASSERT_EQ(p.height, 1);
  ASSERT_EQ(p.rgb.size(), 6u);
  EXPECT_EQ(p.rgb[0], 118);  // 0.18
  EXPECT_EQ(p.rgb[2], 255);  // 2.0 clamps
  // (0.5 * 5 + 0.25) / 6 = 0.4583 -> sRGB 0.7072 * 255 = 180.3 (a box of the right size: a
  // 2x2 box over the same pixels would give another value)
  EXPECT_EQ(p.rgb[3], 180);
  // Small frames are not enlarged.
  EXPECT_EQ(make_preview(WholeFrame(b), 256).width, 5);
  const std::string png = encode_png(p);
  ASSERT_GT(png.size(), 8u);
  EXPECT_EQ(png.substr(1, 3), "PNG");
  std::string dir = test::make_temp_dir("preview-png");
  test::write_text(dir + "/p.png", png);
  auto in = OIIO::ImageInput::open(dir + "/p.png");
  ASSERT_TRUE(in) << OIIO::geterror();
  std::vector<uint8_t> px(6);
  ASSERT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, px.data()));
  EXPECT_EQ(px, p.rgb);
}

// read_rgb gives back what write_exr stored (the estimate, as float).
TEST(ImageIO, ReadRgbReadsTheExrEstimate) {
  BufferHeader h = test::test_header(PassSet::range(0, 1), 5, 3);
  SampleBuffer b(h, test::full_frame(h), false);
  for (int y = 0; y < 3; ++y)
    for (int x = 0; x < 5; ++x) b.add_sample(x, y, RGB(float(x), float(y), 0.25f));
  std::string path = test::make_temp_dir("read-rgb") + "/img.exr";
  write_exr(path, b);
  RgbImage img = read_rgb(path);
  ASSERT_EQ(img.width, 5);
  ASSERT_EQ(img.height, 3);
  EXPECT_EQ(img.rgb[3 * (2 * 5 + 4) + 0], 4.0f);
  EXPECT_EQ(img.rgb[3 * (2 * 5 + 4) + 1], 2.0f);
  EXPECT_EQ(img.rgb[3 * (2 * 5 + 4) + 2], 0.25f);
  EXPECT_NE(test::error_of([] { read_rgb("/nonexistent/x.exr"); }).find("/nonexistent/x.exr"),
            std::string::npos);
}

// rayfarm compare's figures, hand-computed: one pixel of two off by (0.1, 0, 0.2) against a
// reference of (1, 0, 2) and (0, 0, 0): squared errors 0.01 and 0.04 over 6 values.
TEST(ImageIO, ImageErrorHandComputed) {
  RgbImage ref{2, 1, {1, 0, 2, 0, 0, 0}};
  RgbImage img{2, 1, {1.1f, 0, 2.2f, 0, 0, 0}};
  ImageError e = image_error(img, ref);
  double d0 = double(1.1f) - 1, d2 = double(2.2f) - 2;
  EXPECT_DOUBLE_EQ(e.rmse, std::sqrt((d0 * d0 + d2 * d2) / 6));
  EXPECT_DOUBLE_EQ(e.rel_mse, (d0 * d0 / 1.01 + d2 * d2 / 4.01) / 6);
  EXPECT_DOUBLE_EQ(e.mae, (std::fabs(d0) + std::fabs(d2)) / 6);
  // A window over the second pixel alone sees no error.
  ImageError w = image_error(img, ref, PixelWindow{1, 0, 2, 1});
  EXPECT_EQ(w.rmse, 0.0);
  EXPECT_THROW(image_error(img, ref, PixelWindow{1, 0, 3, 1}), std::invalid_argument);
  EXPECT_THROW(image_error(img, ref, PixelWindow{1, 0, 1, 1}), std::invalid_argument);
  EXPECT_THROW(image_error(img, RgbImage{1, 1, {0, 0, 0}}), std::invalid_argument);
}

}  // namespace
}  // namespace rf
