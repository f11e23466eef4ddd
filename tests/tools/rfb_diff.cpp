// rfb_diff: are two renders the same, plane by plane? Used by tests/golden/check.sh.
//
//   rfb_diff [--tolerance] A.rfb B.rfb        sample buffers: identity header and every plane
//   rfb_diff --exr [--tolerance] A.exr B.exr  EXR windows, channel names and every pixel value
//
// Default: bit-identical (bit patterns of every value, so -0 != +0). --tolerance accepts
// DESIGN.md's merge tolerance |a-b| <= 1e-6 * max(|a|,|b|) + 1e-12 on floating-point values;
// counts stay exact. Ignored: build_id, isa and core_seconds of a buffer (they differ by build and
// timing) and every EXR header attribute (provenance). `rays` is a diagnostic counter: printed
// when it differs, never a failure.
// Prints one line per difference (or "identical"); exit 0 equal, 1 different, 2 error.
//
//   rfb_diff [--exr] [--tolerance] --pairs LIST  many pairs in one process: LIST holds one pair
//                                                a line ("A B", paths without spaces); prints
//                                                each differing pair with its differences, then
//                                                a count. Used by bench/soak.sh.
#include <OpenImageIO/imageio.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "engine/buffer_file.h"

namespace {

// Where the values of a plane sit: pixel (x0 + p % width, y0 + p / width) holds
// channels.size() values.
struct Layout {
  int x0 = 0, y0 = 0, width = 1;
  std::vector<std::string> channels;
};

struct Comparison {
  bool tolerance = false;
  bool different = false;
  size_t bitwise_only = 0;  // values that differ bitwise but are within the tolerance
  double bitwise_max_rel = 0;

  bool buffered = false;  // --pairs: lines kept in `lines`, printed only for a differing pair
  std::string lines;

  void fail(const std::string& line) {
    different = true;
    if (buffered)
      lines += line + "\n";
    else
      std::printf("%s\n", line.c_str());
  }
};

template <class T>
bool same_bits(T a, T b) {
  return std::memcmp(&a, &b, sizeof(T)) == 0;
}

double rel_diff(double a, double b) {
  double m = std::max(std::fabs(a), std::fabs(b));
  return m > 0 ? std::fabs(a - b) / m : 0.0;
}

bool within_tolerance(double a, double b) {
  return std::isfinite(a) && std::isfinite(b) &&
         std::fabs(a - b) <= 1e-6 * std::max(std::fabs(a), std::fabs(b)) + 1e-12;
}

std::string number_text(double v) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.17g", v);
  return buf;
}

// Compares one plane value by value; one line when it differs: how many values, the first
// differing pixel and channel, the largest absolute and relative difference.
template <class T>
void compare_plane(const std::string& name, const std::vector<T>& a, const std::vector<T>& b,
                   const Layout& layout, Comparison& cmp) {
  if (a.size() != b.size()) {
    cmp.fail(name + ": sizes differ (" + std::to_string(a.size()) + " vs " +
             std::to_string(b.size()) + " values)");
    return;
  }
  constexpr bool floating = std::is_floating_point_v<T>;
  size_t differ = 0, first = 0;
  double max_abs = 0, max_rel = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (same_bits(a[i], b[i])) continue;
    double x = double(a[i]), y = double(b[i]);
    if (floating && cmp.tolerance && within_tolerance(x, y)) {
      ++cmp.bitwise_only;
      cmp.bitwise_max_rel = std::max(cmp.bitwise_max_rel, rel_diff(x, y));
      continue;
    }
    if (differ++ == 0) first = i;
    max_abs = std::max(max_abs, std::fabs(x - y));
    max_rel = std::max(max_rel, rel_diff(x, y));
  }
  if (differ == 0) return;
  size_t nch = layout.channels.size(), pixel = first / nch;
  int x = layout.x0 + int(pixel % size_t(layout.width));
  int y = layout.y0 + int(pixel / size_t(layout.width));
  cmp.fail(name + ": " + std::to_string(differ) + " of " + std::to_string(a.size()) +
           " values differ; first at pixel (" + std::to_string(x) + "," + std::to_string(y) + ") " +
           layout.channels[first % nch] + ": " + number_text(double(a[first])) + " vs " +
           number_text(double(b[first])) + "; max abs diff " + number_text(max_abs) +
           ", max rel diff " + number_text(max_rel));
}

