#include "coordinator/checkpoint.h"

#include "engine/buffer_file.h"
#include "engine/digest.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <tuple>

namespace rf {

namespace fs = std::filesystem;

FrameCheckpoint::FrameCheckpoint(std::string dir) : dir_(std::move(dir)) {
  fs::create_directories(dir_);
}

void FrameCheckpoint::save_task(uint32_t pass, uint32_t tile, const SampleBuffer& buffer) const {
  save_task(pass, tile, encode_buffer(buffer));
}

void FrameCheckpoint::save_task(uint32_t pass, uint32_t tile, std::string_view encoded) const {
  write_file_atomic(dir_ + "/task-" + std::to_string(pass) + "-" + std::to_string(tile) + ".rfb",
                    encoded);
}

void FrameCheckpoint::save_prefix(const SampleBuffer& frame) const {
  write_buffer_file(dir_ + "/prefix.rfb", frame);
  uint32_t k = frame.header.passes.count();
  for (const auto& e : fs::directory_iterator(dir_)) {
    unsigned pass = 0, tile = 0;
    char tail[8] = {};
    std::string name = e.path().filename().string();
    if (std::sscanf(name.c_str(), "task-%u-%u%7s", &pass, &tile, tail) == 3 &&
        std::string(tail) == ".rfb" && pass < k)
      fs::remove(e.path());
  }
}

FrameCheckpoint::Loaded FrameCheckpoint::load() const {
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
      SampleBuffer b = read_buffer_file(e.path().string());
      if (is_prefix)
        out.prefix = std::move(b);
      else
        out.tasks.push_back({pass, tile, std::move(b)});
    } catch (const std::exception& ex) {
      set_aside(e.path(), ex.what());
    }
  }
  std::sort(out.tasks.begin(), out.tasks.end(), [](const TaskResult& a, const TaskResult& b) {
    return std::tie(a.pass, a.tile) < std::tie(b.pass, b.tile);
  });
  return out;
}

}  // namespace rf
