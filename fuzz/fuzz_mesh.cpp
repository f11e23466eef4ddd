// libFuzzer target: the OBJ and PLY mesh readers (engine/mesh_io.h), straight from memory. The
// first byte picks the reader, so one corpus exercises both.
#include <cstdint>
#include <exception>
#include <string_view>

#include <spdlog/spdlog.h>

#include "engine/mesh_io.h"

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  spdlog::set_level(spdlog::level::off);
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  std::string_view bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    if (data[0] & 1)
      rf::parse_ply(bytes, "fuzz.ply");
    else
      rf::parse_obj(bytes, "fuzz.obj");
  } catch (const std::exception&) {
  }
  return 0;
}
