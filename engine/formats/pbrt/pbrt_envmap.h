// pbrt-v4's image infinite lights are equal-area octahedral square maps (Clarberg 2008, +z up in
// light space); the engine's environment is a lat-long map. The importer resamples the square
// into a lat-long image once, at load: an N x N square becomes a 2N x N float OpenEXR whose texel
// is the mean of 4 x 4 nearest lookups of the square (pbrt-v4 looks its map up nearest too) at
// directions spread over the texel. The result is cached by the source's SHA-256 in
// $TMPDIR/rayfarm-pbrt-envmaps/ (a worker re-imports the scene and re-creates it there); the
// scene's asset, digest and farm bundle stay the original file.
#pragma once

#include <string>

#include "engine/math.h"

namespace rf::pbrt {

// pbrt-v4's EqualAreaSphereToSquare: a unit direction to its point of [0, 1]^2 (v = 0 is the
// image's top row).
Vec2 equal_area_square(Vec3 d);

// Converts the square map at `path` (see above) and returns the lat-long file's path. Throws
// SceneError "<what>: ..." when it cannot be read, is not square, or the cache cannot be written.
std::string octahedral_to_latlong(const std::string& path, const std::string& what);

}  // namespace rf::pbrt
