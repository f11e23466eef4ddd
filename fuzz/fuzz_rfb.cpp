// libFuzzer target: the .rfb sample buffer decoders (engine/buffer_file.h), which read task results
// from the network and checkpoints from disk: decode_buffer (planes copied) and EncodedBuffer
// (planes read where they lie, as the coordinator merges results). Both must refuse the same
// inputs, and what they accept must be the same buffer.
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <optional>
#include <string>

#include "engine/buffer_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes(reinterpret_cast<const char*>(data), size);
  std::optional<rf::SampleBuffer> copied;
  std::optional<rf::EncodedBuffer> in_place;
  try {
    copied = rf::decode_buffer(bytes, "fuzz.rfb");
  } catch (const std::exception&) {
  }
  try {
    in_place.emplace(bytes, "fuzz.rfb");
  } catch (const std::exception&) {
  }
  if (copied.has_value() != in_place.has_value()) std::abort();  // one accepted, one refused
  if (copied && !(rf::same_samples(*copied, in_place->view()) &&
                  copied->header == in_place->header() && copied->rays == in_place->view().rays))
    std::abort();
  return 0;
}
