// Sampler's lockstep draws (see sampler.h).
#include "engine/sampler.h"

#include <cassert>

#include "engine/simd.h"

namespace rf {

namespace {

constexpr int kLanes = Sampler::kMaxLanes;

// sobol_draw_1d for kLanes samples at one dimension slot (hash h), lane j's bit-reversed sample
// index r[j]. All lanes, used or not (no remainder loop). Integer operations and exact
// conversions only, so every clone gives the same bits (engine/simd.h).
RF_SIMD_CLONES
void sobol_1d_lanes(const uint32_t* __restrict r, uint64_t h, float* __restrict out) {
  for (int j = 0; j < kLanes; ++j) out[j] = sobol_draw_1d(r[j], h);
}

// sobol_draw_2d likewise, the two coordinates into a and b.
RF_SIMD_CLONES
void sobol_2d_lanes(const uint32_t* __restrict r, uint64_t h, float* __restrict a,
                    float* __restrict b) {
  for (int j = 0; j < kLanes; ++j) {
    const Vec2 v = sobol_draw_2d(r[j], h);
    a[j] = v.x, b[j] = v.y;
  }
}

// sobol_draw_2d_joint likewise (h0: the first draw's hash).
RF_SIMD_CLONES
void sobol_joint_lanes(const uint32_t* __restrict r, uint64_t h0, uint64_t h, int k,
                       float* __restrict a, float* __restrict b) {
  for (int j = 0; j < kLanes; ++j) {
    const Vec2 v = sobol_draw_2d_joint(r[j], h0, h, k);
    a[j] = v.x, b[j] = v.y;
  }
}

}  // namespace

void Sampler::start_camera_samples(Sampler* s, int n, uint64_t seed, FrameNumber frame,
                                   uint32_t pass, int px, int py, uint64_t first_index) {
  if (n <= 0) return;
  const Kind kind = s[0].kind_;
  if (kind == Kind::Independent) {
    const uint64_t pixel = IndependentSampler::pixel_key(seed, frame, pass, px, py);
    for (int i = 0; i < n; ++i) {
      assert(s[i].kind_ == kind);
      s[i].sobol_active_ = false;
      s[i].independent_.start_camera_sample(pixel, first_index + uint64_t(i));
    }
    return;
  }
  // As start_camera_sample: SobolSequence keys without the pass and numbers on from the pass's
  // first sample.
  const bool sequence = kind == Kind::SobolSequence;
  const uint64_t base = sequence ? uint64_t(pass) * s[0].spp_per_pass_ + first_index : first_index;
  const uint64_t pixel =
      SobolSampler::pixel_key(seed, frame, sequence ? kSequencePass : pass, px, py);
  uint64_t high = base >> 32;  // the sample index's high bits the key holds
  SobolSampler key = SobolSampler::keyed(pixel, high);
  for (int i = 0; i < n; ++i) {
    assert(s[i].kind_ == kind && s[i].spp_per_pass_ == s[0].spp_per_pass_);
    const uint64_t index = base + uint64_t(i);
    if ((index >> 32) != high) high = index >> 32, key = SobolSampler::keyed(pixel, high);
    s[i].sobol_active_ = true;
    s[i].sobol_.start_camera_sample(key, index);
  }
}

bool Sampler::sobol_lockstep(const Sampler* s, const int* lane, int n) {
  const Sampler& first = s[lane[0]];
  if (!first.sobol_active_) return false;
  for (int j = 1; j < n; ++j) {
    const Sampler& o = s[lane[j]];
    if (!o.sobol_active_ || o.sobol_.key_ != first.sobol_.key_ ||
        o.sobol_.dimension_ != first.sobol_.dimension_)
      return false;
  }
  return true;
}

void Sampler::get_lanes(Sampler* s, const int* lane, int n, const uint8_t* draws, int count,
                        LaneDraws* out) {
  if (n <= 0) return;
  if (n == 1 || !sobol_lockstep(s, lane, n)) {
    for (int j = 0; j < n; ++j) {
      const int i = lane[j];
      for (int k = 0; k < count; ++k) {
        if (draws[k] == 0) {
          s[i].skip_1d();
        } else if (draws[k] == 1) {
          out[k][0][i] = s[i].get_1d();
        } else if (draws[k] >= kJointDraw) {
          Vec2 v = s[i].get_2d_joint(draws[k] - kJointDraw);
          out[k][0][i] = v.x, out[k][1][i] = v.y;
        } else {
          Vec2 v = s[i].get_2d();
          out[k][0][i] = v.x, out[k][1][i] = v.y;
        }
      }
    }
    return;
  }
  // In lane space: lanes not named compute from index 0, values nobody reads.
  uint32_t r[kLanes] = {};
  for (int j = 0; j < n; ++j) r[lane[j]] = s[lane[j]].sobol_.index_reversed_;
  SobolSampler& first = s[lane[0]].sobol_;
  const uint64_t h0 = first.first_draw_hash();  // the joint pairs' shuffle
  for (int k = 0; k < count; ++k) {
    if (draws[k] == 0) {
      first.skip_1d();
      continue;
    }
    const uint64_t h = first.dimension_hash();
    assert(draws[k] < kJointDraw + kJointPairs);
    if (draws[k] >= kJointDraw)
      sobol_joint_lanes(r, h0, h, draws[k] - kJointDraw, out[k][0], out[k][1]);
    else if (draws[k] == 1)
      sobol_1d_lanes(r, h, out[k][0]);
    else
      sobol_2d_lanes(r, h, out[k][0], out[k][1]);
  }
  for (int j = 1; j < n; ++j) s[lane[j]].sobol_.dimension_ = first.dimension_;
}

}  // namespace rf
