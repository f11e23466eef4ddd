#include "farm/chunking.h"

#include <grpcpp/support/sync_stream.h>

#include "engine/digest.h"

namespace rf {

void for_each_chunk(std::string_view payload, const std::function<void(rayfarm::v1::Chunk&&)>& emit,
                    size_t chunk_bytes, bool with_sha256) {
  size_t offset = 0;
  do {
    rayfarm::v1::Chunk c;
    size_t n = std::min(chunk_bytes, payload.size() - offset);
    c.set_offset(offset);
    c.set_data(std::string(payload.substr(offset, n)));
    if (offset == 0) {
      c.set_total_size(payload.size());
      if (with_sha256) c.set_sha256(sha256_hex(payload));
    }
    offset += n;
    emit(std::move(c));
  } while (offset < payload.size());
}

ChunkAssembler::ChunkAssembler(uint64_t max_bytes, Digest digest, Sink sink)
    : max_bytes_(max_bytes), digest_(digest), sink_(std::move(sink)) {}
ChunkAssembler::~ChunkAssembler() = default;
ChunkAssembler::ChunkAssembler(ChunkAssembler&&) noexcept = default;
ChunkAssembler& ChunkAssembler::operator=(ChunkAssembler&&) noexcept = default;

ChunkAssembler::Status ChunkAssembler::add(const rayfarm::v1::Chunk& c) {
  if (!started_) {
    if (c.offset() != 0)
      return fail(Status::InvalidArgument, "first chunk has offset " + std::to_string(c.offset()));
    if (c.sha256().size() != 64 && !(digest_ == Digest::Optional && c.sha256().empty()))
      return fail(Status::InvalidArgument, "first chunk lacks the payload's SHA-256");
    if (c.total_size() > max_bytes_)
      return fail(Status::ResourceExhausted, "payload of " + std::to_string(c.total_size()) +
                                                 " bytes is over the limit of " +
                                                 std::to_string(max_bytes_));
    started_ = true;
    total_ = c.total_size();
    sha256_ = c.sha256();
    if (!sink_)
      data_.reserve(total_);
    else if (!sha256_.empty())
      running_ = std::make_unique<Sha256>();
  }
  if (c.offset() != received_)
    return fail(Status::InvalidArgument, "chunk at offset " + std::to_string(c.offset()) +
                                             " where " + std::to_string(received_) +
                                             " was expected");
  if (received_ + c.data().size() > total_)
    return fail(Status::InvalidArgument,
                "chunks run past the announced size of " + std::to_string(total_) + " bytes");
  if (sink_) {
    sink_(c.data(), received_);
    if (running_) running_->update(c.data());
  } else {
    data_ += c.data();
  }
  received_ += c.data().size();
  return Status::Ok;
}

ChunkAssembler::Status ChunkAssembler::finish() {
  if (!started_) return fail(Status::InvalidArgument, "no chunks");
  if (received_ != total_)
    return fail(Status::InvalidArgument, "payload ends at " + std::to_string(received_) + " of " +
                                             std::to_string(total_) + " bytes");
  if (!sha256_.empty() && (running_ ? running_->hex_digest() : sha256_hex(data_)) != sha256_)
    return fail(Status::DataLoss, "checksum mismatch");
  return Status::Ok;
}

bool write_result(grpc::ClientWriterInterface<rayfarm::v1::CompleteRequest>& stream,
                  const rayfarm::v1::CompleteHeader& header, std::string_view payload, bool last) {
  rayfarm::v1::CompleteRequest head;
  *head.mutable_header() = header;
  bool ok = stream.Write(head);
  for_each_chunk(
      payload,
      [&](rayfarm::v1::Chunk&& c) {
        if (!ok) return;
        rayfarm::v1::CompleteRequest m;
        *m.mutable_chunk() = std::move(c);
        ok = stream.Write(m);
      },
      kChunkBytes, /*with_sha256=*/false);
  if (ok && last) ok = stream.WritesDone();
  return ok;
}

}  // namespace rf
