// The .rfb encoding of a sample buffer: partial results on disk that `rayfarm merge` combines,
// coordinator checkpoints, and task results on the wire (docs/sample-buffer-format.md).
#pragma once

#include <optional>
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
// The same, written a band of rows at a time (a frame kept in tiles on disk is never whole in
// memory): the same bytes as write_buffer_file of the whole frame.
void write_buffer_file(const std::string& path, const FrameBands& frame);

// The same encoding in memory (for the wire and for checkpoints).
std::string encode_buffer(const SampleBuffer& buf);
SampleBuffer decode_buffer(const std::string& bytes, const std::string& what_for_errors);

// An .rfb file read a band of rows at a time (FrameBands), so that a frame larger than memory is
// written out (EXR, PNG) or cut into tiles without being whole in memory. Opening checks the file
// as read_buffer_file does, the checksum over the file read in 8 MiB pieces; bands are rows of
// at most band_bytes (at least one row). A buffer with a splat plane (the whole frame's) is read
// whole, as one band. Throws BufferFileError naming the path.
class BufferFileBands final : public FrameBands {
 public:
  BufferFileBands(const std::string& path, uint64_t band_bytes);
  ~BufferFileBands() override;
  BufferFileBands(const BufferFileBands&) = delete;
  BufferFileBands& operator=(const BufferFileBands&) = delete;

  const SampleBuffer& info() const override { return info_; }
  int band_height() const override { return band_height_; }
  const SampleBuffer& band(int y0) const override;
  uint64_t total_samples() const override { return total_samples_; }
  double rel_mse() const override;  // the first call reads every band

 private:
  std::string path_;
  int fd_ = -1;
  SampleBuffer info_;
  uint64_t planes_at_ = 0;
  int band_height_ = 1;
  uint64_t total_samples_ = 0;
  mutable SampleBuffer band_;
  mutable std::optional<double> rel_mse_;
};

// A decoded buffer whose planes stay in its encoded bytes: decoding checks everything
// decode_buffer checks and copies nothing, so the coordinator checks, stores and merges a
// received result where it lies. The planes are 8-byte aligned in the bytes (the format pads the
// header for it) and little-endian, as the hosts this builds for are.
class EncodedBuffer {
 public:
  EncodedBuffer() = default;
  // Throws BufferFileError, as decode_buffer does.
  EncodedBuffer(std::string bytes, const std::string& what_for_errors);

  const std::string& bytes() const { return bytes_; }
  const BufferHeader& header() const { return header_; }
  const Rect& rect() const { return rect_; }
  BufferView view() const;  // into bytes(): valid while this lives and is not moved from
  SampleBuffer decoded() const { return view().copy(); }

 private:
  std::string bytes_;
  BufferHeader header_;
  Rect rect_;
  bool has_splats_ = false;
  uint64_t light_paths_ = 0, nonfinite_samples_ = 0, rays_ = 0;
  size_t planes_at_ = 0;
};

// Sets the C heap up for a process that receives and frees many sample buffers of a few hundred
// kB to a few MB (the coordinator; `rayfarm bench`): buffers up to 32 MiB come from the heap,
// not one mmap each, and up to 128 MiB of freed heap is kept for the next ones instead of being
// returned to the kernel and faulted back in page by page. Measured by `rayfarm bench`'s merge
// line: receive + decode + merge at 1.2 GB/s per core with glibc's defaults, 2.3 GB/s with this.
void keep_heap_for_sample_buffers();

}  // namespace rf
