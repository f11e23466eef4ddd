#include "engine/frame_accumulator.h"

#include <algorithm>

namespace rf {

FrameAccumulator::FrameAccumulator(const BufferHeader& base, std::vector<Rect> tiles, bool splats,
                                   const ProgressiveOptions& options)
    : base_(base), tiles_(std::move(tiles)), splats_(splats), options_(options) {
  base_.passes = PassSet{};
  base_.core_seconds = 0;
  frame_ = SampleBuffer(base_, Rect{0, 0, base_.width, base_.height}, splats_);
  if (options_.pass_count == 0) done_ = true;
}

size_t FrameAccumulator::tile_index(const Rect& rect) const {
  auto it = std::find(tiles_.begin(), tiles_.end(), rect);
  if (it == tiles_.end())
    throw MergeError("rect " + std::to_string(rect.x0) + "," + std::to_string(rect.y0) + " " +
                     std::to_string(rect.w) + "x" + std::to_string(rect.h) +
                     " is not a tile of this frame");
  return size_t(it - tiles_.begin());
}

bool FrameAccumulator::task_needed(const Rect& rect, uint32_t pass) const {
  if (done_ || pass < options_.first_pass + merged_ ||
      pass >= options_.first_pass + options_.pass_count)
    return false;
  auto it = pending_.find(pass);
  return it == pending_.end() || !it->second.have[tile_index(rect)];
}

FrameAccumulator::AddResult FrameAccumulator::add(SampleBuffer task) {
  if (task.header.passes.count() != 1 || task.header.passes.ranges.size() != 1)
    throw MergeError("a task buffer must hold exactly one pass, got " +
                     task.header.passes.to_string());
  std::string why = merge_incompatibility(base_, task.header);
  if (!why.empty()) throw MergeError(why);
  uint32_t pass = task.header.passes.ranges[0].first;
  size_t ti = tile_index(task.rect);
  if (pass < options_.first_pass || pass >= options_.first_pass + options_.pass_count)
    return AddResult::Dropped;
  if (pass < options_.first_pass + merged_) return AddResult::Duplicate;
  if (done_) return AddResult::Dropped;

  auto it = pending_.find(pass);
  if (it == pending_.end()) {
    BufferHeader h = base_;
    h.passes = PassSet::range(pass, pass + 1);
    PendingPass pp{SampleBuffer(h, Rect{0, 0, base_.width, base_.height}, splats_),
                   std::vector<bool>(tiles_.size(), false), tiles_.size()};
    it = pending_.emplace(pass, std::move(pp)).first;
  }
  PendingPass& pp = it->second;
  if (pp.have[ti]) return AddResult::Duplicate;
  if (splats_ || task.rect == pp.buffer.rect) {
    // Whole-frame task: it is the pass.
    pp.buffer = std::move(task);
  } else {
    assemble_tile(pp.buffer, task);
  }
  pp.have[ti] = true;
  --pp.remaining;
  size_t before = merged_;
  merge_ready_passes();
  return merged_ > before ? AddResult::Merged : AddResult::Pending;
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
      prefix.count.size() != frame_.count.size())
    throw MergeError("checkpoint has another frame size or planes");
  frame_ = std::move(prefix);
  merged_ = k;
  double rel = frame_.rel_mse();
  rel_mse_history_.assign(k, rel);  // only the last value is known; it is the one that decides
  if (merged_ == options_.pass_count)
    done_ = true;
  else if (options_.noise_target > 0 && merged_ >= std::min(options_.min_passes, options_.pass_count) &&
           rel <= options_.noise_target)
    done_ = stopped_on_target_ = true;
}

void FrameAccumulator::merge_ready_passes() {
  while (!done_) {
    auto it = pending_.find(options_.first_pass + merged_);
    if (it == pending_.end() || it->second.remaining != 0) return;
    merge_into(frame_, it->second.buffer);
    pending_.erase(it);
    ++merged_;
    double rel = frame_.rel_mse();
    rel_mse_history_.push_back(rel);
    if (merged_ == options_.pass_count) {
      done_ = true;
    } else if (options_.noise_target > 0 &&
               merged_ >= std::min(options_.min_passes, options_.pass_count) &&
               rel <= options_.noise_target) {
      done_ = stopped_on_target_ = true;
    }
  }
  if (done_) pending_.clear();  // passes beyond the prefix are dropped
}

}  // namespace rf
