// The .rfb encoding of a sample buffer: partial results on disk that `rayfarm merge` combines,
// coordinator checkpoints, and task results on the wire (docs/sample-buffer-format.md).
#pragma once

#include <stdexcept>
#include <string>

#include "engine/sample_buffer.h"

namespace rf {

struct BufferFileError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// The partial-result file (.rfb): magic, version, header, planes, checksum. Written atomically
// (temporary file, fsync, rename); reading verifies the checksum and every size, and throws
// BufferFileError naming the file and what is wrong.
void write_buffer_file(const std::string& path, const SampleBuffer& buf);
SampleBuffer read_buffer_file(const std::string& path);

// The same encoding in memory (for the wire and for checkpoints).
std::string encode_buffer(const SampleBuffer& buf);
SampleBuffer decode_buffer(const std::string& bytes, const std::string& what_for_errors);

}  // namespace rf
