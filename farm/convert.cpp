#include "farm/convert.h"

namespace rf {

namespace pb = rayfarm::v1;

SceneOverrides to_scene_overrides(const pb::RenderOverrides& o) {
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
  if (o.has_aovs()) s.aovs = o.aovs();
  if (o.has_light_selection()) s.light_selection = o.light_selection();
  if (o.has_shutter()) s.shutter = o.shutter();
  return s;
}

pb::RenderOverrides to_wire_overrides(const SceneOverrides& s) {
  pb::RenderOverrides o;
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
  if (s.aovs) o.set_aovs(*s.aovs);
  if (s.light_selection) o.set_light_selection(*s.light_selection);
  if (s.shutter) o.set_shutter(*s.shutter);
  return o;
}

std::vector<BundleEntry> from_wire(
    const google::protobuf::RepeatedPtrField<pb::BundleFile>& files) {
  std::vector<BundleEntry> out;
  out.reserve(size_t(files.size()));
  for (const pb::BundleFile& f : files) out.push_back({f.path(), f.sha256()});
  return out;
}

JobSpec from_wire(const pb::JobSpec& spec) {
  JobSpec s;
  s.name = spec.name();
  s.scene_path = spec.scene_path();
  s.files = from_wire(spec.files());
  s.frames = spec.frames();
  s.overrides = to_scene_overrides(spec.overrides());
  s.priority = spec.priority();
  s.tile_size = spec.tile_size();
  s.build_id = spec.build_id();
  s.request_id = spec.request_id();
  s.required_tags.assign(spec.required_tags().begin(), spec.required_tags().end());
  return s;
}

pb::JobSpec to_wire(const JobSpec& s) {
  pb::JobSpec spec;
  spec.set_name(s.name);
  spec.set_scene_path(s.scene_path);
  for (const BundleEntry& e : s.files) {
    pb::BundleFile* f = spec.add_files();
    f->set_path(e.path);
    f->set_sha256(e.sha256);
  }
  spec.set_frames(s.frames);
  spec.set_build_id(s.build_id);
  spec.set_request_id(s.request_id);
  for (const std::string& r : s.required_tags) spec.add_required_tags(r);
  *spec.mutable_overrides() = to_wire_overrides(s.overrides);
  spec.set_priority(s.priority);
  spec.set_tile_size(s.tile_size);
  return spec;
}

Rect from_wire(const pb::Rect& r) { return Rect{r.x0(), r.y0(), r.w(), r.h()}; }

pb::Rect to_wire(const Rect& r) {
  pb::Rect out;
  out.set_x0(r.x0);
  out.set_y0(r.y0);
  out.set_w(r.w);
  out.set_h(r.h);
  return out;
}

std::string encode_job_spec(const JobSpec& spec) { return to_wire(spec).SerializeAsString(); }

std::optional<JobSpec> decode_job_spec(const std::string& bytes) {
  pb::JobSpec spec;
  if (!spec.ParseFromString(bytes)) return std::nullopt;
  return from_wire(spec);
}

}  // namespace rf
