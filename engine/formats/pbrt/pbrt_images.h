// Image textures with pbrt-v4's per-texture arithmetic the engine's textures do not have (an
// imagemap's "scale" and "invert", a "scale" texture of an image by a constant): the importer
// bakes it into a float OpenEXR once, at load, value = invert ? 1 - scale v : scale v (pbrt-v4's
// order) with v the linear texel (8-bit images sRGB-decoded unless `data`). Cached like the
// environment maps (pbrt_envmap.h) in $TMPDIR/rayfarm-pbrt-textures/ by the source's SHA-256 and
// the arithmetic; the scene's asset, digest and bundle stay the original image.
#pragma once

#include <string>

namespace rf::pbrt {

// Returns the baked file's path. Throws SceneError "<what>: ..." when it cannot be read or written.
std::string bake_image(const std::string& path, float scale, bool invert, bool data,
                       const std::string& what);

}  // namespace rf::pbrt
