// Samplers under the determinism contract (DESIGN.md): every number they return is a pure
// function of (seed, frame, pass, pixel x, pixel y, sample index, dimension) for camera paths, and
// of (seed, frame, pass, light-path index, dimension) for light paths. No state is shared between
// samples, threads or tasks, so any tile or pass renders the same anywhere.
//
// - IndependentSampler: hashed uniform numbers.
// - SobolSampler: padded, shuffled, Owen-scrambled 2D Sobol (pbrt-v4's PaddedSobolSampler with
//   Burley 2020, "Practical Hash-based Owen Scrambling"). See the class. Its joint pairs
//   (get_2d_joint) are the exception to padding: draws stratified with the sample's first one.
// - Sampler: the tag-and-switch front the integrators use (RenderSettings::sampler). Its
//   SobolSequence kind ("sobol-sequence") keys the Sobol scrambles without the pass and gives
//   pass p the sample indices p * spp_per_pass + i: one scrambled sequence per pixel, each pass a
//   block of it (docs/design.md, "Passes, seeds and determinism").
#pragma once

#include <array>
#include <cassert>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "engine/frame.h"
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
inline float bits_to_unit_float(uint64_t bits) { return float(bits >> 40) * 0x1p-24f; }

class IndependentSampler {
 public:
  // Domain tags keep camera samples and light paths of the same indices independent.
  static constexpr uint64_t kCameraDomain = 0x63616d657261ULL;  // "camera"
  static constexpr uint64_t kLightDomain = 0x6c69676874ULL;     // "light"

  void start_camera_sample(uint64_t seed, FrameNumber frame, uint32_t pass, int px, int py,
                           uint64_t sample_index) {
    start_camera_sample(pixel_key(seed, frame, pass, px, py), sample_index);
  }
  // The hashes the samples of one pixel and pass share, and the start from them.
  static uint64_t pixel_key(uint64_t seed, FrameNumber frame, uint32_t pass, int px, int py) {
    uint64_t h = hash_combine(mix64(seed), kCameraDomain);
    h = hash_combine(h, (uint64_t(frame_bits(frame)) << 32) | pass);
    return hash_combine(h, (uint64_t(uint32_t(px)) << 32) | uint32_t(py));
  }
  void start_camera_sample(uint64_t pixel, uint64_t sample_index) {
    base_ = hash_combine(pixel, sample_index);
    dimension_ = 0;
  }
  void start_light_path(uint64_t seed, FrameNumber frame, uint32_t pass,
                        uint64_t light_path_index) {
    uint64_t h = hash_combine(mix64(seed), kLightDomain);
    h = hash_combine(h, (uint64_t(frame_bits(frame)) << 32) | pass);
    base_ = hash_combine(h, light_path_index);
    dimension_ = 0;
  }
  float get_1d() { return bits_to_unit_float(mix64(base_ + 0x9e3779b97f4a7c15ULL * ++dimension_)); }
  Vec2 get_2d() {
    float a = get_1d();
    return {a, get_1d()};
  }
  void skip_1d() { ++dimension_; }
  void skip_2d() { dimension_ += 2; }
  uint32_t dimension() const { return dimension_; }
  // The number at `slot` of a hashed stream (Sampler::kStreamSlots and up), the counter left
  // where it is.
  float get_1d_at(uint32_t slot) {
    return bits_to_unit_float(mix64(base_ + 0x9e3779b97f4a7c15ULL * (uint64_t(slot) + 1)));
  }

 private:
  uint64_t base_ = 0;
  uint32_t dimension_ = 0;
};

// Reverses the 32 bits of v (bit 0 <-> bit 31).
inline uint32_t reverse_bits32(uint32_t v) {
  v = __builtin_bswap32(v);
  v = ((v >> 4) & 0x0f0f0f0fu) | ((v & 0x0f0f0f0fu) << 4);
  v = ((v >> 2) & 0x33333333u) | ((v & 0x33333333u) << 2);
  return ((v >> 1) & 0x55555555u) | ((v & 0x55555555u) << 1);
}

// Generator matrix columns of Sobol's second dimension (primitive polynomial x + 1, m_1 = 1):
// column 0 is the top bit and column j = column j-1 ^ (column j-1 >> 1), i.e. Pascal's triangle
// mod 2. The first dimension's matrix is the identity reversed (van der Corput).
inline constexpr std::array<uint32_t, 32> kSobolDimension1 = [] {
  std::array<uint32_t, 32> c{};
  c[0] = 1u << 31;
  for (int j = 1; j < 32; ++j) c[j] = c[j - 1] ^ (c[j - 1] >> 1);
  return c;
}();

