// Arbitrary output variables (docs/outputs.md): per-pixel auxiliary images for compositing and
// denoising, merged by passes through the sample buffer like the main image.
//
//   albedo  the first non-specular hit's reflectance colour (textures resolved), through any
//           chain of smooth mirrors and glass in front of it, times their tints; 0 on a miss
//   normal  that hit's shading normal, world space, turned to face the incoming ray; 0 on a miss
//   depth   the camera ray's distance to its first surface, averaged over the samples that hit
//           one, and the fraction of samples that hit (coverage)
//
// In the sample buffer they are one plane of doubles per pixel of the rect, in this order: the
// AOV sample count n, then albedo RGB sums (3), normal XYZ sums (3), depth sum and hit count (2),
// each group only when its AOV is on. Sums are of unweighted values (no filter weight), so the
// per-pixel value is sum / n (depth: sum / hits).
#pragma once

#include <string>

#include "engine/math.h"

namespace rf {

struct AovSet {
  bool albedo = false, normal = false, depth = false;
  bool any() const { return albedo || normal || depth; }
  // Channels per pixel in the sample buffer's AOV plane (0 when none is on).
  int channels() const { return any() ? 1 + 3 * albedo + 3 * normal + 2 * depth : 0; }
  // Offsets of each group in a pixel's channels (valid when that AOV is on).
  int albedo_offset() const { return 1; }
  int normal_offset() const { return 1 + 3 * albedo; }
  int depth_offset() const { return 1 + 3 * albedo + 3 * normal; }
  bool operator==(const AovSet&) const = default;
};

// The canonical text: the names that are on, in the order albedo, normal, depth, joined by ','
// ("" for none). Part of the buffer header's identity.
std::string to_string(const AovSet& aovs);
// Parses a comma-separated list of names in any order ("" = none); throws std::invalid_argument
// naming an unknown or repeated name.
AovSet parse_aovs(const std::string& list);

// What one camera sample contributes.
struct AovSample {
  RGB albedo{0.0f};
  Vec3 normal{0.0f};
  float depth = 0;
  bool hit = false;
};

}  // namespace rf
