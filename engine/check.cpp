#include "engine/check.h"

#include <cstring>

namespace rf {

void check_failed(const char* file, int line, const char* condition, const std::string& message) {
  // The path below the source tree ("engine/render.cpp"), the same on every build machine: the
  // tree's root is this file's path less "engine/check.cpp".
  static const std::string root = [] {
    std::string self = __FILE__;
    size_t at = self.rfind("engine/check.cpp");
    return at == std::string::npos ? std::string() : self.substr(0, at);
  }();
  const char* shown = file;
  if (!root.empty() && std::strncmp(file, root.c_str(), root.size()) == 0) shown += root.size();
  std::string what = std::string("internal error: ") + shown + ":" + std::to_string(line) +
                     ": check failed: " + condition;
  if (!message.empty()) what += " (" + message + ")";
  throw CheckFailure(what);
}

}  // namespace rf