// Sample `index` of Sobol dimension 0 or 1, bit-reversed. Column j of dimension 1's matrix has
// bit 31 - m set iff binomial(j, m) is odd, which by Lucas' theorem is iff the bits of m are a
// subset of those of j. So bit m of the reversed sample is the XOR of the index bits k whose
// positions are supersets of m: a superset (zeta) transform over the 5-bit positions, one
// shift-mask-XOR per position bit, with no table (not a lookup per byte: that is four scalar
// loads per lane in the SIMD draws, sampler.cpp).
inline uint32_t sobol_sample_reversed(uint32_t index, int dimension) {
  if (dimension == 0) return index;
  uint32_t y = index;
  y ^= (y >> 1) & 0x55555555u;
  y ^= (y >> 2) & 0x33333333u;
  y ^= (y >> 4) & 0x0f0f0f0fu;
  y ^= (y >> 8) & 0x00ff00ffu;
  y ^= y >> 16;
  return y;
}

// Sample `index` of Sobol dimension 0 or 1, as a 32-bit fixed-point fraction.
inline uint32_t sobol_sample(uint32_t index, int dimension) {
  return reverse_bits32(sobol_sample_reversed(index, dimension));
}

// A hash in which each output bit depends only on the input bits below it (xor with an even
// multiple, add, multiply by an odd number), so it is a bijection that, applied to bit-reversed
// values, is a nested uniform (Owen) scramble. Laine-Karras 2011 as improved by Vegdahl 2021
// ("Building a Better LK Hash"); seed should be well mixed.
inline uint32_t lk_hash(uint32_t x, uint32_t seed) {
  x ^= x * 0x3d20adeau;
  x += seed;
  x *= (seed >> 16) | 1u;
  x ^= x * 0x05526c56u;
  x ^= x * 0x53a22864u;
  return x;
}

// Owen scramble of a 32-bit fraction: bit k (from the top) is flipped by a hash of the bits above
// it. Applied to an integer index it flips bit k by a hash of the bits above k, so it maps each
// aligned block [m 2^j, (m+1) 2^j) onto another aligned block of the same size.
inline uint32_t owen_scramble(uint32_t x, uint32_t seed) {
  return reverse_bits32(lk_hash(reverse_bits32(x), seed));
}

// owen_scramble(sobol_sample(index, dimension), seed), with the reversals that cancel removed.
inline uint32_t scrambled_sobol(uint32_t index, int dimension, uint32_t seed) {
  return reverse_bits32(lk_hash(sobol_sample_reversed(index, dimension), seed));
}

// 32-bit fixed-point fraction to a float in [0, 1): the top 24 bits, exactly representable (the
// conversion is from a signed int, which every SIMD level has; below 2^24 it is the same value).
inline float fraction_to_float(uint32_t x) { return float(int32_t(x >> 8)) * 0x1p-24f; }

// One sample's Sobol draw at a dimension slot with hash h (SobolSampler below; also a loop body
// over lanes, Sampler::get_lanes): the sample index, bit-reversed, Owen-scrambled with the slot's
// seed (its shuffle), then each coordinate scrambled with its own seed.
inline uint32_t sobol_shuffled_index(uint32_t index_reversed, uint64_t h) {
  return reverse_bits32(lk_hash(index_reversed, uint32_t(h)));
}
inline float sobol_draw_1d(uint32_t index_reversed, uint64_t h) {
  return fraction_to_float(
      scrambled_sobol(sobol_shuffled_index(index_reversed, h), 0, uint32_t(h >> 32)));
}
// Sobol dimensions 0 and 1 at a (shuffled) index, each scrambled with its own seed from h.
inline Vec2 sobol_point_2d(uint32_t index, uint64_t h) {
  return {fraction_to_float(scrambled_sobol(index, 0, uint32_t(h >> 32))),
          fraction_to_float(scrambled_sobol(index, 1, uint32_t(mix64(h))))};
}
inline Vec2 sobol_draw_2d(uint32_t index_reversed, uint64_t h) {
  return sobol_point_2d(sobol_shuffled_index(index_reversed, h), h);
}

