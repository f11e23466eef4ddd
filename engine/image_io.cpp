// Image output through OpenImageIO (DESIGN.md "Sample buffers and variance", "Outputs").
//
// EXR: 32-bit float channels R, G, B, A (= 1), variance.R, variance.G, variance.B, where variance
// is the batch-means variance of the mean (zero with fewer than 2 passes). A buffer whose rect is
// a tile is written as the EXR data window (rect) inside the display window (the full frame), so
// tiles load in place in any EXR viewer. Provenance goes in "rayfarm:*" header attributes; the
// caller's extra attributes are written first so the built-in ones cannot be overridden.
// EXR has only 32-bit int attributes: the seed is a decimal string, and counts (spp,
// nonfinite_samples) are ints when they fit, else a float (spp) or a decimal string.
//
// PNG: 8-bit sRGB (piecewise sRGB transfer) of the rect's pixels, estimate * 2^stops clamped to
// [0, 1]. A PNG has no data window, so a tile's PNG is just the tile.
//
// Both are written to a hidden temporary file beside the target, fsynced and renamed over it.
#include "engine/image_io.h"

#include <fcntl.h>
#include <unistd.h>

#include <OpenImageIO/filesystem.h>
#include <OpenImageIO/imageio.h>

#include <atomic>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <limits>
#include <vector>

#include "engine/build_info.h"

