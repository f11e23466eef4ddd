// Work units (DESIGN.md "Work units"): a task is (frame, rect, pass). The frame selects the seed
// stream, the rect is a tile (or the whole frame for splatting integrators), the pass one
// independent estimate of the image. Tasks are values: any Renderer of the scene renders any of
// them, anywhere, in any order, to the same pixels.
#pragma once

#include <cstdint>
#include <vector>

#include "engine/frame.h"
#include "engine/sample_buffer.h"
#include "engine/scene.h"

namespace rf {

struct TaskKey {
  FrameNumber frame = 0;
  Rect rect;
  uint32_t pass = 0;
  bool operator==(const TaskKey&) const = default;
};

// The rects a frame is split into: tiles of tile_size (row-major, clipped at the border), or the
// whole frame for splatting integrators (and for tile_size <= 0).
TileGrid work_units(const Scene& scene, int tile_size);

// The header every buffer of this scene's frame carries, for the given passes: scene digest,
// seed, frame, integrator and settings text, resolution, this build and CPU kind.
BufferHeader frame_header(const Scene& scene, FrameNumber frame, const PassSet& passes);

}  // namespace rf
