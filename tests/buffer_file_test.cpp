// Tests of engine/buffer_file: the .rfb encoding round-trips bit-identically, matches
// docs/sample-buffer-format.md, and refuses every truncation, flipped byte and lying header.
#include "engine/buffer_merge.h"
#include "engine/digest.h"

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "engine/buffer_file.h"
#include "tests/support/fixtures.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

SampleBuffer small_buffer(bool splats) {
  SampleBuffer a = test::random_pass(0, Rect{0, 0, 8, 6}, splats, 11);
  merge_into(a, test::random_pass(1, Rect{0, 0, 8, 6}, splats, 12));
  a.header.core_seconds = 0.1;  // not exactly representable: must still round-trip
  a.header.seed = 0xfedcba9876543210ull;
  return a;
}

SampleBuffer small_tile() {
  SampleBuffer t = test::random_pass(4, Rect{2, 1, 3, 2}, false, 13);
  t.header.settings = "quote \" backslash \\ unicode \xc3\xa9";
  return t;
}

TEST(BufferFile, EncodeDecodeRoundTripIsBitIdentical) {
  for (const SampleBuffer& b : {small_buffer(false), small_buffer(true), small_tile()}) {
    std::string bytes = encode_buffer(b);
    SampleBuffer d = decode_buffer(bytes, "mem");
    test::expect_bit_identical(d, b);
    EXPECT_EQ(encode_buffer(d), bytes);
  }
}

TEST(BufferFile, WriteAndReadFile) {
  std::string dir = test::make_temp_dir("film-rfb");
  std::string path = dir + "/pass.rfb";
  SampleBuffer b = small_buffer(true);
  write_buffer_file(path, b);
  test::expect_bit_identical(read_buffer_file(path), b);
  std::string m = test::error_of([&] { read_buffer_file(dir + "/missing.rfb"); });
  EXPECT_NE(m.find("missing.rfb"), std::string::npos) << m;
  EXPECT_THROW(read_buffer_file(dir + "/missing.rfb"), BufferFileError);
}

TEST(BufferFile, LayoutIsAsDocumented) {
  SampleBuffer b = small_tile();
  std::string bytes = encode_buffer(b);
  EXPECT_EQ(bytes.substr(0, 8), std::string("\x89RFB\r\n\x1a\n", 8));
  uint32_t version, header_len;
  std::memcpy(&version, bytes.data() + 8, 4);  // the tests run on little-endian hosts
  std::memcpy(&header_len, bytes.data() + 12, 4);
  EXPECT_EQ(version, 3u);
  EXPECT_EQ((16 + header_len) % 8, 0u);  // planes are 8-byte aligned
  EXPECT_EQ(bytes.size(), 16 + header_len + 8 * 13 * 6 + 16);
  uint64_t count0;
  std::memcpy(&count0, bytes.data() + 16 + header_len, 8);
  EXPECT_EQ(count0, b.count[0]);
  // The last 16 bytes: XXH3-128 of the rest, canonical (big-endian) order, as xxh128sum
  // prints it.
  std::string checksum_hex;
  for (size_t i = bytes.size() - 16; i < bytes.size(); ++i) {
    checksum_hex += "0123456789abcdef"[uint8_t(bytes[i]) >> 4];
    checksum_hex += "0123456789abcdef"[uint8_t(bytes[i]) & 15];
  }
  std::string dir = test::make_temp_dir("rfb-layout");
  {
    std::ofstream body(dir + "/body", std::ios::binary);
    body.write(bytes.data(), std::streamsize(bytes.size() - 16));
  }
  test::CommandResult sum = test::run_command("(xxhsum -H2 " + dir + "/body 2>/dev/null)");
  if (sum.exit_code == 0) {  // xxhsum (Debian's xxhash package) is not a build dependency
    EXPECT_EQ(sum.output.substr(0, 32), checksum_hex) << sum.output;
  }
  EXPECT_EQ(
      bytes.substr(bytes.size() - 16),
      test::rfb_with_checksum(bytes.substr(0, bytes.size() - 16), 3).substr(bytes.size() - 16));
  auto j = nlohmann::json::parse(bytes.substr(16, header_len));
  EXPECT_EQ(j["passes"], "4");
  EXPECT_EQ(j["aovs"], "");  // no AOV plane
  EXPECT_EQ(j["rect"]["x0"], 2);
}

