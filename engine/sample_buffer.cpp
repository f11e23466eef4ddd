#include "engine/sample_buffer.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "engine/filter.h"
#include "engine/scene.h"

namespace rf {

std::string to_string(const Rect& r) {
  return std::to_string(r.w) + "x" + std::to_string(r.h) + " at (" + std::to_string(r.x0) + "," +
         std::to_string(r.y0) + ")";
}

namespace {

size_t frame_channels(const BufferHeader& h) { return 3 * size_t(h.width) * size_t(h.height); }

using RGBd = std::array<double, 3>;

// Camera mean sum / count plus splat / light paths, in double.
RGBd estimate_at(const SampleBuffer& b, int x, int y) {
  size_t i = b.pixel_index(x, y);
  RGBd e{};
  uint64_t n = b.count[i];
  for (int c = 0; c < 3; ++c) e[c] = n ? b.sum[3 * i + c] / double(n) : 0.0;
  if (!b.splat.empty() && b.light_paths > 0) {
    size_t f = size_t(y) * size_t(b.header.width) + size_t(x);
    for (int c = 0; c < 3; ++c) e[c] += b.splat[3 * f + c] / double(b.light_paths);
  }
  return e;
}

// Batch means over n passes: m = S/n, s^2 = (Q - n m^2) / (n - 1) clamped at 0, Var(mean) = s^2/n.
RGBd variance_at(const SampleBuffer& b, int x, int y) {
  RGBd v{};
  double n = double(b.header.passes.count());
  if (n < 2) return v;
  size_t i = b.pixel_index(x, y);
  for (int c = 0; c < 3; ++c) {
    double m = b.batch_sum[3 * i + c] / n;
    double s2 = (b.batch_sum_sq[3 * i + c] - n * m * m) / (n - 1);
    v[c] = std::max(0.0, s2) / n;
  }
  return v;
}

RGB to_rgb(const RGBd& v) { return RGB(float(v[0]), float(v[1]), float(v[2])); }

}  // namespace

SampleBuffer::SampleBuffer(BufferHeader h, Rect r, bool with_splats)
    : header(std::move(h)), rect(r) {
  if (r.w < 0 || r.h < 0 || !Rect{0, 0, header.width, header.height}.contains(r)) {
    throw std::invalid_argument("sample buffer rect " + to_string(r) + " is not inside the " +
                                std::to_string(header.width) + "x" + std::to_string(header.height) +
                                " frame");
  }
  size_t a = size_t(r.area());
  count.assign(a, 0);
  sum.assign(3 * a, 0.0);
  sum_sq.assign(3 * a, 0.0);
  batch_sum.assign(3 * a, 0.0);
  batch_sum_sq.assign(3 * a, 0.0);
  if (with_splats) splat.assign(frame_channels(header), 0.0);
  aov.assign(size_t(header.aovs.channels()) * a, 0.0);
}

void SampleBuffer::add_aov_sample(int x, int y, const AovSample& s) {
  const AovSet& set = header.aovs;
  double* px = aov.data() + pixel_index(x, y) * size_t(set.channels());
  px[0] += 1;
  if (set.albedo && is_finite(s.albedo))
    for (int c = 0; c < 3; ++c) px[set.albedo_offset() + c] += s.albedo[c];
  if (set.normal && is_finite(s.normal))
    for (int c = 0; c < 3; ++c) px[set.normal_offset() + c] += s.normal[c];
  if (set.depth && s.hit && std::isfinite(s.depth)) {
    px[set.depth_offset()] += s.depth;
    px[set.depth_offset() + 1] += 1;
  }
}

AovSample SampleBuffer::aov_mean(int x, int y, float* coverage) const {
  const AovSet& set = header.aovs;
  AovSample m;
  if (coverage) *coverage = 0;
  if (!set.any()) return m;
  const double* px = aov.data() + pixel_index(x, y) * size_t(set.channels());
  if (!(px[0] > 0)) return m;
  for (int c = 0; c < 3; ++c) {
    if (set.albedo) m.albedo[c] = float(px[set.albedo_offset() + c] / px[0]);
    if (set.normal) m.normal[c] = float(px[set.normal_offset() + c] / px[0]);
  }
  if (set.depth && px[set.depth_offset() + 1] > 0) {
    m.hit = true;
    m.depth = float(px[set.depth_offset()] / px[set.depth_offset() + 1]);
    if (coverage) *coverage = float(px[set.depth_offset() + 1] / px[0]);
  }
  return m;
}

// A filter footprint may reach past the frame border: those pixels are not stored. A non-finite
// splat is counted (once per call) and dropped.
void SampleBuffer::add_splat(int x, int y, RGB weighted_radiance) {
  assert(!splat.empty() && "add_splat on a buffer without a splat plane");
  if (!is_finite(weighted_radiance)) {
    ++nonfinite_samples;
    return;
  }
  if (splat.empty() || x < 0 || y < 0 || x >= header.width || y >= header.height) return;
  size_t f = size_t(y) * size_t(header.width) + size_t(x);
  for (int c = 0; c < 3; ++c) splat[3 * f + c] += double(weighted_radiance[c]);
}

void SampleBuffer::add_splats(const std::vector<Splat>& splats) {
  const uint32_t w = uint32_t(header.width);
  for (const Splat& s : splats) add_splat(int(s.pixel % w), int(s.pixel / w), s.value);
}

void splat_to_film(SplatTarget& t, Vec2 raster, RGB value) {
  if (!is_finite(value) || is_black(value)) return;
  const FilterSettings& f = *t.filter;
  value *= float(t.width) * float(t.height);
  int x0 = std::max(0, int(std::floor(raster.x - f.radius - 0.5f)));
  int x1 = std::min(t.width - 1, int(std::floor(raster.x + f.radius - 0.5f)) + 1);
  int y0 = std::max(0, int(std::floor(raster.y - f.radius - 0.5f)));
  int y1 = std::min(t.height - 1, int(std::floor(raster.y + f.radius - 0.5f)) + 1);
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      Vec2 d{raster.x - (float(x) + 0.5f), raster.y - (float(y) + 0.5f)};
      if (f.type == FilterType::Box &&
          (d.x < -f.radius || d.x >= f.radius || d.y < -f.radius || d.y >= f.radius))
        continue;
      float w = filter_weight(f, d);
      if (w == 0) continue;
      t.out->push_back({uint32_t(y) * uint32_t(t.width) + uint32_t(x), value * w});
    }
}

