// Sampler's lockstep draws (see sampler.h).
#include "engine/sampler.h"

#include "engine/simd.h"

namespace rf {

namespace {

constexpr int kLanes = Sampler::kMaxLanes;

// fraction_to_float through a signed conversion (the value is below 2^24, so exact either way),
// which every SIMD level has.
inline float fraction_to_float_lane(uint32_t x) { return float(int32_t(x >> 8)) * 0x1p-24f; }

// SobolSampler::get_1d for kLanes samples at one dimension, lane j's bit-reversed sample index
// r[j], seeds lo and hi from the dimension's hash. All lanes, used or not (no remainder loop).
// Integer operations only, so every clone gives the same bits (engine/simd.h).
RF_SIMD_CLONES
void sobol_1d_lanes(const uint32_t* __restrict r, uint32_t lo, uint32_t hi, float* __restrict out) {
  for (int j = 0; j < kLanes; ++j)
    out[j] = fraction_to_float_lane(reverse_bits32(lk_hash(reverse_bits32(lk_hash(r[j], lo)), hi)));
}

// SobolSampler::get_2d likewise: both coordinates from one shuffled index, dimension 1's seed hi2.
RF_SIMD_CLONES
void sobol_2d_lanes(const uint32_t* __restrict r, uint32_t lo, uint32_t hi, uint32_t hi2,
                    float* __restrict a, float* __restrict b) {
  for (int j = 0; j < kLanes; ++j) {
    const uint32_t index = reverse_bits32(lk_hash(r[j], lo));
    a[j] = fraction_to_float_lane(reverse_bits32(lk_hash(index, hi)));
    b[j] = fraction_to_float_lane(reverse_bits32(lk_hash(sobol_sample_reversed(index, 1), hi2)));
  }
}

}  // namespace

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
  for (int k = 0; k < count; ++k) {
    if (draws[k] == 0) {
      first.skip_1d();
      continue;
    }
    const uint64_t h = first.dimension_hash();
    if (draws[k] == 1)
      sobol_1d_lanes(r, uint32_t(h), uint32_t(h >> 32), out[k][0]);
    else
      sobol_2d_lanes(r, uint32_t(h), uint32_t(h >> 32), uint32_t(mix64(h)), out[k][0], out[k][1]);
  }
  for (int j = 1; j < n; ++j) s[lane[j]].sobol_.dimension_ = first.dimension_;
}

}  // namespace rf
