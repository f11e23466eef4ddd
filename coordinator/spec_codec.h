// The coordinator's own encoding of a job spec, for its job store, its job folders and the scene
// check's request: JSON, independent of the wire schema, so the store reads what it wrote whatever
// becomes of proto/rayfarm.proto. It also reads the rows and folder records of builds before it,
// which stored the spec as protobuf wire bytes (rayfarm.v1.JobSpec), with a decoder of its own:
// the coordinator links no protobuf.
#pragma once

#include <optional>
#include <string>

#include "farm/job.h"

namespace rf {

std::string encode_spec(const JobSpec& spec);
// JSON as encode_spec writes it, or the protobuf wire bytes of earlier builds; nothing when the
// bytes are neither.
std::optional<JobSpec> decode_spec(const std::string& bytes);

}  // namespace rf
