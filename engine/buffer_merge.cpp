#include "engine/buffer_merge.h"

#include <spdlog/spdlog.h>

#include <set>
#include <string_view>

namespace rf {

namespace {

// Which identity field (everything that changes pixels) differs, or "".
std::string identity_difference(const BufferHeader& a, const BufferHeader& b) {
  auto str = [](const char* field, const std::string& x, const std::string& y) {
    return std::string(field) + " differs: \"" + x + "\" vs \"" + y + "\"";
  };
  auto num = [](const char* field, auto x, auto y) {
    return std::string(field) + " differs: " + std::to_string(x) + " vs " + std::to_string(y);
  };
  if (a.scene_digest != b.scene_digest) return str("scene_digest", a.scene_digest, b.scene_digest);
  if (a.seed != b.seed) return num("seed", a.seed, b.seed);
  if (a.frame != b.frame) return num("frame", a.frame, b.frame);
  if (a.integrator != b.integrator) return str("integrator", a.integrator, b.integrator);
  if (a.settings != b.settings) return str("settings", a.settings, b.settings);
  if (a.width != b.width) return num("width", a.width, b.width);
  if (a.height != b.height) return num("height", a.height, b.height);
  if (a.aovs != b.aovs) return str("aovs", to_string(a.aovs), to_string(b.aovs));
  return "";
}

std::set<std::string> split_ids(const std::string& id) {
  std::set<std::string> ids;
  if (id.rfind("mixed:", 0) != 0) {
    if (!id.empty()) ids.insert(id);
    return ids;
  }
  for (size_t pos = 6; pos <= id.size();) {
    size_t comma = std::min(id.find(',', pos), id.size());
    if (comma > pos) ids.insert(id.substr(pos, comma - pos));
    pos = comma + 1;
  }
  return ids;
}

// Build ids (and ISAs) combine as sets: one id when all agree, else "mixed:" + the sorted distinct
// ids joined by ','. Set union makes this exactly associative and commutative; an empty id (a
// fresh accumulator) adds nothing. Warns once each time a new id joins, since pixels from
// different builds or CPU kinds agree statistically, not bitwise (DESIGN.md).
std::string combine_ids(const std::string& dst, const std::string& src, const char* what) {
  std::set<std::string> a = split_ids(dst), all = a;
  for (const std::string& s : split_ids(src)) all.insert(s);
  if (all.empty()) return "";
  if (all.size() == 1) return *all.begin();
  std::string out = "mixed:";
  for (const std::string& s : all) out += (out.size() > 6 ? "," : "") + s;
  if (all != a && !a.empty()) {
    spdlog::warn(
        "merging sample buffers made by different {} (\"{}\" and \"{}\"): the result agrees "
        "statistically, not bitwise, with a render made by one",
        what, dst, src);
  }
  return out;
}

// dst[i] += src[i] for n values; vectorised by the compiler (no aliasing: dst is the
// accumulator's own, src a received buffer).
template <class T>
void add_values(T* __restrict dst, const T* __restrict src, size_t n) {
  for (size_t i = 0; i < n; ++i) dst[i] += src[i];
}

}  // namespace

void combine_provenance(BufferHeader& dst, const BufferHeader& src) {
  dst.build_id = combine_ids(dst.build_id, src.build_id, "builds");
  dst.isa = combine_ids(dst.isa, src.isa, "CPU kinds");
  dst.core_seconds += src.core_seconds;
}

std::string merge_incompatibility(const BufferHeader& a, const BufferHeader& b) {
  if (std::string why = identity_difference(a, b); !why.empty()) return why;
  if (a.passes.overlaps(b.passes)) {
    return "pass sets overlap: \"" + a.passes.to_string() + "\" and \"" + b.passes.to_string() +
           "\" share passes " + intersection(a.passes, b.passes).to_string();
  }
  return "";
}

void merge_into(SampleBuffer& dst, const BufferView& src) {
  auto fail = [](const std::string& why) {
    return MergeError("cannot merge sample buffers: " + why);
  };
  if (std::string why = merge_incompatibility(dst.header, *src.header); !why.empty())
    throw fail(why);
  if (dst.rect != src.rect) {
    throw fail("rect differs: " + to_string(dst.rect) + " vs " + to_string(src.rect));
  }
  add_tile(dst, src);
  dst.header.passes.add(src.header->passes);
}

void add_tile(SampleBuffer& dst, const BufferView& tile) {
  auto fail = [](const std::string& why) {
    return MergeError("cannot merge sample buffers: " + why);
  };
  if (dst.splat.empty() != tile.splat.empty()) {
    throw fail("one buffer has a splat plane and the other has none");
  }
  if (tile.rect.w < 0 || tile.rect.h < 0 || !dst.rect.contains(tile.rect)) {
    throw fail("tile " + to_string(tile.rect) + " is not inside " + to_string(dst.rect));
  }
  if (!dst.planes_match_rect() || !tile.planes_match_rect()) {
    throw fail("plane sizes do not match the rect " + to_string(tile.rect));
  }
  const size_t na = size_t(dst.header.aovs.channels());
  // Adds n pixels of the tile from its pixel s onto dst's pixels from d, every plane.
  auto add_run = [&](size_t d, size_t s, size_t n) {
    add_values(dst.count.data() + d, tile.count.data() + s, n);
    add_values(dst.sum.data() + 3 * d, tile.sum.data() + 3 * s, 3 * n);
    add_values(dst.sum_sq.data() + 3 * d, tile.sum_sq.data() + 3 * s, 3 * n);
    add_values(dst.batch_sum.data() + 3 * d, tile.batch_sum.data() + 3 * s, 3 * n);
    add_values(dst.batch_sum_sq.data() + 3 * d, tile.batch_sum_sq.data() + 3 * s, 3 * n);
    add_values(dst.aov.data() + na * d, tile.aov.data() + na * s, na * n);
  };
  if (tile.rect == dst.rect)  // one run
    add_run(0, 0, size_t(tile.rect.area()));
  else
    for (int y = tile.rect.y0; y < tile.rect.y1(); ++y)
      add_run(dst.pixel_index(tile.rect.x0, y), tile.pixel_index(tile.rect.x0, y),
              size_t(tile.rect.w));
  add_values(dst.splat.data(), tile.splat.data(), dst.splat.size());
  dst.light_paths += tile.light_paths;
  dst.nonfinite_samples += tile.nonfinite_samples;
  dst.rays += tile.rays;
  combine_provenance(dst.header, *tile.header);
}

void copy_pixels(const SampleBuffer& src, SampleBuffer& dst, const Rect& r) {
  const size_t w = size_t(r.w), na = size_t(src.header.aovs.channels());
  for (int y = r.y0; y < r.y1(); ++y) {
    const size_t s = src.pixel_index(r.x0, y), d = dst.pixel_index(r.x0, y);
    std::copy_n(src.count.begin() + s, w, dst.count.begin() + d);
    std::copy_n(src.sum.begin() + 3 * s, 3 * w, dst.sum.begin() + 3 * d);
    std::copy_n(src.sum_sq.begin() + 3 * s, 3 * w, dst.sum_sq.begin() + 3 * d);
    std::copy_n(src.batch_sum.begin() + 3 * s, 3 * w, dst.batch_sum.begin() + 3 * d);
    std::copy_n(src.batch_sum_sq.begin() + 3 * s, 3 * w, dst.batch_sum_sq.begin() + 3 * d);
    std::copy_n(src.aov.begin() + na * s, na * w, dst.aov.begin() + na * d);
  }
}

// Copies rows without arithmetic, so an assembled pass is bit-identical to a whole-frame render.
// Assembling the same tile twice overwrites its pixels but counts its rays and time twice.
void assemble_tile(SampleBuffer& dst, const SampleBuffer& tile) {
  auto fail = [](const std::string& why) { return MergeError("cannot assemble tile: " + why); };
  if (std::string why = identity_difference(dst.header, tile.header); !why.empty()) throw fail(why);
  if (dst.header.passes != tile.header.passes) {
    throw fail("passes differ: \"" + dst.header.passes.to_string() + "\" vs \"" +
               tile.header.passes.to_string() + "\"");
  }
  if (!dst.splat.empty() || !tile.splat.empty()) {
    throw fail("splatting buffers cover the whole frame; merge them instead");
  }
  if (tile.rect.w < 0 || tile.rect.h < 0 || !dst.rect.contains(tile.rect)) {
    throw fail("tile " + to_string(tile.rect) + " is not inside " + to_string(dst.rect));
  }
  if (!dst.planes_match_rect() || !tile.planes_match_rect()) {
    throw fail("plane sizes do not match the rect");
  }
  copy_pixels(tile, dst, tile.rect);
  dst.rays += tile.rays;
  dst.nonfinite_samples += tile.nonfinite_samples;
  combine_provenance(dst.header, tile.header);
}

MergedBands::MergedBands(std::vector<std::unique_ptr<FrameBands>> in,
                         std::vector<std::string> names)
    : in_(std::move(in)), names_(std::move(names)) {
  if (in_.empty() || names_.size() != in_.size())
    throw std::invalid_argument("MergedBands: an input and a name for each");
  info_ = in_[0]->info();
  info_.count.clear();  // header and counters only: the inputs' planes stay where they are
  for (auto* v :
       {&info_.sum, &info_.sum_sq, &info_.batch_sum, &info_.batch_sum_sq, &info_.splat, &info_.aov})
    v->clear();
  for (size_t i = 1; i < in_.size(); ++i) {
    const SampleBuffer& b = in_[i]->info();
    std::string why = merge_incompatibility(info_.header, b.header);
    if (why.empty() && !(b.rect == info_.rect)) why = "rects differ";
    if (why.empty() && in_[i]->band_height() != in_[0]->band_height()) why = "their planes differ";
    if (!why.empty())
      throw MergeError(names_[i] + ": cannot merge into " + names_[0] + " ...: " + why);
    info_.header.passes.add(b.header.passes);
    combine_provenance(info_.header, b.header);
    info_.light_paths += b.light_paths;
    info_.nonfinite_samples += b.nonfinite_samples;
    info_.rays += b.rays;
  }
  for (const auto& f : in_) samples_ += f->total_samples();
}

const SampleBuffer& MergedBands::checked(size_t i, int y0) const {
  const SampleBuffer& b = in_[i]->band(y0);
  if (std::string why = buffer_problem(b); !why.empty())
    throw std::runtime_error("merge: " + names_[i] + ": refused: " + why);
  return b;
}

const SampleBuffer& MergedBands::band(int y0) const {
  band_ = checked(0, y0);
  for (size_t i = 1; i < in_.size(); ++i) {
    const SampleBuffer& b = checked(i, y0);
    band_.header.build_id = b.header.build_id;  // provenance is info()'s, combined once
    band_.header.isa = b.header.isa;
    try {
      merge_into(band_, b);
    } catch (const MergeError& e) {
      throw MergeError(names_[i] + ": cannot merge into " + names_[0] + " ...: " + e.what());
    }
  }
  band_.header = info_.header;
  band_.light_paths = info_.light_paths;
  band_.nonfinite_samples = info_.nonfinite_samples;
  band_.rays = info_.rays;
  return band_;
}

double MergedBands::rel_mse() const {
  if (!rel_mse_) rel_mse_ = rel_mse_of_bands(*this);
  return *rel_mse_;
}

}  // namespace rf
