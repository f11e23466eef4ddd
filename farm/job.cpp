#include "farm/job.h"

#include <algorithm>
#include <charconv>
#include <cstdint>
#include <cstdio>

namespace rf {

namespace {

// The length of the UTF-8 sequence at text[i] (overlong forms, surrogates and code points past
// U+10FFFF refused), or 0 when it is not one; *cp is its code point.
size_t utf8_length(std::string_view text, size_t i, uint32_t* cp) {
  auto byte = [&](size_t k) { return uint8_t(text[k]); };
  uint8_t b = byte(i);
  size_t n = b < 0x80             ? 1
             : (b & 0xe0) == 0xc0 ? 2
             : (b & 0xf0) == 0xe0 ? 3
             : (b & 0xf8) == 0xf0 ? 4
                                  : 0;
  if (n == 0 || i + n > text.size()) return 0;
  uint32_t c = n == 1 ? b : b & (0x7f >> n);
  for (size_t k = 1; k < n; ++k) {
    if ((byte(i + k) & 0xc0) != 0x80) return 0;
    c = (c << 6) | (byte(i + k) & 0x3f);
  }
  static const uint32_t kMin[] = {0, 0, 0x80, 0x800, 0x10000};
  if (c < kMin[n] || c > 0x10ffff || (c >= 0xd800 && c <= 0xdfff)) return 0;
  *cp = c;
  return n;
}

bool control(uint32_t cp) { return cp < 0x20 || (cp >= 0x7f && cp < 0xa0); }

}  // namespace

std::string text_problem(std::string_view text) {
  for (size_t i = 0; i < text.size();) {
    uint32_t cp = 0;
    size_t n = utf8_length(text, i, &cp);
    if (n == 0) return "byte " + std::to_string(i) + " is not UTF-8";
    if (control(cp)) return "byte " + std::to_string(i) + " is a control character";
    i += n;
  }
  return "";
}

std::string printable(std::string_view text) {
  std::string out;
  for (size_t i = 0; i < text.size();) {
    uint32_t cp = 0;
    size_t n = utf8_length(text, i, &cp);
    if (n == 0 || control(cp)) {
      for (size_t k = 0; k < std::max<size_t>(n, 1); ++k) {
        char buf[8];
        std::snprintf(buf, sizeof buf, "\\x%02x", unsigned(uint8_t(text[i + k])));
        out += buf;
      }
      i += std::max<size_t>(n, 1);
      continue;
    }
    out.append(text.substr(i, n));
    i += n;
  }
  return out;
}

std::vector<std::string> bounded_log(const std::vector<std::string>& lines) {
  constexpr size_t kHead = 8;  // the first lines; the rest of the room for the last ones
  std::vector<std::string> out;
  auto add = [&](const std::string& l) {
    out.push_back(printable(std::string_view(l).substr(0, kAttemptLogLineBytes)));
  };
  if (lines.size() <= kAttemptLogLines) {
    for (const std::string& l : lines) add(l);
    return out;
  }
  const size_t tail = kAttemptLogLines - kHead - 1;
  for (size_t i = 0; i < kHead; ++i) add(lines[i]);
  out.push_back("... " + std::to_string(lines.size() - kHead - tail) + " lines left out ...");
  for (size_t i = lines.size() - tail; i < lines.size(); ++i) add(lines[i]);
  return out;
}

std::string task_id_text(const TaskRef& t) {
  return t.job_id + "/" + std::to_string(t.frame) + "/" + std::to_string(t.pass) + "/" +
         std::to_string(t.tile);
}

namespace {
// One number of a task id and the '/' after it (none after the last): the whole field, in T's
// range, or false.
template <typename T>
bool task_id_field(const char*& p, const char* end, T& out, bool last) {
  auto [q, ec] = std::from_chars(p, end, out);
  if (ec != std::errc() || q == p) return false;
  if (last) {
    p = q;
    return q == end;
  }
  if (q == end || *q != '/') return false;
  p = q + 1;
  return true;
}
}  // namespace

std::optional<TaskRef> parse_task_id(std::string_view text) {
  size_t slash = text.find('/');
  if (slash == std::string_view::npos || slash == 0) return std::nullopt;
  TaskRef t{std::string(text.substr(0, slash)), 0, 0, 0};
  const char* p = text.data() + slash + 1;
  const char* end = text.data() + text.size();
  if (!task_id_field(p, end, t.frame, false) || !task_id_field(p, end, t.pass, false) ||
      !task_id_field(p, end, t.tile, true))
    return std::nullopt;
  return t;
}

}  // namespace rf