// Replaces the JSON header and recomputes the checksum: a "well-formed lie".
std::string with_header(const std::string& bytes, const nlohmann::json& j) {
  uint32_t header_len;
  std::memcpy(&header_len, bytes.data() + 12, 4);
  std::string header = j.dump();
  std::string out = bytes.substr(0, 12);
  uint32_t len = uint32_t(header.size());
  out.append(reinterpret_cast<const char*>(&len), 4);
  out += header;
  out += bytes.substr(16 + header_len, bytes.size() - 16 - header_len - 16);
  return test::rfb_with_checksum(out, 3);
}

nlohmann::json header_of(const std::string& bytes) {
  uint32_t header_len;
  std::memcpy(&header_len, bytes.data() + 12, 4);
  return nlohmann::json::parse(bytes.substr(16, header_len));
}

TEST(BufferFile, RejectsBadMagicAndVersion) {
  std::string good = encode_buffer(small_tile());
  std::string bad = good;
  bad[1] = 'X';
  std::string m = test::error_of([&] { decode_buffer(bad, "a.rfb"); });
  EXPECT_EQ(m, "a.rfb: not a rayfarm sample buffer (bad magic)");
  EXPECT_THROW(decode_buffer("hello world, this is not a buffer at all....................", "t"),
               BufferFileError);
  bad = good;
  bad[8] = 4;
  m = test::error_of([&] { decode_buffer(bad, "a.rfb"); });
  EXPECT_EQ(m, "a.rfb: unsupported format version 4 (this build reads 1 to 3)");
  bad[8] = 0;
  m = test::error_of([&] { decode_buffer(bad, "a.rfb"); });
  EXPECT_EQ(m, "a.rfb: unsupported format version 0 (this build reads 1 to 3)");
}

TEST(BufferFile, EveryTruncationThrows) {
  for (bool splats : {false, true}) {
    std::string good = encode_buffer(splats ? small_buffer(true) : small_tile());
    for (size_t n = 0; n < good.size(); ++n) {
      EXPECT_THROW(decode_buffer(good.substr(0, n), "t.rfb"), BufferFileError) << n;
    }
  }
  std::string good = encode_buffer(small_tile());
  std::string m = test::error_of([&] { decode_buffer(good.substr(0, good.size() - 1), "a.rfb"); });
  EXPECT_EQ(m, "a.rfb: checksum mismatch (file is corrupt or truncated)");
}

TEST(BufferFile, EveryFlippedByteThrows) {
  std::string good = encode_buffer(small_tile());
  for (size_t i = 0; i < good.size(); ++i) {
    std::string bad = good;
    bad[i] ^= 0x10;
    EXPECT_THROW(decode_buffer(bad, "f.rfb"), BufferFileError) << i;
  }
  std::string bad = good;
  bad[good.size() / 2] ^= 1;
  EXPECT_EQ(test::error_of([&] { decode_buffer(bad, "a.rfb"); }),
            "a.rfb: checksum mismatch (file is corrupt or truncated)");
}

TEST(BufferFile, RejectsAHeaderThatLiesWithAValidChecksum) {
  std::string good = encode_buffer(small_tile());
  nlohmann::json j = header_of(good);
  EXPECT_NO_THROW(decode_buffer(with_header(good, j), "ok.rfb"));  // the helper itself is sound
  auto rejection = [&](auto change) {
    nlohmann::json k = j;
    change(k);
    std::string m = test::error_of([&] { decode_buffer(with_header(good, k), "l.rfb"); });
    EXPECT_EQ(m.rfind("l.rfb: ", 0), 0u) << m;
    return m;
  };
  std::string m = rejection([](nlohmann::json& k) { k["rect"]["w"] = 4; });
  EXPECT_NE(m.find("header describes"), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) { k["rect"]["h"] = 1000000; });
  EXPECT_NE(m.find("not inside"), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) {
    k["width"] = 1000000;
    k["height"] = 1000000;
    k["has_splats"] = true;
  });
  EXPECT_NE(m.find("header describes"), std::string::npos) << m;  // would be 24 TB of splats
  m = rejection([](nlohmann::json& k) { k["has_splats"] = true; });
  EXPECT_NE(m.find("header describes"), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) { k["rect"]["x0"] = -1; });
  EXPECT_NE(m.find("\"x0\""), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) { k.erase("seed"); });
  EXPECT_NE(m.find("\"seed\""), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) { k["passes"] = "3-1"; });
  EXPECT_NE(m.find("passes"), std::string::npos) << m;
  m = rejection([](nlohmann::json& k) { k = nlohmann::json::array(); });
  EXPECT_NE(m.find("not a JSON object"), std::string::npos) << m;
  // A header length that runs past the end of the file.
  std::string bad = good;
  bad[13] = char(0x7f);
  EXPECT_THROW(decode_buffer(bad, "l.rfb"), BufferFileError);
}