namespace rf {
namespace {

namespace fs = std::filesystem;
using OIIO::ImageOutput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

void fsync_path(const fs::path& p, int flags) {
  int fd = ::open(p.empty() ? "." : p.c_str(), flags);
  if (fd >= 0) {
    ::fsync(fd);
    ::close(fd);
  }
}

// Writes an image through OIIO's `format` plugin into a temporary file (`body` writes its pixels,
// returning false on failure), then fsync + rename + fsync of the directory: readers see the old
// file or the whole new one.
void write_image_atomic(const std::string& path, const char* format, const ImageSpec& spec,
                        const std::function<bool(ImageOutput&)>& body) {
  static std::atomic<uint64_t> counter{0};
  fs::path target(path);
  fs::path tmp =
      target.parent_path() / ("." + target.filename().string() + ".tmp-" +
                              std::to_string(::getpid()) + "-" + std::to_string(counter++));
  auto out = ImageOutput::create(format);
  if (!out) {
    throw ImageIOError(path + ": cannot create " + format + " writer: " + OIIO::geterror());
  }
  bool ok = false;
  std::string err;
  try {
    ok = out->open(tmp.string(), spec) && body(*out) && out->close();
  } catch (const std::exception& e) {
    err = e.what();
  }
  if (!ok) {
    if (err.empty()) err = out->geterror();
    out.reset();
    std::error_code ec;
    fs::remove(tmp, ec);
    throw ImageIOError(path + ": " + (err.empty() ? std::string("write failed") : err));
  }
  out.reset();
  fsync_path(tmp, O_RDONLY);
  std::error_code ec;
  fs::rename(tmp, target, ec);
  if (ec) {
    fs::remove(tmp, ec);
    throw ImageIOError(path + ": cannot rename temporary file into place: " + ec.message());
  }
  fsync_path(target.parent_path(), O_RDONLY | O_DIRECTORY);
}

// Calls write_rows(band) for each band of the frame in order, with `pixels` sized for the band's
// rows; each band's rows go out as scanlines, so the image is never whole in memory.
template <class T, class F>
bool write_bands(ImageOutput& out, const FrameBands& frame, int channels, F&& write_rows) {
  const Rect& r = frame.info().rect;
  std::vector<T> pixels;
  for (int y0 = r.y0; y0 < r.y1(); y0 += frame.band_height()) {
    const SampleBuffer& band = frame.band(y0);
    int y1 = std::min(r.y1(), y0 + frame.band_height());
    pixels.clear();
    pixels.reserve(size_t(y1 - y0) * size_t(r.w) * size_t(channels));
    write_rows(band, y0, y1, pixels);
    if (!out.write_scanlines(y0, y1, 0, TypeDesc(OIIO::BaseTypeFromC<T>::value), pixels.data()))
      return false;
  }
  return true;
}

void check_writable(const std::string& path, const FrameBands& frame) {
  const SampleBuffer& info = frame.info();
  if (info.rect.area() <= 0) throw ImageIOError(path + ": nothing to write (empty rect)");
  const SampleBuffer& first = frame.band(info.rect.y0);
  if (first.count.size() != size_t(first.rect.area()) || first.rect.x0 != info.rect.x0 ||
      first.rect.w != info.rect.w) {
    throw ImageIOError(path + ": sample buffer planes do not match its rect");
  }
}

// An integer attribute when the value fits EXR's 32-bit int, else a decimal string.
void count_attribute(ImageSpec& spec, const std::string& name, uint64_t v) {
  if (v <= uint64_t(std::numeric_limits<int>::max())) {
    spec.attribute(name, int(v));
  } else {
    spec.attribute(name, std::to_string(v));
  }
}

void double_attribute(ImageSpec& spec, const std::string& name, double v) {
  spec.attribute(name, TypeDesc::DOUBLE, &v);
}

void provenance_attributes(ImageSpec& spec, const FrameBands& bands, const Attributes& extra) {
  for (const auto& [k, v] : extra) spec.attribute("rayfarm:" + k, v);
  const SampleBuffer& frame = bands.info();
  const BufferHeader& h = frame.header;
  spec.attribute("rayfarm:scene_digest", h.scene_digest);
  spec.attribute("rayfarm:seed", std::to_string(h.seed));  // u64 does not fit an EXR int
  count_attribute(spec, "rayfarm:frame", h.frame);
  spec.attribute("rayfarm:integrator", h.integrator);
  spec.attribute("rayfarm:settings", h.settings);
  if (h.aovs.any()) spec.attribute("rayfarm:aovs", to_string(h.aovs));
  spec.attribute("rayfarm:passes", h.passes.to_string());
  // Splatting integrators take no camera samples: their "spp" is light paths per pixel.
  uint64_t pixels = uint64_t(frame.rect.area());
  uint64_t samples = bands.total_samples() ? bands.total_samples() : frame.light_paths;
  if (samples % pixels == 0) {
    count_attribute(spec, "rayfarm:spp", samples / pixels);
  } else {
    double_attribute(spec, "rayfarm:spp", double(samples) / double(pixels));
  }
  spec.attribute("rayfarm:build_id", h.build_id);
  spec.attribute("rayfarm:isa", h.isa);
  spec.attribute("rayfarm:writer_build_id", build_id());
  double_attribute(spec, "rayfarm:core_seconds", h.core_seconds);
  double_attribute(spec, "rayfarm:rel_mse", bands.rel_mse());
  uint32_t n = h.passes.count();
  spec.attribute("rayfarm:variance_estimator",
                 n >= 2 ? "batch means over " + std::to_string(n) + " passes"
                        : std::string("none (fewer than 2 passes; variance channels are zero)"));
  count_attribute(spec, "rayfarm:nonfinite_samples", frame.nonfinite_samples);
}

// The piecewise sRGB transfer (IEC 61966-2-1) of a linear value, clamped to [0, 1] (NaN -> 0).
uint8_t srgb8(double linear) {
  double v = linear > 0.0 ? std::min(linear, 1.0) : 0.0;
  double s = v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
  return uint8_t(std::lround(s * 255.0));
}

}  // namespace

void write_exr(const std::string& path, const SampleBuffer& frame, const Attributes& extra,
               ExrFormat format) {
  write_exr(path, WholeFrame(frame), extra, format);
}

void write_exr(const std::string& path, const FrameBands& frame, const Attributes& extra,
               ExrFormat format) {
  check_writable(path, frame);
  const Rect& r = frame.info().rect;
  const AovSet& aovs = frame.info().header.aovs;
  std::vector<std::string> names = {"R", "G", "B", "A", "variance.R", "variance.G", "variance.B"};
  if (aovs.albedo) names.insert(names.end(), {"albedo.R", "albedo.G", "albedo.B"});
  if (aovs.normal) names.insert(names.end(), {"N.X", "N.Y", "N.Z"});
  if (aovs.depth) names.insert(names.end(), {"Z", "coverage"});
  const int nch = int(names.size());
  ImageSpec spec(r.w, r.h, nch, format == ExrFormat::Half ? TypeDesc::HALF : TypeDesc::FLOAT);
  spec.x = r.x0;
  spec.y = r.y0;
  spec.full_x = 0;
  spec.full_y = 0;
  spec.full_width = frame.info().header.width;
  spec.full_height = frame.info().header.height;
  spec.channelnames = names;
  spec.alpha_channel = 3;
  spec.attribute("compression", "zip");
  spec.attribute("oiio:ColorSpace", "Linear");
  provenance_attributes(spec, frame, extra);

  write_image_atomic(path, "openexr", spec, [&](ImageOutput& out) {
    return write_bands<float>(
        out, frame, nch, [&](const SampleBuffer& band, int y0, int y1, std::vector<float>& pixels) {
          for (int y = y0; y < y1; ++y) {
            for (int x = r.x0; x < r.x1(); ++x) {
              RGB e = band.estimate(x, y), v = band.variance_of_mean(x, y);
              pixels.insert(pixels.end(), {e.x, e.y, e.z, 1.0f, v.x, v.y, v.z});
              if (!aovs.any()) continue;
              float coverage = 0;
              AovSample m = band.aov_mean(x, y, &coverage);
              if (aovs.albedo) pixels.insert(pixels.end(), {m.albedo.x, m.albedo.y, m.albedo.z});
              if (aovs.normal) pixels.insert(pixels.end(), {m.normal.x, m.normal.y, m.normal.z});
              if (aovs.depth) pixels.insert(pixels.end(), {m.depth, coverage});
            }
          }
        });
  });
}

void write_png(const std::string& path, const SampleBuffer& frame, float exposure_stops) {
  write_png(path, WholeFrame(frame), exposure_stops);
}

void write_png(const std::string& path, const FrameBands& frame, float exposure_stops) {
  check_writable(path, frame);
  const Rect& r = frame.info().rect;
  ImageSpec spec(r.w, r.h, 3, TypeDesc::UINT8);
  spec.attribute("oiio:ColorSpace", "sRGB");
  spec.attribute("Software", build_id());
  double scale = std::exp2(double(exposure_stops));
  write_image_atomic(path, "png", spec, [&](ImageOutput& out) {
    return write_bands<uint8_t>(
        out, frame, 3, [&](const SampleBuffer& band, int y0, int y1, std::vector<uint8_t>& pixels) {
          for (int y = y0; y < y1; ++y) {
            for (int x = r.x0; x < r.x1(); ++x) {
              RGB e = band.estimate(x, y);
              for (int c = 0; c < 3; ++c) pixels.push_back(srgb8(double(e[c]) * scale));
            }
          }
        });
  });
}

Preview make_preview(const FrameBands& frame, int max_side, float exposure_stops) {
  const Rect& r = frame.info().rect;
  Preview p;
  if (r.w <= 0 || r.h <= 0 || max_side <= 0) return p;
  p.box = std::max(1, (std::max(r.w, r.h) + max_side - 1) / max_side);
  p.width = (r.w + p.box - 1) / p.box;
  p.height = (r.h + p.box - 1) / p.box;
  std::vector<double> sum(size_t(p.width) * size_t(p.height) * 3, 0.0);
  std::vector<uint32_t> count(size_t(p.width) * size_t(p.height), 0);
  for (int y0 = r.y0; y0 < r.y1(); y0 += frame.band_height()) {
    const SampleBuffer& band = frame.band(y0);
    const int y1 = std::min(y0 + frame.band_height(), r.y1());
    for (int y = y0; y < y1; ++y) {
      const size_t row = size_t((y - r.y0) / p.box) * size_t(p.width);
      for (int x = r.x0; x < r.x1(); ++x) {
        const size_t i = row + size_t((x - r.x0) / p.box);
        RGB e = band.estimate(x, y);
        for (int c = 0; c < 3; ++c)
          if (std::isfinite(e[c])) sum[3 * i + size_t(c)] += double(e[c]);
        ++count[i];
      }
    }
  }
  const double scale = std::exp2(double(exposure_stops));
  p.rgb.resize(sum.size());
  for (size_t i = 0; i < count.size(); ++i)
    for (size_t c = 0; c < 3; ++c)
      p.rgb[3 * i + c] = srgb8(count[i] ? sum[3 * i + c] / count[i] * scale : 0.0);
  return p;
}

std::string encode_png(const Preview& p) {
  ImageSpec spec(p.width, p.height, 3, TypeDesc::UINT8);
  spec.attribute("oiio:ColorSpace", "sRGB");
  std::vector<unsigned char> bytes;
  OIIO::Filesystem::IOVecOutput sink(bytes);
  auto out = ImageOutput::create("png");
  if (!out) throw ImageIOError("PNG preview: " + OIIO::geterror());
  out->set_ioproxy(&sink);
  if (!out->open("preview.png", spec) || !out->write_image(TypeDesc::UINT8, p.rgb.data()) ||
      !out->close())
    throw ImageIOError("PNG preview: " + out->geterror());
  return std::string(bytes.begin(), bytes.end());
}

RgbImage read_rgb(const std::string& path) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) throw ImageIOError(path + ": cannot open: " + OIIO::geterror());
  const ImageSpec& spec = in->spec();
  if (spec.nchannels < 3) throw ImageIOError(path + ": needs at least 3 channels");
  RgbImage img;
  img.width = spec.width, img.height = spec.height;
  img.rgb.resize(size_t(img.width) * size_t(img.height) * 3);
  if (!in->read_image(0, 0, 0, 3, TypeDesc::FLOAT, img.rgb.data()))
    throw ImageIOError(path + ": " + in->geterror());
  return img;
}

