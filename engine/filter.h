// Pixel reconstruction filters by filter importance sampling (pbrt-v4): a camera sample's offset
// from the pixel centre is drawn from the filter, and its weight is filter/pdf, so a sample
// belongs to exactly one pixel and tiles stay independent. The box filter's weight is 1.
#pragma once

#include "engine/math.h"
#include "engine/scene.h"

namespace rf {

struct FilterSample {
  Vec2 offset;   // from the pixel centre, in pixels
  float weight;  // f(offset) / pdf(offset)
};

inline FilterSample sample_filter(const FilterSettings& f, Vec2 u) {
  switch (f.type) {
    case FilterType::Box:
      return {{(2.0f * u.x - 1.0f) * f.radius, (2.0f * u.y - 1.0f) * f.radius}, 1.0f};
  }
  return {{0, 0}, 1.0f};
}

}  // namespace rf
