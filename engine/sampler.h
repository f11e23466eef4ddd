// The independent sampler under the determinism contract (DESIGN.md): every number it returns is
// a pure function of (seed, frame, pass, pixel x, pixel y, sample index, dimension) for camera
// paths, and of (seed, frame, pass, light-path index, dimension) for light paths. No state is
// shared between samples, threads or tasks, so any tile or pass renders the same anywhere.
#pragma once

#include <cstdint>

#include "engine/math.h"

namespace rf {

// SplitMix64's finaliser (Steele et al. 2014): a bijective 64-bit mixer with full avalanche.
inline uint64_t mix64(uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ULL;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebULL;
  x ^= x >> 31;
  return x;
}

// Folds one more key into a running hash; mixing after every word keeps (a, b) and (b, a) apart.
inline uint64_t hash_combine(uint64_t h, uint64_t v) {
  return mix64(h ^ (v + 0x9e3779b97f4a7c15ULL + (h << 6) + (h >> 2)));
}

// Uniform float in [0, 1) from the top 24 bits (exactly representable, never 1).
inline float bits_to_unit_float(uint64_t bits) {
  return float(bits >> 40) * 0x1p-24f;
}

class IndependentSampler {
 public:
  // Domain tags keep camera samples and light paths of the same indices independent.
  static constexpr uint64_t kCameraDomain = 0x63616d657261ULL;  // "camera"
  static constexpr uint64_t kLightDomain = 0x6c69676874ULL;     // "light"

  void start_camera_sample(uint64_t seed, uint32_t frame, uint32_t pass, int px, int py,
                           uint64_t sample_index) {
    uint64_t h = hash_combine(mix64(seed), kCameraDomain);
    h = hash_combine(h, (uint64_t(frame) << 32) | pass);
    h = hash_combine(h, (uint64_t(uint32_t(px)) << 32) | uint32_t(py));
    base_ = hash_combine(h, sample_index);
    dimension_ = 0;
  }
  void start_light_path(uint64_t seed, uint32_t frame, uint32_t pass, uint64_t light_path_index) {
    uint64_t h = hash_combine(mix64(seed), kLightDomain);
    h = hash_combine(h, (uint64_t(frame) << 32) | pass);
    base_ = hash_combine(h, light_path_index);
    dimension_ = 0;
  }
  float get_1d() { return bits_to_unit_float(mix64(base_ + 0x9e3779b97f4a7c15ULL * ++dimension_)); }
  Vec2 get_2d() {
    float a = get_1d();
    return {a, get_1d()};
  }
  uint32_t dimension() const { return dimension_; }

 private:
  uint64_t base_ = 0;
  uint32_t dimension_ = 0;
};

// The sampler integrators draw from: a tag and a switch over the kinds (RenderSettings::sampler).
// Only the independent kind exists so far; the same start/get interface serves every kind.
class Sampler {
 public:
  enum class Kind : uint8_t { Independent };
  explicit Sampler(Kind kind = Kind::Independent) : kind_(kind) {}

  void start_camera_sample(uint64_t seed, uint32_t frame, uint32_t pass, int px, int py,
                           uint64_t sample_index) {
    independent_.start_camera_sample(seed, frame, pass, px, py, sample_index);
  }
  void start_light_path(uint64_t seed, uint32_t frame, uint32_t pass, uint64_t light_path_index) {
    independent_.start_light_path(seed, frame, pass, light_path_index);
  }
  float get_1d() { return independent_.get_1d(); }
  Vec2 get_2d() { return independent_.get_2d(); }
  Kind kind() const { return kind_; }

 private:
  Kind kind_;
  IndependentSampler independent_;
};

}  // namespace rf