ImageError image_error(const RgbImage& a, const RgbImage& b, PixelWindow win) {
  if (a.width != b.width || a.height != b.height)
    throw std::invalid_argument("the image is " + std::to_string(a.width) + "x" +
                                std::to_string(a.height) + ", the reference " +
                                std::to_string(b.width) + "x" + std::to_string(b.height));
  if (win.x0 < 0 || win.y0 < 0 || win.x1 > a.width || win.y1 > a.height || win.x0 >= win.x1 ||
      win.y0 >= win.y1)
    throw std::invalid_argument("the window must satisfy 0 <= X0 < X1 <= " +
                                std::to_string(a.width) + " and 0 <= Y0 < Y1 <= " +
                                std::to_string(a.height));
  double se = 0, rel = 0, abs_err = 0;
  for (int y = win.y0; y < win.y1; ++y)
    for (int x = win.x0; x < win.x1; ++x)
      for (int c = 0; c < 3; ++c) {
        size_t i = (size_t(y) * size_t(a.width) + size_t(x)) * 3 + size_t(c);
        double d = double(a.rgb[i]) - double(b.rgb[i]);
        se += d * d;
        rel += relative_error(d * d, double(b.rgb[i]));
        abs_err += std::fabs(d);
      }
  double n = double(win.x1 - win.x0) * double(win.y1 - win.y0) * 3;
  return {std::sqrt(se / n), rel / n, abs_err / n};
}

ImageError image_error(const RgbImage& image, const RgbImage& reference) {
  return image_error(image, reference, PixelWindow{0, 0, image.width, image.height});
}

}  // namespace rf
