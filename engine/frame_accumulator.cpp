#include "engine/frame_accumulator.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <list>
#include <stdexcept>
#include <type_traits>
#include <unordered_map>

#include "engine/digest.h"
#include "engine/progress.h"

namespace rf {

// A tiled frame's storage (ProgressiveOptions::memory_budget): every tile's planes at a fixed
// place in one unlinked file (tile i after the pixels of tiles 0..i-1, planes in .rfb order), the
// most recently used tiles cached up to a byte budget and written back when evicted; and, per
// pass, an unlinked file of the results waiting for that pass that did not fit in memory.
// Unlinked at creation, the files go with the process however it ends.
class TileSpill {
 public:
  TileSpill(const std::string& dir, const TileGrid& grid, const BufferHeader& header,
            uint64_t cache_budget)
      : dir_(dir), grid_(grid), header_(header), budget_(cache_budget) {
    header_.passes = PassSet{};
    header_.core_seconds = 0;
    fd_ = open_unlinked();
  }
  ~TileSpill() {
    ::close(fd_);
    for (auto& [pass, f] : parked_) ::close(f.fd);
  }
  TileSpill(const TileSpill&) = delete;
  TileSpill& operator=(const TileSpill&) = delete;

  // Tile i with the frame's current passes; `stored`: its planes are in the file (a prefix was
  // merged), else it starts at zero. The reference lives until the next call.
  SampleBuffer& tile(size_t i, bool stored, const PassSet& passes) {
    auto it = cache_.find(i);
    if (it != cache_.end()) {
      lru_.splice(lru_.begin(), lru_, it->second.lru);
    } else {
      SampleBuffer b(header_, grid_[i], false);
      if (stored) read_planes(b, tile_offset(i));
      lru_.push_front(i);
      it = cache_.emplace(i, Cached{std::move(b), false, lru_.begin()}).first;
      cached_bytes_ += tile_bytes(i);
      peak_cached_bytes_ = std::max(peak_cached_bytes_, cached_bytes_);
      evict_beyond_budget(i);
    }
    it->second.buf.header.passes = passes;
    return it->second.buf;
  }
  void mark_dirty(size_t i) { cache_.at(i).dirty = true; }
  uint64_t tile_bytes(size_t i) const { return uint64_t(grid_[i].area()) * bpp(); }
  uint64_t cached_bytes() const { return cached_bytes_; }
  uint64_t peak_cached_bytes() const { return peak_cached_bytes_; }
  // Rows [y0, y1) of tile i (stored) into `out`, whose rect holds them: from the cache if the
  // tile is there, else straight from the file (not cached: a band is read once).
  void read_rows(size_t i, int y0, int y1, SampleBuffer& out) {
    const Rect tr = grid_[i];
    const Rect rows{tr.x0, y0, tr.w, y1 - y0};
    if (auto it = cache_.find(i); it != cache_.end()) {
      copy_pixels(it->second.buf, out, rows);
      return;
    }
    const uint64_t area = uint64_t(tr.area()), first = uint64_t(y0 - tr.y0) * uint64_t(tr.w);
    const uint64_t n = uint64_t(rows.area());
    uint64_t plane_at = tile_offset(i);
    const size_t na = size_t(header_.aovs.channels());
    auto plane = [&](auto* dst_plane, size_t k) {  // k values per pixel
      using T = std::remove_reference_t<decltype((*dst_plane)[0])>;
      scratch_.resize(size_t(k * n));
      read_all(fd_, scratch_.data(), 8 * k * n, plane_at + 8 * k * first);
      for (int y = y0; y < y1; ++y) {
        const size_t d = out.pixel_index(tr.x0, y), s = size_t(y - y0) * size_t(tr.w);
        std::memcpy(dst_plane->data() + k * d, scratch_.data() + k * s, 8 * k * size_t(tr.w));
      }
      static_assert(sizeof(T) == 8);
      plane_at += 8 * k * area;
    };
    plane(&out.count, 1);
    plane(&out.sum, 3);
    plane(&out.sum_sq, 3);
    plane(&out.batch_sum, 3);
    plane(&out.batch_sum_sq, 3);
    if (na) plane(&out.aov, na);
  }

