#include "farm/job.h"

#include <cstdio>

namespace rf {

std::string task_id_text(const TaskRef& t) {
  return t.job_id + "/" + std::to_string(t.frame) + "/" + std::to_string(t.pass) + "/" +
         std::to_string(t.tile);
}

std::optional<TaskRef> parse_task_id(std::string_view text) {
  std::string s(text);
  size_t slash = s.find('/');
  if (slash == std::string::npos || slash == 0) return std::nullopt;
  unsigned frame = 0, pass = 0, tile = 0;
  char extra = 0;
  if (std::sscanf(s.c_str() + slash + 1, "%u/%u/%u%c", &frame, &pass, &tile, &extra) != 3)
    return std::nullopt;
  return TaskRef{s.substr(0, slash), frame, pass, tile};
}

}  // namespace rf