// The index transforms of the joint draws (SobolSampler::get_2d_joint): pair k maps the shuffled
// index n of the camera sample's first draw to L_k n, a linear map over GF(2) of its low 12 bits
// whose output bit j is input bit j XOR some input bits above j (row j of kJointRows[k]: the input
// bits it sums). Such a map is a bijection that sends every aligned block of 2^m indices onto an
// aligned block of the same size, so the pair, (C0 L_k n, C1 L_k n) in Sobol's dimensions 0 and 1,
// is a (0,m,2)-net over any 2^m samples like every other draw, and with the first draw (C0 n, C1 n)
// the four coordinates form one (scrambled) digital net: a 4D elementary box of volume 2^(t-m)
// holds 2^t of the 2^m samples, where independently shuffled draws give no 4D stratification at
// all. The rows were found by a search over such maps for the smallest t at m = 3..12
// (bench/joint_nets.py): t <= 4 for m <= 12 with the first draw, for either pair, and between the
// two pairs. Maps of equal t differ much in a render's error, so these were checked by renders
// (docs/performance.md, "Draws stratified with the pixel").
// Pairs 2 and 3 are L_0 L_1 and L_1 L_1: with pair 1 they stand as pairs 0 and 1 stand with the
// first draw (the same t-values, since L_1 maps aligned blocks to aligned blocks), so a path's
// second vertex is stratified with the first vertex's direction as the first is with the pixel.
constexpr int kJointPairs = 4;
constexpr int kJointBits = 12;
inline constexpr uint16_t kJointRows[2][kJointBits] = {
    {0xa27, 0x15a, 0x98c, 0xa58, 0xc30, 0x1e0, 0xc40, 0x080, 0xb00, 0xa00, 0xc00, 0x800},
    {0x3d7, 0xdda, 0x564, 0xb88, 0xa50, 0x6a0, 0xe40, 0x580, 0x900, 0x200, 0xc00, 0x800}};
// The maps by columns: column i is the output bits that input bit i feeds.
inline constexpr std::array<std::array<uint32_t, kJointBits>, kJointPairs> kJointColumns = [] {
  std::array<std::array<uint32_t, kJointBits>, kJointPairs> c{};
  for (int k = 0; k < 2; ++k)
    for (int j = 0; j < kJointBits; ++j)
      for (int i = 0; i < kJointBits; ++i)
        if ((kJointRows[k][j] >> i) & 1) c[k][i] |= 1u << j;
  auto apply = [&](int a, uint32_t v) {  // L_a v
    uint32_t y = 0;
    for (int j = 0; j < kJointBits; ++j)
      if ((v >> j) & 1) y ^= c[a][j];
    return y;
  };
  for (int i = 0; i < kJointBits; ++i) c[2][i] = apply(0, c[1][i]), c[3][i] = apply(1, c[1][i]);
  return c;
}();
// L_k n (bits 12 and up unchanged); masks only, so it vectorises over lanes.
inline uint32_t joint_index(uint32_t n, int k) {
  uint32_t y = n & ~((1u << kJointBits) - 1);
  for (int i = 0; i < kJointBits; ++i) y ^= kJointColumns[k][i] & (0u - ((n >> i) & 1u));
  return y;
}
// Joint pair k of a sample: its index is the first draw's shuffled index (hash h0), transformed;
// its coordinates are scrambled with its own slot's seeds (hash h), as sobol_draw_2d's.
inline Vec2 sobol_draw_2d_joint(uint32_t index_reversed, uint64_t h0, uint64_t h, int k) {
  return sobol_point_2d(joint_index(sobol_shuffled_index(index_reversed, h0), k), h);
}

// Padded, shuffled, Owen-scrambled 2D Sobol. Every get_1d/get_2d call is one dimension slot d,
// and draws from Sobol dimensions 0 (and 1), the (0,2)-sequence, independently of other slots:
// - the sample index is Owen-scrambled as an integer with a seed hashed from (seed, frame, pass,
//   pixel, d), which sends the pixel's first 2^k samples of a pass onto an aligned block of 2^k
//   Sobol indices: a (0,k,2)-net. Different slots get different index orders, so slots are
//   decorrelated (this is the "padding" by shuffling);
// - each coordinate is then Owen-scrambled with its own hashed seed, which keeps the net
//   property and makes each point uniformly distributed, so every pass is an unbiased,
//   independently scrambled estimate.
// So, for N = 2^k samples of a pixel in a pass, every 2D slot has exactly one point in each
// elementary interval of area 1/N, and every 1D slot one point in each [i/N, (i+1)/N). Sample
// indices beyond 2^32 fold their high bits into the key. Light paths use IndependentSampler.
class SobolSampler {
 public:
  static constexpr uint64_t kDomain = 0x736f626f6cULL;  // "sobol"

