// Texture lookups for material parameters: constant, checkerboard and image textures.
//
// Image textures go through OpenImageIO's TextureSystem (a private one per evaluator): tiled,
// MIP-mapped, cached in at most `cache_megabytes`, filtered trilinearly over a footprint, wrapping
// periodically.
//
// Conventions and decisions:
// - uv (0,0) is the BOTTOM-left of an image and v grows upwards (OpenGL/pbrt), so the image's
//   first (top) scanline is at v = 1. Every kind first maps uv' = uv * uv_scale + uv_offset.
// - Results are linear RGB. OpenImageIO 2.4 returns stored values as they are (an 8-bit 128 reads
//   0.502, whatever "oiio:ColorSpace" says) and filters and MIP-maps those stored values. So a
//   colour image stored in integers (8/16-bit PNG, JPEG, TIFF: is_data false and not tagged
//   linear) is sRGB-decoded exactly once, by us, before any filtering.
// - Memory: OIIO MIP-maps an untiled or unmipped file itself ("automip") only after raising its
//   cache to twice that image's size, which breaks the bound for large images. So, when it is
//   built, the evaluator rewrites every image that is not already a tiled, MIP-mapped file (a
//   maketx ".tx"), and every image it must decode, as a tiled (64x64), MIP-mapped OpenEXR in a
//   private temporary directory (half for 8-bit and half sources, float otherwise), with
//   box-filtered levels that keep the image's mean, and points the TextureSystem at it. This
//   streams 64 rows at a time, so it needs a few strips of memory whatever the image size (plus
//   whatever the decoder holds; PNG and JPEG decoders may hold the image). The peak RSS is then
//   the cache plus a few MB. The cost is a pass over each image at start-up and its
//   uncompressed scratch copy on disk ($TMPDIR, 4/3 of the texels), removed with the evaluator;
//   ready-made .tx files skip both.
// - A checkerboard is colour a where floor(u') + floor(v') is even, else b; with a footprint it is
//   box-filtered in closed form over a square of that width.
// - Colour channels are read as stored, never multiplied by the image's alpha (OIIO associates
//   alpha by default for PNG and TIFF; the engine has no cut-outs, so alpha is not coverage).
// - FloatParam textures read their single channel, or the luminance of a colour.
// - Remapping after the lookup (Texture::scale, channel, squared; defaults are the identity): the
//   RGB is multiplied by scale; a FloatParam with channel c in 0..2 reads (scale * RGB)[c]
//   (a one- or two-channel image, grey or grey-alpha, gives its grey for every c), channel 3
//   reads the alpha (1 when the image has none, never scaled); then, if squared, the scalar is
//   squared. ColorParams ignore channel and squared.
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "engine/math.h"
#include "engine/scene.h"

namespace rf {

// The sRGB transfer functions (IEC 61966-2-1), piecewise, on [0, 1].
float srgb_to_linear(float encoded);
float linear_to_srgb(float linear);

class TextureEvaluator {
 public:
  // Opens every image texture of the scene (rewriting images as above). Throws SceneError naming
  // the texture and file if one cannot be read or rewritten.
  explicit TextureEvaluator(const Scene& scene, size_t cache_megabytes = 256);
  ~TextureEvaluator();
  TextureEvaluator(const TextureEvaluator&) = delete;
  TextureEvaluator& operator=(const TextureEvaluator&) = delete;

  // uv_footprint: approximate width of the lookup in (unscaled) uv units; 0 = finest level,
  // bilinear. It becomes OIIO's derivatives of a square footprint, dsdx = fp |uv_scale.x| and
  // dtdy = fp |uv_scale.y| (cross terms 0), so the lookup blends the two MIP levels whose texels
  // are about that wide (trilinear). Thread-safe; takes no lock of its own (OIIO's cache has its
  // own).
  RGB eval(const ColorParam& p, Vec2 uv, float uv_footprint) const;
  float eval(const FloatParam& p, Vec2 uv, float uv_footprint) const;

  size_t cache_megabytes() const { return cache_megabytes_; }

 private:
  struct Image;  // per image texture: OIIO handle, channel count
  // Fills out[0..2] (colour) or out[0] (want_scalar: single channel or luminance).
  void lookup(int index, Vec2 uv, float uv_footprint, bool want_scalar, float* out) const;
  void open_image(int index);
  void release();

  std::vector<Texture> textures_;  // a copy: the evaluator may outlive the scene it came from
  size_t cache_megabytes_;
  void* texture_system_ = nullptr;  // OIIO::TextureSystem, kept out of this header
  std::vector<Image> images_;       // indexed like Scene::textures (unused for other kinds)
  std::string temp_dir_;            // rewritten images; removed by the destructor
};

}  // namespace rf
