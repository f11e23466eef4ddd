#include "farm/tags.h"

#include <unistd.h>

#include <charconv>
#include <thread>

#include "engine/build_info.h"
#include "farm/job.h"  // printable

namespace rf {

namespace {

std::string name_problem(const std::string& name) {
  if (name.empty() || name.size() > 64) return "a tag name has 1 to 64 characters";
  if (name[0] < 'a' || name[0] > 'z') return "a tag name starts with a letter (a-z)";
  for (char c : name)
    if (!((c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '_' || c == '.' || c == '-'))
      return "a tag name holds a-z, 0-9, '_', '.' and '-' only";
  return "";
}

std::string value_problem(const std::string& value) {
  if (value.empty() || value.size() > 128) return "a tag value has 1 to 128 characters";
  for (char c : value)
    if (c <= ' ' || c > '~' || c == ',')
      return "a tag value holds printable ASCII, no space or ','";
  return "";
}

bool number(const std::string& text, double& out) {
  const char* end = text.data() + text.size();
  auto [p, ec] = std::from_chars(text.data(), end, out);
  return ec == std::errc() && p == end;
}

// "name", "name=value" or (requirements only) "name>=value" as its parts.
struct Parsed {
  std::string name, op, value;
};

Parsed split(const std::string& text) {
  size_t ge = text.find(">=");
  size_t eq = text.find('=');
  if (ge != std::string::npos && ge < eq) return {text.substr(0, ge), ">=", text.substr(ge + 2)};
  if (eq != std::string::npos) return {text.substr(0, eq), "=", text.substr(eq + 1)};
  return {text, "", ""};
}

std::string problem(const std::string& tag, bool requirement) {
  const std::string text = printable(tag.substr(0, 200));  // quoted in messages and logs
  Parsed p = split(tag);
  if (p.op == ">=" && !requirement) return "'" + text + "': a worker's tag has no '>='";
  if (std::string why = name_problem(p.name); !why.empty()) return "'" + text + "': " + why;
  if (p.op.empty()) return "";
  if (std::string why = value_problem(p.value); !why.empty()) return "'" + text + "': " + why;
  double n = 0;
  if (p.op == ">=" && !number(p.value, n)) return "'" + text + "': '>=' takes a number";
  return "";
}

}  // namespace

std::string tag_problem(const std::string& tag) { return problem(tag, false); }
std::string requirement_problem(const std::string& r) { return problem(r, true); }

bool satisfies(const std::vector<std::string>& tags, const std::string& requirement) {
  const Parsed want = split(requirement);
  for (const std::string& tag : tags) {
    const Parsed have = split(tag);
    if (have.name != want.name) continue;
    if (want.op.empty()) return true;
    if (want.op == "=" && have.op == "=" && have.value == want.value) return true;
    double h = 0, w = 0;
    if (want.op == ">=" && have.op == "=" && number(have.value, h) && number(want.value, w) &&
        h >= w)
      return true;
  }
  return false;
}

bool satisfies_all(const std::vector<std::string>& tags,
                   const std::vector<std::string>& requirements) {
  for (const std::string& r : requirements)
    if (!satisfies(tags, r)) return false;
  return true;
}

std::string pool_of(const std::vector<std::string>& requirements) {
  for (const std::string& r : requirements) {
    const Parsed p = split(r);
    if (p.name == "pool" && p.op == "=") return p.value;
  }
  return "";
}

std::vector<std::string> automatic_tags() {
  const std::string kind = cpu_isa();
  std::vector<std::string> tags{"isa=" + kind.substr(0, kind.find(' '))};
  tags.push_back("cores=" + std::to_string(std::max(1u, std::thread::hardware_concurrency())));
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  if (pages > 0 && page > 0)
    tags.push_back("memory_gb=" + std::to_string((long long)pages * page >> 30));
  return tags;
}

}  // namespace rf