template <class T>
void compare_field(const std::string& name, const T& a, const T& b, Comparison& cmp) {
  if (a == b) return;
  if constexpr (std::is_same_v<T, std::string>)
    cmp.fail("header " + name + ": '" + a + "' vs '" + b + "'");
  else
    cmp.fail("header " + name + ": " + std::to_string(a) + " vs " + std::to_string(b));
}

std::string rect_text(const rf::Rect& r) {
  return std::to_string(r.x0) + "," + std::to_string(r.y0) + " " + std::to_string(r.w) + "x" +
         std::to_string(r.h);
}

void compare_buffers(const std::string& path_a, const std::string& path_b, Comparison& cmp) {
  rf::SampleBuffer a = rf::read_buffer_file(path_a), b = rf::read_buffer_file(path_b);
  const rf::BufferHeader &ha = a.header, &hb = b.header;
  compare_field("scene_digest", ha.scene_digest, hb.scene_digest, cmp);
  compare_field("seed", ha.seed, hb.seed, cmp);
  compare_field("frame", ha.frame, hb.frame, cmp);
  compare_field("integrator", ha.integrator, hb.integrator, cmp);
  compare_field("settings", ha.settings, hb.settings, cmp);
  compare_field("width", ha.width, hb.width, cmp);
  compare_field("height", ha.height, hb.height, cmp);
  compare_field("passes", ha.passes.to_string(), hb.passes.to_string(), cmp);
  compare_field("rect", rect_text(a.rect), rect_text(b.rect), cmp);
  compare_field("light_paths", a.light_paths, b.light_paths, cmp);
  compare_field("nonfinite_samples", a.nonfinite_samples, b.nonfinite_samples, cmp);
  if (a.rays != b.rays)
    std::printf("note: rays differ (%llu vs %llu), a diagnostic counter, not compared\n",
                (unsigned long long)a.rays, (unsigned long long)b.rays);

  Layout px{a.rect.x0, a.rect.y0, std::max(a.rect.w, 1), {"count"}};
  compare_plane("count", a.count, b.count, px, cmp);
  px.channels = {"R", "G", "B"};
  compare_plane("sum", a.sum, b.sum, px, cmp);
  compare_plane("sum_sq", a.sum_sq, b.sum_sq, px, cmp);
  compare_plane("batch_sum", a.batch_sum, b.batch_sum, px, cmp);
  compare_plane("batch_sum_sq", a.batch_sum_sq, b.batch_sum_sq, px, cmp);
  Layout frame{0, 0, std::max(ha.width, 1), {"R", "G", "B"}};
  compare_plane("splat", a.splat, b.splat, frame, cmp);
}

struct Image {
  OIIO::ImageSpec spec;
  std::vector<float> px;
};

Image read_image(const std::string& path) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) throw std::runtime_error(path + ": cannot open: " + OIIO::geterror());
  Image img{in->spec(), {}};
  if (img.spec.depth != 1) throw std::runtime_error(path + ": volume images are not supported");
  img.px.resize(img.spec.image_pixels() * size_t(img.spec.nchannels));
  if (!in->read_image(0, 0, 0, img.spec.nchannels, OIIO::TypeDesc::FLOAT, img.px.data()))
    throw std::runtime_error(path + ": " + in->geterror());
  return img;
}

std::string window_text(int x, int y, int w, int h) { return rect_text(rf::Rect{x, y, w, h}); }

