// Image output through OpenImageIO: the multi-channel OpenEXR of a frame (R, G, B, A,
// variance.R/G/B, the AOV layers albedo.R/G/B, N.X/Y/Z, Z and coverage when the frame carries
// them (docs/outputs.md), provenance in the header) and its tone-mapped PNG preview.
#pragma once

#include <map>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/sample_buffer.h"

namespace rf {

struct ImageIOError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Extra provenance attributes ("rayfarm:<key>") besides those taken from the buffer header
// (scene digest, seed, frame, integrator, settings, passes, spp, build id, ISA, core-seconds,
// relMSE and which variance estimator made the variance channels).
using Attributes = std::map<std::string, std::string>;

// The EXR's channels: 32-bit float, or half float (half the file; every channel, variance and
// depth included, rounded to 11 significant bits, finite values above 65504 to infinity).
enum class ExrFormat { Float, Half };

// Writes the frame accumulator as EXR. Written to a temporary file then renamed, so a reader
// never sees half a file. Throws ImageIOError naming the path.
void write_exr(const std::string& path, const SampleBuffer& frame, const Attributes& extra = {},
               ExrFormat format = ExrFormat::Float);
// The same, a band of rows at a time (scanlines), so a frame kept in tiles on disk is never
// whole in memory.
void write_exr(const std::string& path, const FrameBands& frame, const Attributes& extra = {},
               ExrFormat format = ExrFormat::Float);

// sRGB-encoded 8-bit PNG of the estimate scaled by 2^exposure_stops (clamped), written atomically.
void write_png(const std::string& path, const SampleBuffer& frame, float exposure_stops = 0.0f);
void write_png(const std::string& path, const FrameBands& frame, float exposure_stops = 0.0f);

// A small picture of a frame for a monitor (coordinator/monitor.h): the estimate averaged over
// boxes of whole pixels (the same box in x and y, the smallest that brings the longer side to
// at most `max_side`), scaled by 2^exposure_stops, sRGB-encoded 8-bit, row-major RGB. Read a band
// at a time, so a frame kept in tiles is never whole in memory.
struct Preview {
  int width = 0, height = 0;
  int box = 1;               // frame pixels per preview pixel, in x and in y
  std::vector<uint8_t> rgb;  // 3 per pixel
};
Preview make_preview(const FrameBands& frame, int max_side, float exposure_stops = 0.0f);
// The preview as PNG bytes (OpenImageIO, in memory). Throws ImageIOError.
std::string encode_png(const Preview& preview);

// An image's RGB as floats, row-major, 3 per pixel.
struct RgbImage {
  int width = 0, height = 0;
  std::vector<float> rgb;
};
// Reads the first three channels of any image OpenImageIO reads (EXR, PNG, ...). Throws
// ImageIOError naming the path.
RgbImage read_rgb(const std::string& path);

// The error of an image against a reference, over a window of pixels and RGB: root mean square,
// relative MSE (pbrt-v4's convention: squared error / (reference^2 + 0.01), the same as the
// render's noise figure) and mean absolute error.
struct ImageError {
  double rmse = 0, rel_mse = 0, mae = 0;
};
struct PixelWindow {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // half-open
};
// Throws std::invalid_argument when the sizes differ or the window is not inside the image.
ImageError image_error(const RgbImage& image, const RgbImage& reference, PixelWindow window);
ImageError image_error(const RgbImage& image, const RgbImage& reference);  // the whole image

}  // namespace rf
