// The XML layer of the Mitsuba 3 importer: the main file and its includes parsed by pugixml,
// `default` parameters and `$name` substitution in attribute values, the upgrade of pre-2.0
// names (camelCase to snake_case), and locations for messages: every element knows its file, its
// line (from pugixml's parse offsets) and its XML path (scene/bsdf[@id='x']/float[@name='foo']).
#pragma once

#include <deque>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <pugixml.hpp>

#include "engine/formats/scene_files.h"

namespace rf::mitsuba {

struct Source;  // one parsed file

// An element of the (include-expanded) document.
struct Node {
  pugi::xml_node xml;
  const Source* source = nullptr;
  std::string path;  // XML path from the main file's root, e.g. scene/shape[@id='floor']

  explicit operator bool() const { return bool(xml); }
  int line() const;
  const std::string& file() const;  // the file as messages name it
  std::string where() const;        // "<file>:<line>: <path>"
  std::string tag() const;          // upgraded for pre-2.0 files (lookAt -> lookat, srgb -> rgb)
  bool has(const char* attribute) const { return bool(xml.attribute(attribute)); }
};

class Document {
 public:
  // Parses the main file (its bytes already read); includes are read through `files`.
  Document(const std::string& path, const std::string& bytes, SceneFiles& files,
           std::vector<std::string>& warnings);
  ~Document();

  const Node& root() const { return root_; }  // the <scene> element
  // Element children, with <include> replaced by the included file's children; <default>
  // elements are consumed here (they define parameters when the file is parsed).
  std::vector<Node> children(const Node& n);
  // An attribute after $name substitution (and, for "name" in pre-2.0 files, the snake_case
  // upgrade); throws naming the element when it is missing and required.
  std::string attr(const Node& n, const char* attribute);
  std::string attr_or(const Node& n, const char* attribute, const std::string& fallback);

  [[noreturn]] void fail(const Node& n, const std::string& message) const;
  void warn(const Node& n, const std::string& message);
  // Runs a SceneFiles call, re-throwing its error with this element's location in front.
  template <class F>
  auto with_location(const Node& n, F&& f) -> decltype(f()) {
    try {
      return f();
    } catch (const SceneError& e) {
      fail(n, strip_scene_path(e.what()));
    }
  }

 private:
  const Source& load(const std::string& name, const std::string& bytes, const Node* from);
  void collect_defaults(const Source& src, pugi::xml_node scene);
  std::string substitute(const Node& n, const std::string& value, const char* attribute) const;
  std::string strip_scene_path(const std::string& message) const;

  std::string scene_path_;
  SceneFiles& files_;
  std::vector<std::string>& warnings_;
  std::deque<std::unique_ptr<Source>> sources_;
  std::map<std::string, std::string> params_;
  Node root_;
  int include_depth_ = 0;
};

}  // namespace rf::mitsuba
