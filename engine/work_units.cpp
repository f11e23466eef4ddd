#include "engine/work_units.h"

#include "engine/scene_summary.h"

namespace rf {

TileGrid work_units(const Scene& scene, int tile_size) {
  return work_units(summarize(scene), tile_size);
}

BufferHeader frame_header(const Scene& scene, FrameNumber frame, const PassSet& passes) {
  return frame_header(summarize(scene), frame, passes);
}

}  // namespace rf
