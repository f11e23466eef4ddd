// Conversions between the wire's render overrides and the engine's scene overrides, shared by
// the client (submit), the coordinator (validation) and the worker (rendering), so all three
// apply a job's settings the same way.
#pragma once

#include "engine/scene.h"
#include "proto/rayfarm.pb.h"

namespace rf {

inline SceneOverrides to_scene_overrides(const rayfarm::v1::RenderOverrides& o) {
  SceneOverrides s;
  if (o.has_spp()) s.spp = o.spp();
  if (o.has_passes()) s.passes = o.passes();
  if (o.has_integrator()) s.integrator = o.integrator();
  if (o.has_seed()) s.seed = o.seed();
  if (o.has_width()) s.width = int(o.width());
  if (o.has_height()) s.height = int(o.height());
  if (o.has_max_depth()) s.max_depth = o.max_depth();
  if (o.has_filter()) s.filter = o.filter();
  if (o.has_noise_target()) s.noise_target = o.noise_target();
  if (o.has_sampler()) s.sampler = o.sampler();
  return s;
}

inline rayfarm::v1::RenderOverrides to_wire_overrides(const SceneOverrides& s) {
  rayfarm::v1::RenderOverrides o;
  if (s.spp) o.set_spp(*s.spp);
  if (s.passes) o.set_passes(*s.passes);
  if (s.integrator) o.set_integrator(*s.integrator);
  if (s.seed) o.set_seed(*s.seed);
  if (s.width) o.set_width(uint32_t(*s.width));
  if (s.height) o.set_height(uint32_t(*s.height));
  if (s.max_depth) o.set_max_depth(*s.max_depth);
  if (s.filter) o.set_filter(*s.filter);
  if (s.noise_target) o.set_noise_target(*s.noise_target);
  if (s.sampler) o.set_sampler(*s.sampler);
  return o;
}

// "job/frame/pass/tile": what a Task's task_id holds.
inline std::string task_id_text(const std::string& job, uint32_t frame, uint32_t pass,
                                uint32_t tile) {
  return job + "/" + std::to_string(frame) + "/" + std::to_string(pass) + "/" +
         std::to_string(tile);
}

}  // namespace rf
