// Large payloads as streams of Chunk messages (rayfarm.proto): about 1 MiB each, offsets in
// order, the first chunk carrying the total size and the SHA-256 of the whole payload. Never by
// raising gRPC's 4 MiB message limit.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "engine/digest.h"
#include "proto/rayfarm.pb.h"

namespace grpc {
template <class W>
class ClientWriterInterface;
}

namespace rf {

inline constexpr size_t kChunkBytes = 1 << 20;

// Calls emit for each chunk of payload, in order (at least one chunk, even when empty). The first
// carries the payload's SHA-256 unless `with_sha256` is false (a payload that checks itself).
void for_each_chunk(std::string_view payload, const std::function<void(rayfarm::v1::Chunk&&)>& emit,
                    size_t chunk_bytes = kChunkBytes, bool with_sha256 = true);

// A CompleteTask upload's messages: the header, then `payload` (a sample buffer, which carries
// its own checksum: no SHA-256 in the chunks) in chunks, then WritesDone unless more results
// follow (a batched upload). False when a write failed (the stream is broken; Finish() says why).
bool write_result(grpc::ClientWriterInterface<rayfarm::v1::CompleteRequest>& stream,
                  const rayfarm::v1::CompleteHeader& header, std::string_view payload,
                  bool last = true);

// Reassembles chunks. Each problem maps to the gRPC status the receiver answers with.
class ChunkAssembler {
 public:
  enum class Status { Ok, InvalidArgument, ResourceExhausted, DataLoss };
  // Digest::Optional: the payload checks itself (a sample buffer, CompleteTask); a SHA-256 in
  // the first chunk, as workers before format 3 send, is still checked.
  enum class Digest { Required, Optional };
  explicit ChunkAssembler(uint64_t max_bytes, Digest digest = Digest::Required)
      : max_bytes_(max_bytes), digest_(digest) {}
  // Chunks handed to `sink` (their bytes and offset) as they come instead of kept, so a payload
  // larger than memory goes to a file; take() is then empty. A SHA-256 in the first chunk is
  // computed as they pass. An exception from the sink passes on.
  using Sink = std::function<void(std::string_view data, uint64_t offset)>;
  ChunkAssembler(uint64_t max_bytes, Digest digest, Sink sink);
  ~ChunkAssembler();
  ChunkAssembler(ChunkAssembler&&) noexcept;
  ChunkAssembler& operator=(ChunkAssembler&&) noexcept;

  // Adds the next chunk; on a problem returns it and keeps the message for error().
  Status add(const rayfarm::v1::Chunk& chunk);
  // After the last chunk: checks completeness and the checksum.
  Status finish();
  const std::string& error() const { return error_; }
  std::string take() { return std::move(data_); }

 private:
  Status fail(Status s, std::string why) {
    error_ = std::move(why);
    return s;
  }
  uint64_t max_bytes_;
  Digest digest_;
  uint64_t total_ = 0, received_ = 0;
  bool started_ = false;
  Sink sink_;
  std::unique_ptr<Sha256> running_;  // with a sink and a SHA-256
  std::string sha256_;
  std::string data_;
  std::string error_;
};

}  // namespace rf
