#include "coordinator/checkpoint.h"

#include "engine/buffer_file.h"
#include "engine/digest.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <set>
#include <stdexcept>
#include <tuple>

#define XXH_INLINE_ALL
#include <xxhash.h>

namespace rf {

namespace fs = std::filesystem;

namespace {

constexpr uint32_t kRecordMagic = 0x4c544652;  // "RFTL" little-endian
constexpr size_t kHeadBytes = 32;

void put32(char* at, uint32_t v) {
  for (int b = 0; b < 4; ++b) at[b] = char((v >> (8 * b)) & 0xff);
}
void put64(char* at, uint64_t v) {
  for (int b = 0; b < 8; ++b) at[b] = char((v >> (8 * b)) & 0xff);
}
uint32_t get32(const char* at) {
  uint32_t v = 0;
  for (int b = 0; b < 4; ++b) v |= uint32_t(uint8_t(at[b])) << (8 * b);
  return v;
}
uint64_t get64(const char* at) {
  uint64_t v = 0;
  for (int b = 0; b < 8; ++b) v |= uint64_t(uint8_t(at[b])) << (8 * b);
  return v;
}

std::array<char, kHeadBytes> record_head(uint32_t pass, uint32_t tile, uint64_t length) {
  std::array<char, kHeadBytes> h{};
  put32(h.data(), kRecordMagic);
  put32(h.data() + 4, pass);
  put32(h.data() + 8, tile);
  put32(h.data() + 12, 0);
  put64(h.data() + 16, length);
  put64(h.data() + 24, XXH3_64bits(h.data(), 24));
  return h;
}

// Reads exactly n bytes at offset; false at the end of the file.
void write_all(int fd, const char* data, size_t n, const std::string& path) {
  while (n > 0) {
    ssize_t put = ::write(fd, data, n);
    if (put < 0 && errno == EINTR) continue;
    if (put < 0) throw std::runtime_error(path + ": write failed: " + std::strerror(errno));
    data += put;
    n -= size_t(put);
  }
}

struct Fd {
  int fd = -1;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

}  // namespace

FrameCheckpoint::FrameCheckpoint(std::string dir) : dir_(std::move(dir)) {
  fs::create_directories(dir_);
}

std::vector<FrameCheckpoint::Record> FrameCheckpoint::scan_log(uint64_t* end,
                                                               uint64_t* size) const {
  std::vector<Record> records;
  *end = *size = 0;
  Fd f{::open(log_path().c_str(), O_RDONLY | O_CLOEXEC)};
  if (f.fd < 0) return records;  // no log yet
  struct stat st {};
  if (::fstat(f.fd, &st) != 0) throw std::runtime_error(log_path() + ": cannot stat");
  *size = uint64_t(st.st_size);
  uint64_t at = 0;
  std::array<char, kHeadBytes> h{};
  while (at + kHeadBytes <= *size && pread_full(f.fd, h.data(), kHeadBytes, at)) {
    if (get32(h.data()) != kRecordMagic || get64(h.data() + 24) != XXH3_64bits(h.data(), 24)) break;
    uint64_t length = get64(h.data() + 16);
    if (length > *size - at - kHeadBytes) break;  // torn: the bytes did not all reach the file
    records.push_back({get32(h.data() + 4), get32(h.data() + 8), at + kHeadBytes, length});
    at += kHeadBytes + length;
  }
  *end = at;
  return records;
}

void FrameCheckpoint::save_task(uint32_t pass, uint32_t tile, const SampleBuffer& buffer) const {
  save_task(pass, tile, encode_buffer(buffer));
}

void FrameCheckpoint::save_task(uint32_t pass, uint32_t tile, std::string_view encoded) const {
  const std::string path = log_path();
  if (!log_checked_) {  // an earlier process's torn tail goes before anything follows it
    uint64_t end = 0, size = 0;
    scan_log(&end, &size);
    if (end < size && ::truncate(path.c_str(), off_t(end)) != 0)
      throw std::runtime_error(path + ": cannot cut its torn end: " + std::strerror(errno));
    log_checked_ = true;
  }
  Fd f{::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644)};
  if (f.fd < 0) throw std::runtime_error(path + ": cannot open: " + std::strerror(errno));
  struct stat st {};
  if (::fstat(f.fd, &st) != 0) throw std::runtime_error(path + ": cannot stat");
  std::array<char, kHeadBytes> head = record_head(pass, tile, encoded.size());
  try {
    write_all(f.fd, head.data(), head.size(), path);
    write_all(f.fd, encoded.data(), encoded.size(), path);
  } catch (...) {
    // A full disk: no partial record stays behind for the next append to follow.
    if (::ftruncate(f.fd, st.st_size) != 0) log_checked_ = false;
    throw;
  }
}

void FrameCheckpoint::save_prefix(const FrameBands& frame) const {
  write_buffer_file(dir_ + "/prefix.rfb", frame);
  uint32_t k = frame.info().header.passes.count();
  for (const auto& e : fs::directory_iterator(dir_)) {  // task files of builds before the log
    unsigned pass = 0, tile = 0;
    char tail[8] = {};
    std::string name = e.path().filename().string();
    if (std::sscanf(name.c_str(), "task-%u-%u%7s", &pass, &tile, tail) == 3 &&
        std::string(tail) == ".rfb" && pass < k)
      fs::remove(e.path());
  }
  uint64_t end = 0, size = 0;
  std::vector<Record> records = scan_log(&end, &size);
  uint64_t live = 0;
  for (const Record& r : records)
    if (r.pass >= k) live += kHeadBytes + r.length;
  const std::string path = log_path();
  if (live == 0) {
    if (size > 0 && ::truncate(path.c_str(), 0) != 0)
      throw std::runtime_error(path + ": cannot empty: " + std::strerror(errno));
    return;
  }
  if (2 * live >= end) return;  // mostly live: rewritten later, when more of it is merged
  // The later passes' records into a new log, flushed before it replaces the old one (they were
  // acknowledged: never lost in between).
  Fd in{::open(path.c_str(), O_RDONLY | O_CLOEXEC)};
  const std::string tmp = path + ".tmp." + std::to_string(::getpid()) + ".0";  // as atomic writes
  Fd out{::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644)};
  if (in.fd < 0 || out.fd < 0) throw std::runtime_error(path + ": cannot rewrite");
  std::string bytes;
  for (const Record& r : records) {
    if (r.pass < k) continue;
    bytes.resize(size_t(kHeadBytes + r.length));
    if (!pread_full(in.fd, bytes.data(), bytes.size(), r.offset - kHeadBytes))
      throw std::runtime_error(path + ": cannot read a record back");
    write_all(out.fd, bytes.data(), bytes.size(), tmp);
  }
  if (::fdatasync(out.fd) != 0 || ::rename(tmp.c_str(), path.c_str()) != 0)
    throw std::runtime_error(path + ": rewrite failed: " + std::strerror(errno));
  Fd d{::open(dir_.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)};
  if (d.fd >= 0) ::fsync(d.fd);
}

