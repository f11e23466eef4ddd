// libFuzzer target: the frame-range parser (farm/frame_range.h), which reads `submit --frames`
// and the frame range of every job a client sends the coordinator. Beyond not crashing, an
// accepted range must keep the parser's promises: frames listed once each, at most kMaxFrames.
#include <cstdint>
#include <cstdlib>
#include <set>
#include <string>

#include "farm/frame_range.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  std::string text(reinterpret_cast<const char*>(data), size);
  std::vector<rf::FrameNumber> frames;
  try {
    frames = rf::parse_frame_range(text);
  } catch (const rf::FrameRangeError&) {
    return 0;
  }
  if (frames.size() > rf::kMaxFrames) std::abort();
  std::set<rf::FrameNumber> seen(frames.begin(), frames.end());
  if (seen.size() != frames.size()) std::abort();
  return 0;
}