// A frame is a signed 32-bit number (engine/frame.h): a negative frame round-trips, one past the
// range is refused, and a frame >= 0 is written as it was when frames were unsigned.
TEST(BufferFile, NegativeFramesRoundTripAndFramesOutOfRangeAreRefused) {
  SampleBuffer b = small_tile();
  for (FrameNumber f : {-7, INT32_MIN, INT32_MAX}) {
    b.header.frame = f;
    test::expect_bit_identical(decode_buffer(encode_buffer(b), "neg.rfb"), b);
  }
  b.header.frame = 12;
  EXPECT_NE(encode_buffer(b).find("\"frame\":12,"), std::string::npos);
  const std::string good = encode_buffer(b);
  nlohmann::json j = header_of(good);
  for (int64_t f : {int64_t(INT32_MAX) + 1, int64_t(INT32_MIN) - 1}) {
    j["frame"] = f;
    std::string m = test::error_of([&] { decode_buffer(with_header(good, j), "f.rfb"); });
    EXPECT_NE(m.find("\"frame\""), std::string::npos) << m;
    EXPECT_NE(m.find("from -2147483648 to 2147483647"), std::string::npos) << m;
  }
}

// EncodedBuffer reads the planes where they lie: the same header, rect, planes and counters as
// decode_buffer's copy, bit for bit, for every version, and the same refusals.
TEST(BufferFile, EncodedBufferViewsWhatDecodeCopies) {
  for (const SampleBuffer& b : {small_buffer(false), small_buffer(true), small_tile()}) {
    std::string bytes = encode_buffer(b);
    EncodedBuffer e(bytes, "mem");
    test::expect_bit_identical(e.decoded(), decode_buffer(bytes, "mem"));
    EXPECT_EQ(e.bytes(), bytes);
    EXPECT_TRUE(same_samples(e.view(), b));
    EncodedBuffer moved = std::move(e);  // the view follows the bytes
    test::expect_bit_identical(moved.decoded(), b);
  }
  std::string good = encode_buffer(small_tile());
  for (size_t n : {size_t(0), size_t(20), good.size() - 1})
    EXPECT_THROW(EncodedBuffer(good.substr(0, n), "t.rfb"), BufferFileError) << n;
  std::string bad = good;
  bad[good.size() / 2] ^= 1;
  EXPECT_EQ(test::error_of([&] { EncodedBuffer(bad, "a.rfb"); }),
            "a.rfb: checksum mismatch (file is corrupt or truncated)");
}

// Files of format version 2 (SHA-256), written by the build before version 3
// (tests/data/rfb-v2/README.md): a.rfb holds passes 0-1 and b.rfb passes 2-3 of a 12x8 render,
// ab.rfb their merge by that build. This build reads them, merges them to the same samples, and
// `rayfarm merge` takes them and writes version 3.
TEST(BufferFile, VersionTwoFilesStillReadAndMerge) {
  const std::string data = test::source_dir() + "/tests/data/rfb-v2/";
  std::string a_bytes = read_file_bytes(data + "a.rfb");
  uint32_t version;
  std::memcpy(&version, a_bytes.data() + 8, 4);
  ASSERT_EQ(version, 2u);
  SampleBuffer a = read_buffer_file(data + "a.rfb"), b = read_buffer_file(data + "b.rfb");
  SampleBuffer old_merge = read_buffer_file(data + "ab.rfb");
  EncodedBuffer a_in_place(a_bytes, "a.rfb");
  test::expect_bit_identical(a_in_place.decoded(), a);
  SampleBuffer merged = a;
  merge_into(merged, b);
  EXPECT_TRUE(same_samples(merged, old_merge));
  EXPECT_EQ(merged.header.passes.to_string(), "0-3");

  std::string dir = test::make_temp_dir("rfb-v2-merge");
  test::CommandResult r = test::run_command(test::rayfarm_binary() + " merge " + data + "a.rfb " +
                                            data + "b.rfb -o " + dir + "/ab.rfb");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::string out = read_file_bytes(dir + "/ab.rfb");
  std::memcpy(&version, out.data() + 8, 4);
  EXPECT_EQ(version, 3u);
  EXPECT_TRUE(same_samples(read_buffer_file(dir + "/ab.rfb"), old_merge));
}

}  // namespace
}  // namespace rf