void compare_exrs(const std::string& path_a, const std::string& path_b, Comparison& cmp) {
  Image a = read_image(path_a), b = read_image(path_b);
  const OIIO::ImageSpec &sa = a.spec, &sb = b.spec;
  compare_field("data window", window_text(sa.x, sa.y, sa.width, sa.height),
                window_text(sb.x, sb.y, sb.width, sb.height), cmp);
  compare_field("display window", window_text(sa.full_x, sa.full_y, sa.full_width, sa.full_height),
                window_text(sb.full_x, sb.full_y, sb.full_width, sb.full_height), cmp);
  std::string names_a, names_b;
  for (const auto& n : sa.channelnames) names_a += n + " ";
  for (const auto& n : sb.channelnames) names_b += n + " ";
  compare_field("channels", names_a, names_b, cmp);
  if (cmp.different) return;  // pixel values would not line up
  compare_plane("pixels", a.px, b.px, Layout{sa.x, sa.y, sa.width, sa.channelnames}, cmp);
}

int usage() {
  std::fprintf(stderr,
               "usage: rfb_diff [--tolerance] A.rfb B.rfb\n"
               "       rfb_diff --exr [--tolerance] A.exr B.exr\n"
               "       rfb_diff [--exr] [--tolerance] --pairs LIST   (a pair \"A B\" a line)\n"
               "exit 0: equal, 1: different, 2: error\n");
  return 2;
}

}  // namespace

// --pairs: every pair of the list; 0 all equal, 1 some differ, 2 an error (a missing file too).
int compare_pairs(const std::string& list, bool exr, bool tolerance) {
  std::ifstream in(list);
  if (!in) {
    std::fprintf(stderr, "rfb_diff: error: %s: cannot open\n", list.c_str());
    return 2;
  }
  size_t pairs = 0, different = 0, errors = 0, line_no = 0;
  for (std::string line; std::getline(in, line);) {
    ++line_no;
    std::istringstream words(line);
    std::string a, b, extra;
    if (!(words >> a)) continue;  // a blank line
    if (!(words >> b) || (words >> extra)) {
      std::fprintf(stderr, "rfb_diff: error: %s:%zu: expected two paths\n", list.c_str(), line_no);
      return 2;
    }
    ++pairs;
    Comparison cmp;
    cmp.tolerance = tolerance;
    cmp.buffered = true;
    try {
      exr ? compare_exrs(a, b, cmp) : compare_buffers(a, b, cmp);
      if (cmp.different) {
        ++different;
        std::printf("%s %s differ:\n%s", a.c_str(), b.c_str(), cmp.lines.c_str());
      }
    } catch (const std::exception& e) {
      std::printf("%s %s: error: %s\n", a.c_str(), b.c_str(), e.what());
      ++errors;
    }
  }
  std::printf("%zu pairs: %zu equal, %zu different, %zu errors\n", pairs,
              pairs - different - errors, different, errors);
  return errors ? 2 : different ? 1 : 0;
}

int main(int argc, char** argv) {
  Comparison cmp;
  bool exr = false;
  std::string pairs;
  std::vector<std::string> files;
  for (int i = 1; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg == "--tolerance")
      cmp.tolerance = true;
    else if (arg == "--exr")
      exr = true;
    else if (arg == "--pairs" && i + 1 < argc)
      pairs = argv[++i];
    else if (arg.starts_with("-"))
      return usage();
    else
      files.push_back(arg);
  }
  if (!pairs.empty()) return files.empty() ? compare_pairs(pairs, exr, cmp.tolerance) : usage();
  if (files.size() != 2) return usage();
  try {
    if (exr)
      compare_exrs(files[0], files[1], cmp);
    else
      compare_buffers(files[0], files[1], cmp);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "rfb_diff: error: %s\n", e.what());
    return 2;
  }
  if (cmp.different) return 1;
  if (cmp.bitwise_only)
    std::printf("equal within tolerance (%zu values differ bitwise, max rel diff %s)\n",
                cmp.bitwise_only, number_text(cmp.bitwise_max_rel).c_str());
  else
    std::printf("identical\n");
  return 0;
}