FrameCheckpoint::Loaded FrameCheckpoint::load(uint64_t band_bytes) const {
  Loaded out = load_prefix(band_bytes);
  const uint32_t k = out.prefix ? out.prefix->info().header.passes.count() : 0;
  std::set<std::pair<uint32_t, uint32_t>> have;
  for (const TaskResult& t : out.tasks) have.insert({t.pass, t.tile});
  load_log(
      k, std::move(have), [&](TaskResult&& t) { out.tasks.push_back(std::move(t)); }, out.problems);
  std::sort(out.tasks.begin(), out.tasks.end(), [](const TaskResult& a, const TaskResult& b) {
    return std::tie(a.pass, a.tile) < std::tie(b.pass, b.tile);
  });
  return out;
}

FrameCheckpoint::Loaded FrameCheckpoint::load_prefix(uint64_t band_bytes) const {
  Loaded out;
  auto set_aside = [&](const fs::path& p, const std::string& why) {
    out.problems.push_back(p.string() + ": " + why);
    std::error_code ec;
    fs::rename(p, p.string() + ".bad", ec);
  };
  for (const auto& e : fs::directory_iterator(dir_)) {
    std::string name = e.path().filename().string();
    unsigned pass = 0, tile = 0;
    char tail[8] = {};
    bool is_prefix = name == "prefix.rfb";
    bool is_task = std::sscanf(name.c_str(), "task-%u-%u%7s", &pass, &tile, tail) == 3 &&
                   std::string(tail) == ".rfb";
    if (!is_prefix && !is_task) continue;  // temporaries of an interrupted write, set-aside files
    try {
      if (is_prefix)
        out.prefix = std::make_unique<BufferFileBands>(e.path().string(), band_bytes);
      else
        out.tasks.push_back({pass, tile, read_buffer_file(e.path().string())});
    } catch (const std::exception& ex) {
      set_aside(e.path(), ex.what());
    }
  }
  return out;
}

// The log's records of passes not in the prefix; the first of a task's results counts (a later
// one is another worker's result of the same task, written while the first was flushed).
void FrameCheckpoint::load_log(uint32_t k, std::set<std::pair<uint32_t, uint32_t>> have,
                               const std::function<void(TaskResult&&)>& each,
                               std::vector<std::string>& problems) const {
  uint64_t end = 0, size = 0;
  std::vector<Record> records = scan_log(&end, &size);
  if (!records.empty()) {
    Fd in{::open(log_path().c_str(), O_RDONLY | O_CLOEXEC)};
    std::string bytes;
    for (const Record& r : records) {
      if (r.pass < k || !have.insert({r.pass, r.tile}).second) continue;
      const std::string what = log_path() + " (task " + std::to_string(r.pass) + "-" +
                               std::to_string(r.tile) + " at byte " + std::to_string(r.offset) +
                               ")";
      bytes.resize(size_t(r.length));
      TaskResult t{r.pass, r.tile, {}};
      try {
        if (in.fd < 0 || !pread_full(in.fd, bytes.data(), bytes.size(), r.offset))
          throw BufferFileError(what + ": cannot read it");
        t.buffer = decode_buffer(bytes, what);
      } catch (const std::exception& ex) {
        problems.push_back(std::string(ex.what()) + "; skipped");
        have.erase({r.pass, r.tile});
        continue;
      }
      each(std::move(t));
    }
  }
  if (end < size) {  // a crash in the middle of an append: nothing after it was acknowledged
    problems.push_back(log_path() + ": " + std::to_string(size - end) + " bytes after byte " +
                       std::to_string(end) + " are not a whole record; cut off");
    if (::truncate(log_path().c_str(), off_t(end)) != 0)
      problems.push_back(log_path() + ": cannot cut: " + std::strerror(errno));
  }
  log_checked_ = true;
}

}  // namespace rf
