#include "engine/import_limits.h"

#include <OpenImageIO/imageio.h>

#include <map>

namespace rf {

bool ImportLimits::set(const std::string& name, uint64_t value) {
  std::map<std::string, uint64_t*> fields = {
      {"files", &files}, {"bytes", &bytes}, {"elements", &elements}};
  auto it = fields.find(name);
  if (it == fields.end()) return false;
  *it->second = value;
  return true;
}

std::vector<std::string> ImportLimits::names() { return {"files", "bytes", "elements"}; }

void set_import_threads(int threads) {
  OIIO::attribute("threads", threads);
  OIIO::attribute("exr_threads", threads);
}

}  // namespace rf