  void start_camera_sample(uint64_t seed, FrameNumber frame, uint32_t pass, int px, int py,
                           uint64_t sample_index) {
    const SobolSampler key = keyed(pixel_key(seed, frame, pass, px, py), sample_index >> 32);
    start_camera_sample(key, sample_index);
  }
  // The hashes the samples of one pixel and pass share (pixel_key, then keyed by the sample
  // index's high bits), and the start from a sampler so keyed.
  static uint64_t pixel_key(uint64_t seed, FrameNumber frame, uint32_t pass, int px, int py) {
    uint64_t h = hash_combine(mix64(seed), kDomain);
    h = hash_combine(h, (uint64_t(frame_bits(frame)) << 32) | pass);
    return hash_combine(h, (uint64_t(uint32_t(px)) << 32) | uint32_t(py));
  }
  static SobolSampler keyed(uint64_t pixel, uint64_t index_high) {
    SobolSampler k;
    k.key_ = hash_combine(pixel, index_high);
    k.key_term_ = 0x9e3779b97f4a7c15ULL + (k.key_ << 6) + (k.key_ >> 2);
    return k;
  }
  void start_camera_sample(const SobolSampler& keyed, uint64_t sample_index) {
    key_ = keyed.key_, key_term_ = keyed.key_term_;
    index_reversed_ = reverse_bits32(uint32_t(sample_index));
    dimension_ = 0;
  }
  float get_1d() { return sobol_draw_1d(index_reversed_, dimension_hash()); }
  Vec2 get_2d() { return sobol_draw_2d(index_reversed_, dimension_hash()); }
  // A 2D draw at the next slot, stratified jointly with the sample's first draw (slot 0, the
  // camera's filter offset) as joint pair k < kJointPairs (sobol_draw_2d_joint).
  Vec2 get_2d_joint(int k) {
    assert(unsigned(k) < unsigned(kJointPairs));
    const uint64_t h = dimension_hash();
    return sobol_draw_2d_joint(index_reversed_, first_draw_hash(), h, k);
  }
  void skip_1d() { ++dimension_; }
  void skip_2d() { ++dimension_; }
  uint32_t dimension() const { return dimension_; }
  // A 1D draw at `slot` of a hashed stream (Sampler::kStreamSlots and up), stratified over a
  // pixel's samples as every slot is; the counter is left where it is.
  float get_1d_at(uint32_t slot) {
    const uint32_t next = dimension_;
    dimension_ = slot;
    const float v = get_1d();
    dimension_ = next;
    return v;
  }

 private:
  friend class Sampler;  // its lockstep draws (get_lanes) share dimension_hash() across lanes
  // hash_combine(key_, dimension_++), its key-only terms summed once per sample (the same value).
  uint64_t dimension_hash() { return mix64(key_ ^ (uint64_t(dimension_++) + key_term_)); }
  // dimension_hash() of slot 0.
  uint64_t first_draw_hash() const { return mix64(key_ ^ key_term_); }
  uint64_t key_ = 0, key_term_ = 0;
  uint32_t index_reversed_ = 0;
  uint32_t dimension_ = 0;
};

// The sampler integrators draw from: a tag and a switch over the kinds (RenderSettings::sampler).
// The Sobol kind draws light paths (start_light_path) from the independent sampler: a light path
// has no pixel to stratify over, and its index already spreads it over the pass.
class Sampler {
 public:
  enum class Kind : uint8_t { Independent, Sobol, SobolSequence };
  // spp_per_pass: only SobolSequence uses it (pass p draws sample indices p * spp_per_pass + i).
  explicit Sampler(Kind kind = Kind::Independent, uint64_t spp_per_pass = 0)
      : kind_(kind), spp_per_pass_(spp_per_pass) {}