  // A waiting result of `pass` written to that pass's file; its bytes read back.
  std::pair<uint64_t, uint64_t> park(uint32_t pass, std::string_view bytes) {
    auto it = parked_.find(pass);
    if (it == parked_.end()) it = parked_.emplace(pass, ParkFile{open_unlinked(), 0}).first;
    uint64_t at = it->second.end;
    write_all(it->second.fd, bytes.data(), bytes.size(), at);
    it->second.end += bytes.size();
    return {at, bytes.size()};
  }
  std::string unpark(uint32_t pass, uint64_t offset, uint64_t length) const {
    std::string bytes(length, '\0');
    read_all(parked_.at(pass).fd, bytes.data(), length, offset);
    return bytes;
  }
  void drop_parked(uint32_t pass) {
    auto it = parked_.find(pass);
    if (it == parked_.end()) return;
    ::close(it->second.fd);
    parked_.erase(it);
  }
  // Passes with parked results up to `last` (inclusive).
  void drop_parked_up_to(uint32_t last) {
    while (!parked_.empty() && parked_.begin()->first <= last) drop_parked(parked_.begin()->first);
  }
  void drop_all_parked() {
    while (!parked_.empty()) drop_parked(parked_.begin()->first);
  }

 private:
  struct Cached {
    SampleBuffer buf;
    bool dirty = false;
    std::list<size_t>::iterator lru;
  };
  struct ParkFile {
    int fd;
    uint64_t end;
  };

