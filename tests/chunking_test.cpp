// Chunked payloads: round trip, and each malformed stream mapped to its gRPC status.
#include <gtest/gtest.h>

#include <vector>

#include "farm/chunking.h"

namespace rf {
namespace {

using Status = ChunkAssembler::Status;

std::vector<rayfarm::v1::Chunk> chunks_of(const std::string& payload, size_t size) {
  std::vector<rayfarm::v1::Chunk> out;
  for_each_chunk(
      payload, [&](rayfarm::v1::Chunk&& c) { out.push_back(std::move(c)); }, size);
  return out;
}

std::string payload(size_t n) {
  std::string s(n, '\0');
  for (size_t i = 0; i < n; ++i) s[i] = char((i * 131) ^ (i >> 7));
  return s;
}

TEST(Chunking, RoundTripsAnySize) {
  for (size_t n : {size_t(0), size_t(1), size_t(1000), size_t(4096), size_t(10001)}) {
    std::string p = payload(n);
    auto cs = chunks_of(p, 1000);
    EXPECT_EQ(cs.size(), std::max<size_t>(1, (n + 999) / 1000));
    ChunkAssembler a(1 << 20);
    for (auto& c : cs) ASSERT_EQ(a.add(c), Status::Ok) << a.error();
    ASSERT_EQ(a.finish(), Status::Ok) << a.error();
    EXPECT_EQ(a.take(), p);
  }
  // The default chunk is 1 MiB: a 4.5 MiB buffer travels as 5 messages under gRPC's 4 MiB limit.
  EXPECT_EQ(chunks_of(payload(4'500'000), kChunkBytes).size(), 5u);
}

// With a sink, chunks pass through as they come (to a file, for a frame larger than memory):
// the same bytes at their offsets, the SHA-256 computed on the way and a wrong one refused, out
// of order chunks refused, nothing kept.
TEST(Chunking, ASinkGetsTheBytesAsTheyComeAndTheDigestIsStillChecked) {
  std::string p = payload(10001), got(p.size(), '\0');
  auto sink = [&](std::string_view data, uint64_t at) { got.replace(at, data.size(), data); };
  ChunkAssembler a(1 << 20, ChunkAssembler::Digest::Optional, sink);
  for (auto& c : chunks_of(p, 1000)) ASSERT_EQ(a.add(c), Status::Ok) << a.error();
  ASSERT_EQ(a.finish(), Status::Ok) << a.error();
  EXPECT_TRUE(got == p);
  EXPECT_TRUE(a.take().empty()) << "nothing kept";

  auto cs = chunks_of(p, 1000);
  cs[0].set_sha256(std::string(64, 'a'));
  ChunkAssembler wrong(1 << 20, ChunkAssembler::Digest::Optional, sink);
  for (auto& c : cs) ASSERT_EQ(wrong.add(c), Status::Ok);
  EXPECT_EQ(wrong.finish(), Status::DataLoss);

  cs = chunks_of(p, 1000);
  ChunkAssembler gap(1 << 20, ChunkAssembler::Digest::Optional, sink);
  ASSERT_EQ(gap.add(cs[0]), Status::Ok);
  EXPECT_EQ(gap.add(cs[2]), Status::InvalidArgument) << "a chunk missing";
  ChunkAssembler short_one(1 << 20, ChunkAssembler::Digest::Optional, sink);
  ASSERT_EQ(short_one.add(cs[0]), Status::Ok);
  EXPECT_EQ(short_one.finish(), Status::InvalidArgument) << "ends early";
}

TEST(Chunking, MalformedStreamsGetTheirStatus) {
  std::string p = payload(5000);
  auto cs = chunks_of(p, 1000);
  {
    ChunkAssembler a(1000);  // over the limit
    EXPECT_EQ(a.add(cs[0]), Status::ResourceExhausted);
    EXPECT_NE(a.error().find("over the limit"), std::string::npos);
  }
  {
    ChunkAssembler a(1 << 20);  // a chunk skipped
    ASSERT_EQ(a.add(cs[0]), Status::Ok);
    EXPECT_EQ(a.add(cs[2]), Status::InvalidArgument);
    EXPECT_NE(a.error().find("offset 2000 where 1000"), std::string::npos) << a.error();
  }
  {
    ChunkAssembler a(1 << 20);  // truncated
    for (size_t i = 0; i + 1 < cs.size(); ++i) ASSERT_EQ(a.add(cs[i]), Status::Ok);
    EXPECT_EQ(a.finish(), Status::InvalidArgument);
  }
  {
    ChunkAssembler a(1 << 20);  // a flipped byte
    auto bad = cs;
    bad[3].mutable_data()->at(17) ^= 1;
    for (auto& c : bad) ASSERT_EQ(a.add(c), Status::Ok);
    EXPECT_EQ(a.finish(), Status::DataLoss);
  }
  {
    ChunkAssembler a(1 << 20);  // no checksum announced
    auto bad = cs;
    bad[0].clear_sha256();
    EXPECT_EQ(a.add(bad[0]), Status::InvalidArgument);
  }
  // A payload that checks itself (CompleteTask's sample buffer) may come without the SHA-256;
  // one that is announced is still checked.
  {
    ChunkAssembler a(1 << 20, ChunkAssembler::Digest::Optional);
    auto none = cs;
    none[0].clear_sha256();
    for (auto& c : none) ASSERT_EQ(a.add(c), Status::Ok);
    EXPECT_EQ(a.finish(), Status::Ok);
    EXPECT_EQ(a.take(), p);
  }
  {
    ChunkAssembler a(1 << 20, ChunkAssembler::Digest::Optional);
    auto bad = cs;
    bad[3].mutable_data()->at(17) ^= 1;
    for (auto& c : bad) ASSERT_EQ(a.add(c), Status::Ok);
    EXPECT_EQ(a.finish(), Status::DataLoss);
  }
  {
    ChunkAssembler a(1 << 20, ChunkAssembler::Digest::Optional);  // not a digest at all
    auto bad = cs;
    bad[0].set_sha256("abc");
    EXPECT_EQ(a.add(bad[0]), Status::InvalidArgument);
  }
}

}  // namespace
}  // namespace rf
