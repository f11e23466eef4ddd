#include "engine/json_reader.h"

#include <algorithm>
#include <cctype>
#include <set>
#include <sstream>

namespace rf {

std::string join_names(const std::vector<std::string>& names) {
  std::string out;
  for (const std::string& n : names) out += (out.empty() ? "" : ", ") + n;
  return out;
}

bool contains_name(const std::vector<std::string>& names, const std::string& n) {
  return std::find(names.begin(), names.end(), n) != names.end();
}

std::string json_child(const std::string& parent, std::string_view key) {
  bool plain = !key.empty() && std::all_of(key.begin(), key.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
  });
  if (!plain) return parent + "[\"" + std::string(key) + "\"]";
  return parent.empty() ? std::string(key) : parent + "." + std::string(key);
}
std::string json_child(const std::string& parent, size_t index) {
  return parent + "[" + std::to_string(index) + "]";
}

std::string describe_json(const Json& j) {
  if (j.is_array()) return "an array of " + std::to_string(j.size()) + " elements";
  if (j.is_object()) return "an object";
  std::string s = j.dump();
  if (s.size() > 40) s = s.substr(0, 37) + "...";
  return j.type_name() + std::string(" ") + s;
}

std::string format_number(double v) {
  std::ostringstream os;
  os << v;
  return os.str();
}


namespace {

// JSON text -> json, with positions for syntax errors and a check for duplicate keys (nlohmann
// silently keeps the last one, which would hide e.g. two materials of the same name).

struct JsonFrame {
  bool is_array = false;
  size_t count = 0;  // elements started so far (arrays)
  std::string key;   // current key (objects)
  std::set<std::string> keys;
};

std::string frames_path(const std::vector<JsonFrame>& frames) {
  std::string path;
  for (size_t i = 0; i + 1 < frames.size(); ++i)
    path = frames[i].is_array ? json_child(path, frames[i].count - 1) : json_child(path, frames[i].key);
  return path;
}

std::string line_column(std::string_view text, size_t byte) {
  size_t line = 1, col = 1;
  for (size_t i = 0; i < byte && i < text.size(); ++i) text[i] == '\n' ? (++line, col = 1) : ++col;
  return "line " + std::to_string(line) + ", column " + std::to_string(col);
}

// Refuses arrays and objects nested deeper than kMaxNesting before a parser sees them: nlohmann
// parses such text, but recursive readers of the result (tinygltf's) run out of stack.
void check_json_nesting(std::string_view text, const std::string& file) {
  int depth = 0;
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    char c = text[i];
    if (in_string) {
      if (c == '\\')
        ++i;
      else if (c == '"')
        in_string = false;
    } else if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      if (++depth > kMaxNesting)
        throw SceneError(file + ": " + line_column(text, i) + ": arrays and objects nested more " +
                         "than " + std::to_string(kMaxNesting) + " deep (the import limit on " +
                         "nesting)");
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
}

}  // namespace

Json parse_json_text(const std::string& text, const std::string& file) {
  check_json_nesting(text, file);
  std::vector<JsonFrame> frames;
  auto callback = [&](int, Json::parse_event_t ev, Json& parsed) {
    using E = Json::parse_event_t;
    bool starts = ev == E::object_start || ev == E::array_start || ev == E::value;
    if (starts && !frames.empty() && frames.back().is_array) ++frames.back().count;
    if (ev == E::object_start || ev == E::array_start) {
      frames.emplace_back();
      frames.back().is_array = ev == E::array_start;
    }
    if (ev == E::object_end || ev == E::array_end) frames.pop_back();
    if (ev == E::key) {
      std::string k = parsed.get<std::string>();
      if (!frames.back().keys.insert(k).second)
        throw SceneError(file + ": " + json_child(frames_path(frames), k) + ": duplicate key");
      frames.back().key = k;
    }
    return true;
  };
  try {
    return Json::parse(text, callback);
  } catch (const Json::parse_error& e) {
    // Keep nlohmann's explanation, but put the position in our own "file: where: what" form.
    std::string what = e.what();
    size_t col = what.find("column ");
    size_t colon = col == std::string::npos ? col : what.find(": ", col);
    std::string why = colon == std::string::npos ? what : what.substr(colon + 2);
    throw SceneError(file + ": " + line_column(text, e.byte ? e.byte - 1 : 0) + ": " + why);
  } catch (const Json::out_of_range& e) {
    // Number overflow (e.g. 1e999) carries no position; find the literal it names.
    std::string what = e.what();
    size_t q1 = what.find('\''), q2 = what.rfind('\'');
    std::string literal = q1 < q2 ? what.substr(q1 + 1, q2 - q1 - 1) : "";
    size_t at = literal.empty() ? std::string::npos : text.find(literal);
    std::string where = at == std::string::npos ? "(unknown position)" : line_column(text, at);
    throw SceneError(file + ": " + where + ": number " + literal +
                     " is out of range (JSON numbers must be finite)");
  }
}

}  // namespace rf