  uint64_t bpp() const { return FrameAccumulator::bytes_per_pixel(header_.aovs); }
  uint64_t tile_offset(size_t i) const {
    const uint64_t t = uint64_t(grid_.tile()), w = uint64_t(grid_.width());
    if (t == 0) return 0;
    const uint64_t row = i / grid_.columns(), col = i % grid_.columns();
    const uint64_t row_h = std::min<uint64_t>(t, uint64_t(grid_.height()) - row * t);
    return (row * t * w + col * t * row_h) * bpp();
  }
  template <class F>
  static void for_each_plane(SampleBuffer& b, F&& f) {
    f(b.count.data(), b.count.size() * 8);
    for (auto* v : {&b.sum, &b.sum_sq, &b.batch_sum, &b.batch_sum_sq, &b.aov})
      f(v->data(), v->size() * 8);
  }
  void read_planes(SampleBuffer& b, uint64_t at) const {
    for_each_plane(b, [&](void* p, size_t n) {
      read_all(fd_, p, n, at);
      at += n;
    });
  }
  void write_planes(SampleBuffer& b, uint64_t at) const {
    for_each_plane(b, [&](void* p, size_t n) {
      write_all(fd_, p, n, at);
      at += n;
    });
  }
  void evict_beyond_budget(size_t keep) {
    while (cached_bytes_ > budget_ && lru_.size() > 1) {
      size_t victim = lru_.back();
      if (victim == keep) break;
      Cached& c = cache_.at(victim);
      if (c.dirty) write_planes(c.buf, tile_offset(victim));
      cached_bytes_ -= tile_bytes(victim);
      lru_.pop_back();
      cache_.erase(victim);
    }
  }
  int open_unlinked() const {
    int fd = ::open(dir_.c_str(), O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
    if (fd < 0 && (errno == EOPNOTSUPP || errno == EISDIR || errno == EINVAL)) {
      std::string path = dir_ + "/.rayfarm-spill-XXXXXX";
      fd = ::mkostemp(path.data(), O_CLOEXEC);
      if (fd >= 0) ::unlink(path.c_str());
    }
    if (fd < 0) fail("cannot create a spill file");
    return fd;
  }
  [[noreturn]] void fail(const std::string& what) const {
    throw std::runtime_error(what + " in " + dir_ +
                             " (the frame's tiles kept on disk): " + std::strerror(errno));
  }
  void write_all(int fd, const void* p, size_t n, uint64_t at) const {
    if (!pwrite_full(fd, p, n, at)) fail("cannot write a spill file");
  }
  void read_all(int fd, void* p, size_t n, uint64_t at) const {
    if (!pread_full(fd, p, n, at)) fail("cannot read a spill file");
  }

  std::string dir_;
  TileGrid grid_;
  BufferHeader header_;
  uint64_t budget_;
  int fd_ = -1;
  std::unordered_map<size_t, Cached> cache_;
  std::list<size_t> lru_;  // most recently used first
  uint64_t cached_bytes_ = 0, peak_cached_bytes_ = 0;
  std::map<uint32_t, ParkFile> parked_;
  std::vector<uint64_t> scratch_;  // read_rows
};

namespace {

// A held result's view (not a parked one: the caller reads that back first).
template <class Task>
BufferView view_of(const Task& task) {
  if (const SampleBuffer* b = std::get_if<SampleBuffer>(&task)) return BufferView(*b);
  return std::get<EncodedBuffer>(task).view();
}

uint64_t held_bytes(const BufferView& v) {
  return 8 * (v.count.size() + v.sum.size() + v.sum_sq.size() + v.batch_sum.size() +
              v.batch_sum_sq.size() + v.splat.size() + v.aov.size());
}

}  // namespace

FrameAccumulator::FrameAccumulator(const BufferHeader& base, TileGrid tiles, bool splats,
                                   const ProgressiveOptions& options)
    : base_(base), tiles_(tiles), splats_(splats), options_(options) {
  if (tiles_.width() != base_.width || tiles_.height() != base_.height)
    throw MergeError("a grid of " + std::to_string(tiles_.width()) + "x" +
                     std::to_string(tiles_.height()) + " for a frame of " +
                     std::to_string(base_.width) + "x" + std::to_string(base_.height));
  base_.passes = PassSet{};
  base_.core_seconds = 0;
  const Rect whole{0, 0, base_.width, base_.height};
  const uint64_t frame_bytes = uint64_t(whole.area()) * bytes_per_pixel(base_.aovs);
  if (options_.memory_budget > 0 && frame_bytes > options_.memory_budget && !splats_ &&
      tiles_.size() > 1) {
    spill_ =
        std::make_unique<TileSpill>(options_.spill_dir, tiles_, base_, options_.memory_budget / 2);
    frame_ = SampleBuffer();  // header and counters only
    frame_.header = base_;
    frame_.rect = whole;
  } else {
    frame_ = SampleBuffer(base_, whole, splats_);
  }
  if (options_.pass_count == 0) done_ = true;
}

FrameAccumulator::~FrameAccumulator() = default;
FrameAccumulator::FrameAccumulator(FrameAccumulator&&) noexcept = default;
FrameAccumulator& FrameAccumulator::operator=(FrameAccumulator&&) noexcept = default;

const SampleBuffer& FrameAccumulator::frame() const {
  if (spill_) throw std::logic_error("FrameAccumulator::frame(): the frame is kept in tiles");
  return frame_;
}

size_t FrameAccumulator::tile_index(const Rect& rect) const {
  std::optional<size_t> i = tiles_.index_of(rect);
  if (!i)
    throw MergeError("rect " + std::to_string(rect.x0) + "," + std::to_string(rect.y0) + " " +
                     std::to_string(rect.w) + "x" + std::to_string(rect.h) +
                     " is not a tile of this frame");
  return *i;
}

bool FrameAccumulator::task_needed(const Rect& rect, uint32_t pass) const {
  if (done_ || pass < options_.first_pass + merged_ ||
      pass >= options_.first_pass + options_.pass_count)
    return false;
  auto it = pending_.find(pass);
  return it == pending_.end() || !it->second.tiles.count(tile_index(rect));
}

FrameAccumulator::AddResult FrameAccumulator::add(SampleBuffer task) {
  if (!task.planes_match_rect()) throw MergeError("plane sizes do not match the rect");
  return add_task(std::move(task));
}

FrameAccumulator::AddResult FrameAccumulator::add(EncodedBuffer task) {
  return add_task(std::move(task));  // its planes match its rect: decoding checked them
}

FrameAccumulator::AddResult FrameAccumulator::add_task(Task task) {
  const BufferView v = view_of(task);  // read before the task moves into pending_
  const BufferHeader& header = *v.header;
  if (header.passes.count() != 1 || header.passes.ranges.size() != 1)
    throw MergeError("a task buffer must hold exactly one pass, got " + header.passes.to_string());
  std::string why = merge_incompatibility(base_, header);
  if (!why.empty()) throw MergeError(why);
  uint32_t pass = header.passes.ranges[0].first;
  size_t ti = tile_index(v.rect);
  if (v.splat.empty() == splats_)
    throw MergeError(splats_ ? "a task of this frame must carry a splat plane"
                             : "a task of this frame must not carry a splat plane");
  if (pass < options_.first_pass || pass >= options_.first_pass + options_.pass_count)
    return AddResult::Dropped;
  if (pass < options_.first_pass + merged_) return AddResult::Duplicate;
  if (done_) return AddResult::Dropped;

  PendingPass& pp = pending_[pass];
  if (pp.tiles.count(ti)) return AddResult::Duplicate;
  if (spill_) {
    // Beyond half the budget, a waiting result goes to its pass's spill file.
    const uint64_t bytes = held_bytes(v);
    if (waiting_bytes_ + bytes > options_.memory_budget / 2) {
      std::pair<uint64_t, uint64_t> at;
      if (const EncodedBuffer* e = std::get_if<EncodedBuffer>(&task))
        at = spill_->park(pass, e->bytes());
      else
        at = spill_->park(pass, encode_buffer(std::get<SampleBuffer>(task)));
      task = Parked{at.first, at.second};
      ++parked_;
    } else {
      waiting_bytes_ += bytes;
    }
    peak_waiting_ = std::max(peak_waiting_, waiting_bytes_);
  }
  pp.tiles.emplace(ti, std::move(task));
  size_t before = merged_;
  merge_ready_passes();
  return merged_ > before ? AddResult::Merged : AddResult::Pending;
}

double FrameAccumulator::prefix_rel_mse() const {
  double total = 0;
  for (size_t t = 0; t < tiles_.size(); ++t) {
    if (spill_) {
      const SampleBuffer& tile = spill_->tile(t, merged_ > 0, frame_.header.passes);
      total += rel_mse_sum(tile, tile.rect);
    } else {
      total += rel_mse_sum(frame_, tiles_[t]);
    }
  }
  double area = double(frame_.rect.area());
  return area > 0 ? total / (3.0 * area) : 0.0;
}

void FrameAccumulator::decide_after(uint32_t merged) {
  double rel = rel_mse();
  if (merged == options_.pass_count) {
    done_ = true;
  } else if (options_.noise_target > 0 &&
             merged >= std::min(options_.min_passes, options_.pass_count) &&
             rel <= options_.noise_target) {
    done_ = stopped_on_target_ = true;
  }
}

void FrameAccumulator::resume_from(SampleBuffer prefix) {
  if (!prefix.planes_match_rect() || prefix.splat.empty() == splats_ ||
      prefix.aov.size() != size_t(prefix.rect.area()) * size_t(base_.aovs.channels()))
    throw MergeError("checkpoint has another frame size or planes");
  if (!spill_) {
    check_prefix(prefix);
    frame_ = std::move(prefix);
    samples_ = frame_.total_samples();
    resumed();
    return;
  }
  resume_from(WholeFrame(prefix));
}

void FrameAccumulator::resume_from(const FrameBands& bands) {
  const SampleBuffer& info = bands.info();
  check_prefix(info);
  if (!spill_) {  // assembled whole
    SampleBuffer whole(info.header, info.rect, splats_);
    whole.light_paths = info.light_paths;
    whole.nonfinite_samples = info.nonfinite_samples;
    whole.rays = info.rays;
    for (int y0 = info.rect.y0; y0 < info.rect.y1(); y0 += bands.band_height()) {
      const SampleBuffer& band = bands.band(y0);
      if (!band.planes_match_rect() || band.splat.size() != whole.splat.size() ||
          band.aov.size() != size_t(band.rect.area()) * size_t(base_.aovs.channels()))
        throw MergeError("checkpoint has another frame size or planes");
      copy_pixels(band, whole, band.rect);
      if (!whole.splat.empty()) whole.splat = band.splat;
    }
    frame_ = std::move(whole);
    samples_ = frame_.total_samples();
  } else {  // cut into the tiles: a tile row's tiles begin with the band holding its first row
    const int t = tiles_.tile();
    for (int y0 = info.rect.y0; y0 < info.rect.y1(); y0 += bands.band_height()) {
      const SampleBuffer& band = bands.band(y0);
      if (!band.planes_match_rect() || band.rect.x0 != 0 || band.rect.w != info.rect.w ||
          band.aov.size() != size_t(band.rect.area()) * size_t(base_.aovs.channels()))
        throw MergeError("checkpoint has another frame size or planes");
      const int y1 = band.rect.y1();
      for (size_t row = size_t(y0 / t); row <= size_t((y1 - 1) / t); ++row)
        for (size_t c = 0; c < tiles_.columns(); ++c) {
          const size_t i = row * tiles_.columns() + c;
          const Rect tr = tiles_[i];
          SampleBuffer& tile = spill_->tile(i, /*stored=*/tr.y0 < y0, info.header.passes);
          copy_pixels(
              band, tile,
              Rect{tr.x0, std::max(y0, tr.y0), tr.w, std::min(y1, tr.y1()) - std::max(y0, tr.y0)});
          spill_->mark_dirty(i);
        }
    }
    frame_.header = info.header;
    frame_.light_paths = info.light_paths;
    frame_.nonfinite_samples = info.nonfinite_samples;
    frame_.rays = info.rays;
    samples_ = bands.total_samples();
  }
  resumed();
}

void FrameAccumulator::check_prefix(const SampleBuffer& info) const {
  if (merged_ != 0 || !pending_.empty())
    throw MergeError("resume_from needs a fresh accumulator");
  if (std::string why = merge_incompatibility(base_, info.header); !why.empty())
    throw MergeError("checkpoint is of another image: " + why);
  uint32_t k = info.header.passes.count();
  if (!(info.header.passes == PassSet::range(options_.first_pass, options_.first_pass + k)) ||
      k > options_.pass_count)
    throw MergeError("checkpoint holds passes " + info.header.passes.to_string() +
                     ", not a prefix of this frame's passes");
  if (!(info.rect == frame_.rect) || (info.light_paths > 0 && !splats_))
    throw MergeError("checkpoint has another frame size or planes");
}

void FrameAccumulator::resumed() {
  merged_ = frame_.header.passes.count();
  // Only the last value is known; it is the one that decides.
  rel_mse_history_.assign(merged_, prefix_rel_mse());
  const double area = double(frame_.rect.area());
  spp_ = area > 0 ? double(samples_ ? samples_ : frame_.light_paths) / area : 0.0;
  decide_after(merged_);
}

// Adds the next pass's tiles into the frame in tile order once all are there. The relMSE of the
// new prefix is summed per tile right after the tile is added, while its pixels are in cache.
void FrameAccumulator::merge_ready_passes() {
  const double area = double(frame_.rect.area());
  while (!done_) {
    const uint32_t pass = options_.first_pass + merged_;
    auto it = pending_.find(pass);
    if (it == pending_.end() || it->second.tiles.size() != tiles_.size()) return;
    frame_.header.passes.add(PassSet::range(pass, pass + 1));  // the variance counts it
    double rel = 0;
    if (spill_) {
      merge_pass_tiled(it->second.tiles, pass, &rel);
    } else {
      for (const auto& [t, task] : it->second.tiles) {  // in tile order
        BufferView tile = view_of(task);
        add_tile(frame_, tile);  // checked when it was added: cannot throw
        samples_ += tile.total_samples();
        rel += rel_mse_sum(frame_, tile.rect);
      }
    }
    pending_.erase(it);
    ++merged_;
    rel_mse_history_.push_back(area > 0 ? rel / (3.0 * area) : 0.0);
    spp_ = area > 0 ? double(samples_ ? samples_ : frame_.light_paths) / area : 0.0;
    decide_after(merged_);
  }
  if (done_) {  // passes beyond the prefix are dropped
    pending_.clear();
    if (spill_) {
      spill_->drop_all_parked();
      waiting_bytes_ = 0;
    }
  }
}

// The same per tile as above, each tile read from (and written back to) the spill file: the
// same sums in the same order, so the same bits as a frame held whole.
void FrameAccumulator::merge_pass_tiled(std::map<size_t, Task>& tiles, uint32_t pass, double* rel) {
  for (auto& [t, task] : tiles) {  // in tile order
    if (const Parked* p = std::get_if<Parked>(&task)) {
      // Read back; its checksum is checked again (the spill file is storage like any other).
      task = EncodedBuffer(spill_->unpark(pass, p->offset, p->length), "a result kept on disk");
    } else {
      waiting_bytes_ -= held_bytes(view_of(task));
    }
    BufferView v = view_of(task);
    SampleBuffer& tile = spill_->tile(t, merged_ > 0, frame_.header.passes);
    tile.header.build_id = v.header->build_id;  // the frame's provenance is combined below,
    tile.header.isa = v.header->isa;            // once (a mixed build warns once)
    add_tile(tile, v);
    spill_->mark_dirty(t);
    frame_.light_paths += v.light_paths;
    frame_.nonfinite_samples += v.nonfinite_samples;
    frame_.rays += v.rays;
    combine_provenance(frame_.header, *v.header);
    samples_ += v.total_samples();
    *rel += rel_mse_sum(tile, tile.rect);
    task = SampleBuffer();  // merged: its memory goes now
  }
  spill_->drop_parked(pass);
}

// Tiled: rows of up to an eighth of the budget (at least one, at most a tile's height), so a
// band and the writer's pixels of it stay within a quarter of it.
int FrameAccumulator::band_height() const {
  if (!spill_) return std::max(frame_.rect.h, 1);
  const uint64_t row = uint64_t(frame_.rect.w) * bytes_per_pixel(base_.aovs);
  const uint64_t rows = options_.memory_budget / 8 / std::max<uint64_t>(row, 1);
  return int(std::clamp<uint64_t>(rows, 1, uint64_t(tiles_.tile())));
}

const SampleBuffer& FrameAccumulator::band(int y0) const {
  if (!spill_) return frame_;
  const int h = std::min(band_height(), frame_.rect.h - y0);
  const Rect rows{0, y0, frame_.rect.w, h};
  if (!(band_.rect == rows) || band_.count.size() != size_t(rows.area())) {
    band_ = SampleBuffer(base_, rows, false);
  } else {
    std::fill(band_.count.begin(), band_.count.end(), 0);
    for (auto* v : {&band_.sum, &band_.sum_sq, &band_.batch_sum, &band_.batch_sum_sq, &band_.aov})
      std::fill(v->begin(), v->end(), 0.0);
  }
  band_.header = frame_.header;
  band_.light_paths = frame_.light_paths;
  band_.nonfinite_samples = frame_.nonfinite_samples;
  band_.rays = frame_.rays;
  if (merged_ > 0) {  // the rows of each tile the band crosses
    const int t = tiles_.tile(), y1 = y0 + h;
    for (size_t row = size_t(y0 / t); row <= size_t((y1 - 1) / t); ++row)
      for (size_t c = 0; c < tiles_.columns(); ++c) {
        const size_t i = row * tiles_.columns() + c;
        const Rect tr = tiles_[i];
        spill_->read_rows(i, std::max(y0, tr.y0), std::min(y1, tr.y1()), band_);
      }
  }
  return band_;
}

FrameAccumulator::SpillUse FrameAccumulator::spill_use() const {
  if (!spill_) return {};
  return {spill_->peak_cached_bytes(), peak_waiting_, parked_};
}

}  // namespace rf
