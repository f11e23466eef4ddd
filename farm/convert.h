// Conversions between the wire (proto/rayfarm.proto) and the plain types of the engine and the
// farm (farm/job.h), shared by the client (submit), the coordinator (validation, its job store)
// and the worker (rendering), so all three read a job's settings the same way.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "engine/sample_buffer.h"
#include "engine/scene.h"
#include "farm/job.h"
#include "proto/rayfarm.pb.h"

namespace rf {

SceneOverrides to_scene_overrides(const rayfarm::v1::RenderOverrides& o);
rayfarm::v1::RenderOverrides to_wire_overrides(const SceneOverrides& s);

JobSpec from_wire(const rayfarm::v1::JobSpec& spec);
rayfarm::v1::JobSpec to_wire(const JobSpec& spec);

std::vector<BundleEntry> from_wire(
    const google::protobuf::RepeatedPtrField<rayfarm::v1::BundleFile>& files);
Rect from_wire(const rayfarm::v1::Rect& r);
rayfarm::v1::Rect to_wire(const Rect& r);

// A job's spec as the coordinator's job store keeps it: a serialized rayfarm.v1.JobSpec, the
// format every state directory holds. Nothing when the bytes do not parse.
std::string encode_job_spec(const JobSpec& spec);
std::optional<JobSpec> decode_job_spec(const std::string& bytes);

}  // namespace rf
