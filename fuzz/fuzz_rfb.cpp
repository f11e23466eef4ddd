// libFuzzer target: the .rfb sample buffer decoder (engine/buffer_file.h), which reads task
// results from the network and checkpoints from disk.
#include <cstdint>
#include <exception>
#include <string>

#include "engine/buffer_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  try {
    rf::decode_buffer(std::string(reinterpret_cast<const char*>(data), size), "fuzz.rfb");
  } catch (const std::exception&) {
  }
  return 0;
}
