// Reading the EXRs the CLI writes, for tests: pixels as floats and header attributes as text.
#pragma once

#include <map>
#include <string>
#include <vector>

namespace rf::test {

struct Exr {
  int w = 0, h = 0, nch = 0;
  std::string format;  // the channels' type as OpenImageIO names it: "float", "half"
  std::vector<std::string> names;
  std::vector<float> px;                      // w * h * nch, interleaved
  std::map<std::string, std::string> attrs;   // every attribute, formatted as text
  std::string attr(const std::string& name) const {
    auto it = attrs.find(name);
    return it == attrs.end() ? "" : it->second;
  }
};

// Fails the calling test (and returns an empty image) when the file cannot be opened.
Exr read_exr(const std::string& path);

}  // namespace rf::test
