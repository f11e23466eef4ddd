// Image output through OpenImageIO: the multi-channel OpenEXR of a frame (R, G, B, A,
// variance.R/G/B, provenance in the header) and its tone-mapped PNG preview.
#pragma once

#include <map>
#include <string>

#include "engine/film.h"

namespace rf {

struct ImageIOError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Extra provenance attributes ("rayfarm:<key>") besides those taken from the buffer header
// (scene digest, seed, frame, integrator, settings, passes, spp, build id, ISA, core-seconds,
// relMSE and which variance estimator made the variance channels).
using Attributes = std::map<std::string, std::string>;

// Writes the frame accumulator as float EXR. Written to a temporary file then renamed, so a
// reader never sees half a file. Throws ImageIOError naming the path.
void write_exr(const std::string& path, const SampleBuffer& frame, const Attributes& extra = {});

// sRGB-encoded 8-bit PNG of the estimate scaled by 2^exposure_stops (clamped), written atomically.
void write_png(const std::string& path, const SampleBuffer& frame, float exposure_stops = 0.0f);

}  // namespace rf
