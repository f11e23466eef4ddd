// Frame ranges in Open Job Description's range syntax: comma-separated items, each a frame
// "7", a range "1-10" or a stepped range "1-10:2" / "10-1:-3" (the step's sign must match the
// range's direction). Frames may be negative ("-10--1", "-3-3", "5--5:-2"), and are listed at most
// once, at most kMaxFrames in all.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

#include "engine/frame.h"

namespace rf {

struct FrameRangeError : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

inline constexpr size_t kMaxFrames = 1000000;
inline constexpr int64_t kMinFrame = INT32_MIN, kMaxFrame = INT32_MAX;  // engine/frame.h

// The frames in the order written. Throws FrameRangeError saying which item is wrong and why.
std::vector<FrameNumber> parse_frame_range(const std::string& text);

// The frames, sorted, as the range syntax above writes them most briefly: runs of consecutive
// frames as "A-B", the rest one by one ("1-5,7,9-12", "-3--1,2"); "" for none. parse_frame_range
// reads it back (as a set: sorted, each once).
std::string frame_range_text(std::vector<FrameNumber> frames);

// A per-frame file pattern: each run of '#' becomes the frame number, zero-padded to the run's
// length ("shot.####.json", 7 -> "shot.0007.json"; -7 -> "shot.-007.json", the sign in the width
// as printf's "%04d" puts it). A name without '#' is returned unchanged.
// With `printf_style` (output templates), "%d" and "%0Nd" (N from 1 to 10) are frame numbers
// too, "%%" a percent sign; any other '%' stays as written.
std::string expand_frame_pattern(const std::string& pattern, FrameNumber frame,
                                 bool printf_style = false);
// Whether a pattern names the frame at all (expand_frame_pattern gives each frame its own name).
bool is_frame_pattern(const std::string& pattern, bool printf_style = false);

}  // namespace rf
