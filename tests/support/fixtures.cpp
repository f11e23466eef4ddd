#include "tests/support/fixtures.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "tests/support/test_support.h"

#define XXH_INLINE_ALL
#include <xxhash.h>

#include "engine/digest.h"

namespace rf::test {

Scene cornell_box(const CornellBox& c) {
  SceneOverrides ov;
  if (!c.integrator.empty()) ov.integrator = c.integrator;
  if (!c.sampler.empty()) ov.sampler = c.sampler;
  ov.width = ov.height = c.res;
  ov.spp = c.spp_per_pass * c.passes;
  ov.passes = c.passes;
  ov.seed = c.seed;
  ov.max_depth = c.max_depth;  // nullopt: the scene's
  return load_scene(source_dir() + "/scenes/cornell-box/scene.json", ov);
}

BufferHeader test_header(PassSet passes, int width, int height) {
  BufferHeader h;
  h.scene_digest = std::string(64, 'a');
  h.seed = 42;
  h.frame = 7;
  h.integrator = "path";
  h.settings = "max_depth=5 spp=4 filter=box";
  h.width = width;
  h.height = height;
  h.passes = std::move(passes);
  h.build_id = "test-build";
  h.isa = "x86_64-avx2";
  h.core_seconds = 1.5;
  return h;
}

SampleBuffer random_pass(uint32_t pass, Rect rect, bool splats, uint64_t seed, int width,
                         int height) {
  SampleBuffer b(test_header(PassSet::range(pass, pass + 1), width, height), rect, splats);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 2.0f);
  for (int y = rect.y0; y < rect.y1(); ++y)
    for (int x = rect.x0; x < rect.x1(); ++x)
      for (int s = 0; s < 3; ++s) b.add_sample(x, y, RGB(u(rng), u(rng), u(rng)));
  if (splats) {
    for (int i = 0; i < 40; ++i)
      b.add_splat(int(rng() % uint64_t(width)), int(rng() % uint64_t(height)), RGB(u(rng)));
    b.light_paths = 40;
  }
  b.rays = 1000 + pass;
  b.nonfinite_samples = pass;
  b.finish_pass();
  return b;
}

bool within_merge_tolerance(double a, double b) {
  return std::fabs(a - b) <= 1e-6 * std::max(std::fabs(a), std::fabs(b)) + 1e-12;
}

bool bits_equal(const std::vector<double>& x, const std::vector<double>& y) {
  // memcmp must not see the null data() of an empty vector (UBSan reports it).
  return x.size() == y.size() &&
         (x.empty() || std::memcmp(x.data(), y.data(), sizeof(double) * x.size()) == 0);
}

void expect_bit_identical(const SampleBuffer& a, const SampleBuffer& b) {
  const auto same = &bits_equal;
  EXPECT_EQ(a.header, b.header);
  EXPECT_EQ(a.rect, b.rect);
  EXPECT_EQ(a.count, b.count);
  EXPECT_TRUE(same(a.sum, b.sum));
  EXPECT_TRUE(same(a.sum_sq, b.sum_sq));
  EXPECT_TRUE(same(a.batch_sum, b.batch_sum));
  EXPECT_TRUE(same(a.batch_sum_sq, b.batch_sum_sq));
  EXPECT_TRUE(same(a.splat, b.splat));
  EXPECT_EQ(a.light_paths, b.light_paths);
  EXPECT_EQ(a.nonfinite_samples, b.nonfinite_samples);
  EXPECT_EQ(a.rays, b.rays);
}

size_t rfb_checksum_bytes(uint32_t version) { return version >= 3 ? 16 : 32; }

std::string rfb_with_checksum(std::string body, uint32_t version) {
  for (int b = 0; b < 4; ++b) body[8 + size_t(b)] = char((version >> (8 * b)) & 0xff);
  if (version >= 3) {
    XXH128_canonical_t c;
    XXH128_canonicalFromHash(&c, XXH3_128bits(body.data(), body.size()));
    return body + std::string(reinterpret_cast<const char*>(c.digest), sizeof c.digest);
  }
  std::string hex = sha256_hex(body);
  for (size_t i = 0; i < 32; ++i) body += char(std::stoi(hex.substr(2 * i, 2), nullptr, 16));
  return body;
}

}  // namespace rf::test
