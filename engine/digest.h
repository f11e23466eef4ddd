// SHA-256 digests (OpenSSL) for content addressing: scene bundles, buffer checksums.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <string>
#include <string_view>

namespace rf {

// Lower-case hex SHA-256 of bytes.
std::string sha256_hex(std::string_view bytes);

// Incremental form, for digests over several pieces.
class Sha256 {
 public:
  Sha256();
  ~Sha256();
  Sha256(const Sha256&) = delete;
  Sha256& operator=(const Sha256&) = delete;
  void update(std::string_view bytes);
  std::string hex_digest();  // finishes; the object is then spent

 private:
  void* ctx_;
};

// pread/pwrite of exactly n bytes at `offset`, through short counts and EINTR. False on failure,
// errno set (EIO when the file ends first).
bool pread_full(int fd, void* out, size_t n, uint64_t offset);
bool pwrite_full(int fd, const void* data, size_t n, uint64_t offset);

// Reads a whole file; throws std::runtime_error naming the path if it cannot.
std::string read_file_bytes(const std::string& path);

// Writes bytes to path atomically: temporary file in the same directory, fsync, rename, fsync of
// the directory. Throws std::runtime_error naming the path.
void write_file_atomic(const std::string& path, std::string_view bytes);
// The same, the content written by fill(fd) (an fd open for reading and writing at offset 0);
// an exception from fill removes the temporary file and passes on.
void write_file_atomic(const std::string& path, const std::function<void(int fd)>& fill);

}  // namespace rf