void SampleBuffer::finish_pass() {
  if (header.passes.count() != 1) {
    throw std::logic_error("finish_pass needs a buffer of exactly one pass, this one holds \"" +
                           header.passes.to_string() + "\"");
  }
  for (int y = rect.y0; y < rect.y1(); ++y) {
    for (int x = rect.x0; x < rect.x1(); ++x) {
      size_t i = pixel_index(x, y);
      RGBd e = estimate_at(*this, x, y);
      for (int c = 0; c < 3; ++c) {
        batch_sum[3 * i + c] = e[c];
        batch_sum_sq[3 * i + c] = e[c] * e[c];
      }
    }
  }
}

RGB SampleBuffer::estimate(int x, int y) const { return to_rgb(estimate_at(*this, x, y)); }

RGB SampleBuffer::variance_of_mean(int x, int y) const { return to_rgb(variance_at(*this, x, y)); }

double rel_mse_sum(const SampleBuffer& b, const Rect& region, double total) {
  for (int y = region.y0; y < region.y1(); ++y) {
    for (int x = region.x0; x < region.x1(); ++x) {
      RGBd m = estimate_at(b, x, y), v = variance_at(b, x, y);
      for (int c = 0; c < 3; ++c) total += relative_error(v[c], m[c]);
    }
  }
  return total;
}

double rel_mse_of_bands(const FrameBands& frame) {
  const Rect& r = frame.info().rect;
  double total = 0;
  for (int y0 = r.y0; y0 < r.y1(); y0 += frame.band_height()) {
    const SampleBuffer& b = frame.band(y0);
    total = rel_mse_sum(b, b.rect, total);
  }
  return r.area() > 0 ? total / (3.0 * double(r.area())) : 0.0;
}

double SampleBuffer::rel_mse() const {
  if (rect.area() == 0) return 0.0;
  return rel_mse_sum(*this, rect) / (3.0 * double(rect.area()));
}

RGB SampleBuffer::mean_estimate() const {
  if (rect.area() == 0) return RGB(0.0f);
  RGBd total{};
  for (int y = rect.y0; y < rect.y1(); ++y) {
    for (int x = rect.x0; x < rect.x1(); ++x) {
      RGBd e = estimate_at(*this, x, y);
      for (int c = 0; c < 3; ++c) total[c] += e[c];
    }
  }
  for (double& t : total) t /= double(rect.area());
  return to_rgb(total);
}

uint64_t SampleBuffer::total_samples() const { return BufferView(*this).total_samples(); }

bool SampleBuffer::planes_match_rect() const { return BufferView(*this).planes_match_rect(); }

BufferView::BufferView(const SampleBuffer& b)
    : header(&b.header),
      rect(b.rect),
      count(b.count),
      sum(b.sum),
      sum_sq(b.sum_sq),
      batch_sum(b.batch_sum),
      batch_sum_sq(b.batch_sum_sq),
      splat(b.splat),
      aov(b.aov),
      light_paths(b.light_paths),
      nonfinite_samples(b.nonfinite_samples),
      rays(b.rays) {}

uint64_t BufferView::total_samples() const {
  uint64_t n = 0;
  for (uint64_t c : count) n += c;
  return n;
}

bool BufferView::planes_match_rect() const {
  if (rect.w < 0 || rect.h < 0) return false;
  size_t a = size_t(rect.area());
  return count.size() == a && sum.size() == 3 * a && sum_sq.size() == 3 * a &&
         batch_sum.size() == 3 * a && batch_sum_sq.size() == 3 * a &&
         aov.size() == size_t(header->aovs.channels()) * a &&
         (splat.empty() || splat.size() == frame_channels(*header));
}

