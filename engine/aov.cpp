#include "engine/aov.h"

#include <stdexcept>

namespace rf {

std::string to_string(const AovSet& aovs) {
  std::string s;
  auto add = [&](bool on, const char* name) {
    if (on) s += (s.empty() ? "" : ",") + std::string(name);
  };
  add(aovs.albedo, "albedo");
  add(aovs.normal, "normal");
  add(aovs.depth, "depth");
  return s;
}

AovSet parse_aovs(const std::string& list) {
  AovSet set;
  size_t pos = 0;
  while (pos <= list.size() && !list.empty()) {
    size_t comma = list.find(',', pos);
    std::string name = list.substr(pos, comma == std::string::npos ? std::string::npos : comma - pos);
    bool* flag = name == "albedo" ? &set.albedo
                 : name == "normal" ? &set.normal
                 : name == "depth"  ? &set.depth
                                    : nullptr;
    if (!flag)
      throw std::invalid_argument("unknown AOV '" + name + "' (known: albedo, normal, depth)");
    if (*flag) throw std::invalid_argument("AOV '" + name + "' is listed twice");
    *flag = true;
    if (comma == std::string::npos) break;
    pos = comma + 1;
  }
  return set;
}

}  // namespace rf
