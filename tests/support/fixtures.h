// Fixtures shared by the test suites: the shipped Cornell box with test settings, and synthetic
// sample buffers with their comparisons. One copy each, so a test reads what it varies.
#pragma once

#include <cstdint>
#include <exception>
#include <optional>
#include <string>

#include "engine/sample_buffer.h"
#include "engine/scene.h"

namespace rf::test {

// scenes/cornell-box at res x res with `passes` passes of spp_per_pass samples. What is left
// empty keeps the scene's own: integrator path, seed 1, max depth 64, the independent sampler.
struct CornellBox {
  std::string integrator;
  int res = 32;
  uint64_t spp_per_pass = 4;
  uint32_t passes = 4;
  std::optional<uint64_t> seed;
  std::optional<int> max_depth;
  std::string sampler;
};
Scene cornell_box(const CornellBox& settings);

// The header of a synthetic image: digest "aa...a", seed 42, frame 7, integrator path, a
// width x height frame, build "test-build" on "x86_64-avx2", 1.5 core-seconds.
BufferHeader test_header(PassSet passes, int width = 8, int height = 6);

// One finished pass over `rect` of a test_header(width x height) frame: 3 camera samples per pixel
// uniform in [0, 2) per channel, and with `splats` 40 random splats over the frame (40 light
// paths); rays 1000 + pass, pass non-finite samples. Deterministic in `seed`.
SampleBuffer random_pass(uint32_t pass, Rect rect, bool splats, uint64_t seed, int width = 8,
                         int height = 6);

// DESIGN.md's merge tolerance, summation order only: |a-b| <= 1e-6 max(|a|,|b|) + 1e-12.
bool within_merge_tolerance(double a, double b);

// Same length and the same bit patterns (so -0 != +0, and a NaN equals itself).
bool bits_equal(const std::vector<double>& a, const std::vector<double>& b);

// Every header field, plane and counter equal, planes bit for bit.
void expect_bit_identical(const SampleBuffer& a, const SampleBuffer& b);

inline Rect full_frame(const BufferHeader& h) { return Rect{0, 0, h.width, h.height}; }

// The checksum an .rfb of `version` ends with: 16 bytes of XXH3-128 (3), 32 of SHA-256 (1, 2).
size_t rfb_checksum_bytes(uint32_t version);
// `body` (an .rfb without its checksum) with the version field set to `version` and that
// version's checksum appended: a file as a build writing that version would, for the planes and
// header given (the caller keeps them to that version's rules).
std::string rfb_with_checksum(std::string body, uint32_t version);

// The message of the exception f() throws, or "(no exception)".
template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no exception)";
}

}  // namespace rf::test
