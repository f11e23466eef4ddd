// libFuzzer target: one scene importer (the format is RAYFARM_FUZZ_EXT, the file extension that
// load_scene dispatches on). Each input is written to a private directory as scene<ext> and
// loaded; a SceneError (or any std::exception) is the expected answer to a bad file. A crash, a
// sanitizer report, a hang or an allocation past libFuzzer's limits is a finding
// (fuzz/README.md).
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include <spdlog/spdlog.h>

#include "engine/scene.h"

#ifndef RAYFARM_FUZZ_EXT
#error "define RAYFARM_FUZZ_EXT, e.g. \".json\""
#endif

namespace {

std::string scene_path() {
  static const std::string path = [] {
    char tmpl[] = "/tmp/rayfarm-fuzz-XXXXXX";
    const char* dir = mkdtemp(tmpl);
    if (!dir) std::abort();
    return std::string(dir) + "/scene" RAYFARM_FUZZ_EXT;
  }();
  return path;
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  spdlog::set_level(spdlog::level::off);  // importer warnings would flood the run
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string& path = scene_path();
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
  // Tighter bounds than the defaults, so an input that fans out (a file that includes itself ten
  // times: fuzz/seeds/bombs/) costs milliseconds here; without the bound it runs into the
  // -timeout and is a finding.
  rf::ImportLimits limits;
  limits.files = 256;
  limits.bytes = uint64_t(64) << 20;
  limits.elements = 1000000;
  try {
    rf::Scene scene = rf::load_scene(path, {}, limits);
  } catch (const std::exception&) {
  }
  return 0;
}
