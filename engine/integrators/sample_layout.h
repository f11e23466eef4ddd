// The sample-dimension layout: which draw of a camera sample's sampler holds which number.
//
// A camera sample's sampler hands out numbers slot by slot (Sampler: a slot is one get_1d or
// get_2d, or a skip of one); each slot's number is a pure function of (seed, frame, pass, pixel,
// sample index, slot), so an image is a function of which slot each estimator reads for what.
// This header is that table. The layout, in slot order:
//
//   camera     slot 0  filter offset (2D; the first draw: joint pairs are stratified with it)
//              slot 1  lens point (2D; skipped by a pinhole camera)
//   vertex d   (path) kVertexDraws slots per scattering vertex, in the order of VertexDraw:
//              light choice (1D, read by the light BVH only), light point (2D), lobe choice
//              (1D), direction (2D), roulette (1D). Vertices 0 and 1 draw their light point and
//              direction as joint pairs (joint_pair below); later ones as padded 2D draws.
//   vertex d   (ir, ppm, direct, whitted, ao) their own per-vertex draws, in their estimators.
//
// Every vertex consumes its slots whether or not it reads them (a skip), so a material change
// does not move the numbers of later vertices, and the lockstep draws of a packet's lanes
// (Sampler::get_lanes) read the same slots as one lane alone.
//
// Adding a dimension (motion blur's time, path guiding, media) must not move an existing image:
// - not inside this order: a slot inserted before a vertex's draws renumbers every later slot,
//   and skipping it where the feature is off still consumes it;
// - a draw a vertex makes only when the feature is on goes after that vertex's existing draws,
//   and only where the scene has the feature; a scene without it then draws exactly what it drew
//   before. A per-sample number that every vertex may need (a camera sample's time) does not fit
//   there;
// - so per-sample numbers get their own hashed stream: a slot number outside the counter's
//   range (Sampler::kStreamSlots and up: no path has 2^31 slots), hashed like every slot, read
//   without advancing the counter (StreamSlot below; the camera sample's time is the first).
//   Existing slots keep their numbers, and the stream is as well stratified as any 2D slot.
// docs/design.md ("The sample-dimension layout") says the same for the reader of the design.
#pragma once

#include <cstdint>

#include "engine/sampler.h"

namespace rf {

// The camera sample's slots.
enum CameraDraw { kCameraFilter, kCameraLens, kCameraDraws };

// The hashed streams (Sampler::get_1d_stream), one slot each.
enum StreamSlot : uint32_t {
  kTimeStream = Sampler::kStreamSlots,  // a camera sample's time in the shutter (moving scenes)
};

// A path vertex's draws, in slot order (each a skip where nothing reads it).
enum VertexDraw { kULight, kUPoint, kUChoice, kUDir, kURoulette, kVertexDraws };

// The first vertex's light point and direction are stratified jointly with the camera sample's
// filter offset (Sampler::get_2d_joint, pairs 0 and 1), the second vertex's with the first
// vertex's direction (pairs 2 and 3); later vertices' draws are padded. This lowers the error
// where veach-mis's sits, the small light's image in the smoothest plate, and the variance of the
// Cornell box's one-bounce light (docs/performance.md, "Draws stratified with the pixel: joint
// pairs").
constexpr int kPointPair = 0, kDirPair = 1, kJointDepths = 2;
// The joint pair of a vertex's light point or direction (kPointPair or kDirPair), or -1 (padded).
inline int joint_pair(int depth, int pair) { return depth < kJointDepths ? pair + 2 * depth : -1; }
// Its lockstep draw code (Sampler::get_lanes).
inline uint8_t vertex_draw(int depth, int pair) {
  const int k = joint_pair(depth, pair);
  return k >= 0 ? uint8_t(Sampler::kJointDraw + k) : 2;
}
// Its draw by one lane alone.
inline Vec2 vertex_2d(Sampler& s, bool needed, int depth, int pair) {
  const int k = joint_pair(depth, pair);
  return k >= 0 ? s.get_2d_joint_if(needed, k) : s.get_2d_if(needed);
}

}  // namespace rf