SampleBuffer BufferView::copy() const {
  SampleBuffer b;
  b.header = *header;
  b.rect = rect;
  b.count.assign(count.begin(), count.end());
  b.sum.assign(sum.begin(), sum.end());
  b.sum_sq.assign(sum_sq.begin(), sum_sq.end());
  b.batch_sum.assign(batch_sum.begin(), batch_sum.end());
  b.batch_sum_sq.assign(batch_sum_sq.begin(), batch_sum_sq.end());
  b.splat.assign(splat.begin(), splat.end());
  b.aov.assign(aov.begin(), aov.end());
  b.light_paths = light_paths;
  b.nonfinite_samples = nonfinite_samples;
  b.rays = rays;
  return b;
}

namespace {

std::string samples_problem(const BufferView& b, uint64_t spp_per_pass, double max_core_seconds) {
  if (!b.planes_match_rect()) return "its planes do not match its rect";
  const double cs = b.header->core_seconds;
  if (!std::isfinite(cs) || cs < 0 || cs > max_core_seconds)
    return "core_seconds " + std::to_string(cs) + " is outside 0.." +
           std::to_string(max_core_seconds);
  const uint64_t samples = b.total_samples();
  const uint64_t frame_pixels = uint64_t(b.header->width) * uint64_t(b.header->height);
  if (samples == 0 && !b.splat.empty()) {
    if (b.light_paths != spp_per_pass * frame_pixels)
      return std::to_string(b.light_paths) + " light paths, not the pass's " +
             std::to_string(spp_per_pass * frame_pixels);
  } else {
    for (size_t i = 0; i < b.count.size(); ++i)
      if (b.count[i] != spp_per_pass)
        return "pixel " + std::to_string(i) + " of its rect has " + std::to_string(b.count[i]) +
               " samples, not the pass's " + std::to_string(spp_per_pass);
    if (!b.splat.empty() && b.light_paths != spp_per_pass * uint64_t(b.rect.area()))
      return std::to_string(b.light_paths) + " light paths, not the pass's " +
             std::to_string(spp_per_pass * uint64_t(b.rect.area()));
  }
  if (b.nonfinite_samples > std::max(samples, b.light_paths))
    return "more non-finite samples than samples";
  auto finite = [](std::span<const double> v, bool non_negative) {
    for (double x : v)
      if (!std::isfinite(x) || (non_negative && x < 0)) return false;
    return true;
  };
  if (!finite(b.sum, false) || !finite(b.batch_sum, false) || !finite(b.splat, false) ||
      !finite(b.aov, false))
    return "a sum is not finite";
  // Radiance is never negative, nor are the filter weights (importance-sampled filters carry
  // their sign in the sample's weight, and every filter here is non-negative): an honest sum of
  // radiance is >= 0. AOVs (normals) may be negative.
  if (!finite(b.sum, true) || !finite(b.batch_sum, true) || !finite(b.splat, true))
    return "a sum of radiance is negative";
  if (!finite(b.sum_sq, true) || !finite(b.batch_sum_sq, true))
    return "a sum of squares is negative or not finite";
  return "";
}

}  // namespace

std::string task_buffer_problem(const BufferView& b, uint64_t spp_per_pass) {
  return samples_problem(b, spp_per_pass, 1e7);
}

std::string buffer_problem(const BufferView& b) {
  const std::string key = "spp_per_pass=";
  size_t at = b.header->settings.find(key);
  if (at == std::string::npos) return "its header does not say its samples per pass";
  uint64_t spp = std::strtoull(b.header->settings.c_str() + at + key.size(), nullptr, 10);
  uint64_t passes = b.header->passes.count();
  if (spp == 0 || passes == 0)
    return "its header holds no samples (passes " + b.header->passes.to_string() + ")";
  // 1e12 core-seconds is 31,700 core-years: more is no honest render's.
  std::string why = samples_problem(b, spp * passes, 1e12);
  if (why.empty()) return "";
  return why + " (passes " + b.header->passes.to_string() + " of " + std::to_string(spp) +
         " samples each)";
}

bool same_samples(const BufferView& a, const BufferView& b) {
  auto same = [](auto x, auto y) {  // bit for bit (a NaN equals itself, 0 is not -0)
    return x.size() == y.size() &&
           (x.empty() || std::memcmp(x.data(), y.data(), x.size_bytes()) == 0);
  };
  return a.rect == b.rect && a.header->passes == b.header->passes && same(a.count, b.count) &&
         same(a.sum, b.sum) && same(a.sum_sq, b.sum_sq) && same(a.batch_sum, b.batch_sum) &&
         same(a.batch_sum_sq, b.batch_sum_sq) && same(a.splat, b.splat) &&
         a.light_paths == b.light_paths && same(a.aov, b.aov) &&
         a.nonfinite_samples == b.nonfinite_samples;
}

}  // namespace rf
