#include "engine/frame_accumulator.h"

#include <algorithm>

#include "engine/progress.h"

namespace rf {

namespace {

BufferView view_of(const std::variant<SampleBuffer, EncodedBuffer>& task) {
  if (const SampleBuffer* b = std::get_if<SampleBuffer>(&task)) return BufferView(*b);
  return std::get<EncodedBuffer>(task).view();
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
  frame_ = SampleBuffer(base_, Rect{0, 0, base_.width, base_.height}, splats_);
  if (options_.pass_count == 0) done_ = true;
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
  if (!pp.tiles.try_emplace(ti, std::move(task)).second) return AddResult::Duplicate;
  size_t before = merged_;
  merge_ready_passes();
  return merged_ > before ? AddResult::Merged : AddResult::Pending;
}

double FrameAccumulator::prefix_rel_mse() const {
  double total = 0;
  for (size_t t = 0; t < tiles_.size(); ++t) total += rel_mse_sum(frame_, tiles_[t]);
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
  if (merged_ != 0 || !pending_.empty())
    throw MergeError("resume_from needs a fresh accumulator");
  if (std::string why = merge_incompatibility(base_, prefix.header); !why.empty())
    throw MergeError("checkpoint is of another image: " + why);
  uint32_t k = prefix.header.passes.count();
  if (!(prefix.header.passes == PassSet::range(options_.first_pass, options_.first_pass + k)) ||
      k > options_.pass_count)
    throw MergeError("checkpoint holds passes " + prefix.header.passes.to_string() +
                     ", not a prefix of this frame's passes");
  if (!(prefix.rect == frame_.rect) || prefix.splat.size() != frame_.splat.size() ||
      !prefix.planes_match_rect() || prefix.aov.size() != frame_.aov.size())
    throw MergeError("checkpoint has another frame size or planes");
  frame_ = std::move(prefix);
  merged_ = k;
  // Only the last value is known; it is the one that decides.
  rel_mse_history_.assign(k, prefix_rel_mse());
  samples_ = frame_.total_samples();
  spp_ = rf::samples_per_pixel(frame_);
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
    for (const auto& [t, task] : it->second.tiles) {  // in tile order
      BufferView tile = view_of(task);
      add_tile(frame_, tile);  // checked when it was added: cannot throw
      samples_ += tile.total_samples();
      rel += rel_mse_sum(frame_, tile.rect);
    }
    pending_.erase(it);
    ++merged_;
    rel_mse_history_.push_back(area > 0 ? rel / (3.0 * area) : 0.0);
    spp_ = area > 0 ? double(samples_ ? samples_ : frame_.light_paths) / area : 0.0;
    decide_after(merged_);
  }
  if (done_) pending_.clear();  // passes beyond the prefix are dropped
}

}  // namespace rf