  void start_camera_sample(uint64_t seed, FrameNumber frame, uint32_t pass, int px, int py,
                           uint64_t sample_index) {
    sobol_active_ = kind_ != Kind::Independent;
    if (kind_ == Kind::SobolSequence)  // one scrambled sequence per pixel; a pass is a block of it
      sobol_.start_camera_sample(seed, frame, kSequencePass, px, py,
                                 uint64_t(pass) * spp_per_pass_ + sample_index);
    else if (sobol_active_)
      sobol_.start_camera_sample(seed, frame, pass, px, py, sample_index);
    else
      independent_.start_camera_sample(seed, frame, pass, px, py, sample_index);
  }
  // start_camera_sample(seed, frame, pass, px, py, first_index + i) of s[i] for i < n (samplers
  // of one kind and spp_per_pass), with the hashes the samples share computed once: each s[i] is
  // started as it would be alone.
  static void start_camera_samples(Sampler* s, int n, uint64_t seed, FrameNumber frame,
                                   uint32_t pass, int px, int py, uint64_t first_index);
  void start_light_path(uint64_t seed, FrameNumber frame, uint32_t pass,
                        uint64_t light_path_index) {
    sobol_active_ = false;
    independent_.start_light_path(seed, frame, pass, light_path_index);
  }
  float get_1d() { return sobol_active_ ? sobol_.get_1d() : independent_.get_1d(); }
  Vec2 get_2d() { return sobol_active_ ? sobol_.get_2d() : independent_.get_2d(); }
  // Consume the dimension get_1d / get_2d would, without computing its value: for numbers a
  // caller would not read. Every later number is the one it would have been.
  void skip_1d() { sobol_active_ ? sobol_.skip_1d() : independent_.skip_1d(); }
  void skip_2d() { sobol_active_ ? sobol_.skip_2d() : independent_.skip_2d(); }
  // get_1d / get_2d when `needed`, else the skip and 0.
  float get_1d_if(bool needed) { return needed ? get_1d() : (skip_1d(), 0.0f); }
  Vec2 get_2d_if(bool needed) { return needed ? get_2d() : (skip_2d(), Vec2{0.0f, 0.0f}); }
  // A 2D draw that the Sobol kinds stratify jointly with the camera sample's filter offset (its
  // first draw) as joint pair k < kJointPairs (SobolSampler::get_2d_joint); the independent
  // sampler and light paths draw as get_2d. Same dimensions consumed as get_2d.
  Vec2 get_2d_joint(int k) {
    return sobol_active_ ? sobol_.get_2d_joint(k) : independent_.get_2d();
  }
  Vec2 get_2d_joint_if(bool needed, int k) {
    return needed ? get_2d_joint(k) : (skip_2d(), Vec2{0.0f, 0.0f});
  }
  Kind kind() const { return kind_; }

  // Hashed streams: slots from kStreamSlots up, which the dimension counter never reaches (no
  // path draws 2^31 numbers). A stream's number is hashed like every slot's and read without
  // moving the counter, so a feature that reads one (a camera sample's time) leaves every other
  // number of the sample as it was (integrators/sample_layout.h).
  static constexpr uint32_t kStreamSlots = 1u << 31;
  float get_1d_stream(uint32_t slot) {
    assert(slot >= kStreamSlots);
    return sobol_active_ ? sobol_.get_1d_at(slot) : independent_.get_1d_at(slot);
  }

  // Lockstep draws for the samples of one pixel traced together (the path tracer's packets).
  // draws[k] is 1 (a get_1d), 2 (a get_2d), 0 (a skip) or kJointDraw + p (a get_2d_joint(p)): for
  // each j < n, lane i = lane[j] gets
  // out[k][c][i] = coordinate c of its k-th draw, bit for bit what s[i] would give drawing them
  // one by one, with the same dimensions consumed. Sobol samplers started for one pixel and pass
  // and at one dimension share each dimension's hash, and their per-sample scrambles run in SIMD
  // where the CPU has it; otherwise (the independent kind, or lanes whose keys differ) each lane
  // draws alone. The entries of lanes not named are left unspecified.
  static constexpr int kMaxLanes = 16;
  static constexpr uint8_t kJointDraw = 3;
  using LaneDraws = float[2][kMaxLanes];
  static void get_lanes(Sampler* s, const int* lane, int n, const uint8_t* draws, int count,
                        LaneDraws* out);

 private:
  // Whether lanes lane[0..n) can share one dimension hash (see get_lanes).
  static bool sobol_lockstep(const Sampler* s, const int* lane, int n);
  // The pass key of SobolSequence's scrambles: one for all passes, apart from Sobol's passes.
  static constexpr uint32_t kSequencePass = 0xffffffffu;
  Kind kind_;
  uint64_t spp_per_pass_;
  bool sobol_active_ = false;
  IndependentSampler independent_;
  SobolSampler sobol_;
};

// "independent" or "sobol" (RenderSettings::sampler); throws std::invalid_argument otherwise.
inline Sampler::Kind kind_from_name(const std::string& name) {
  if (name == "independent") return Sampler::Kind::Independent;
  if (name == "sobol") return Sampler::Kind::Sobol;
  if (name == "sobol-sequence") return Sampler::Kind::SobolSequence;
  throw std::invalid_argument("unknown sampler '" + name +
                              "' (expected independent, sobol or sobol-sequence)");
}

inline const char* kind_name(Sampler::Kind kind) {
  return kind == Sampler::Kind::Sobol           ? "sobol"
         : kind == Sampler::Kind::SobolSequence ? "sobol-sequence"
                                                : "independent";
}

}  // namespace rf
