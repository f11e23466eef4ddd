// A frame of a shot (docs/scene-format.md "time"): frame F starts at F / fps seconds. Frames may be
// negative (a shot's handles and pre-roll come before frame 0): any 32-bit signed integer.
#pragma once

#include <cstdint>

namespace rf {

using FrameNumber = int32_t;

// The frame's bits in the samplers' keys and the task keys' hashes: a frame >= 0 keys as it did
// when frames were unsigned, so every image of a frame >= 0 keeps its bits.
inline constexpr uint32_t frame_bits(FrameNumber frame) { return uint32_t(frame); }

}  // namespace rf
