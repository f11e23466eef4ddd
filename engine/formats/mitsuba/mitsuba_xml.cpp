#include "engine/formats/mitsuba/mitsuba_xml.h"

#include <algorithm>
#include <cctype>
#include <map>
#include <new>

#include "engine/scene_error.h"

namespace rf::mitsuba {

struct Source {
  std::string name;  // as messages name it: the main path as given, or the include's path
  std::string bytes;
  pugi::xml_document doc;
  std::vector<size_t> line_starts;  // byte offset of each line's first character
  bool pre_v2 = false;              // Mitsuba 0.x file: names are upgraded on reading

  int line_of(ptrdiff_t offset) const {
    if (offset < 0) return 0;
    auto it = std::upper_bound(line_starts.begin(), line_starts.end(), size_t(offset));
    return int(it - line_starts.begin());
  }
};

namespace {

// Mitsuba 3's upgrade of 0.x parameter names: "maxDepth" -> "max_depth", "intIOR" -> "int_ior".
std::string camel_to_snake(const std::string& s) {
  std::string out;
  for (size_t i = 0; i < s.size(); ++i) {
    char c = s[i];
    if (i > 0 && std::isupper(static_cast<unsigned char>(c)) &&
        (std::islower(static_cast<unsigned char>(s[i - 1])) ||
         std::isdigit(static_cast<unsigned char>(s[i - 1]))))
      out += '_';
    out += char(std::tolower(static_cast<unsigned char>(c)));
  }
  return out;
}

// An element child of a parent with the part of its XML path that tells it from its siblings:
// [@id='x'], [@name='y'], or [i] when it is the i-th of several elements of its name.
struct Qualified {
  pugi::xml_node node;
  std::string qualifier;
};

// The element children of `parent`, qualified, in one pass over them and a map of names (a
// scene of 50,000 shapes has 50,000 siblings).
std::vector<Qualified> qualified_children(pugi::xml_node parent) {
  std::map<std::string, int> count, seen;
  for (pugi::xml_node s = parent.first_child(); s; s = s.next_sibling())
    if (s.type() == pugi::node_element) ++count[s.name()];
  std::vector<Qualified> out;
  for (pugi::xml_node s = parent.first_child(); s; s = s.next_sibling()) {
    if (s.type() != pugi::node_element) continue;
    int index = ++seen[s.name()];
    std::string q;
    if (pugi::xml_attribute id = s.attribute("id"))
      q = "[@id='" + std::string(id.value()) + "']";
    else if (pugi::xml_attribute nm = s.attribute("name"))
      q = "[@name='" + std::string(nm.value()) + "']";
    else if (count[s.name()] > 1)
      q = "[" + std::to_string(index) + "]";
    out.push_back({s, std::move(q)});
  }
  return out;
}

// The first element nested deeper than kMaxNesting, or an empty node (a walk without recursion).
pugi::xml_node too_deep(pugi::xml_node root) {
  int depth = 0;
  pugi::xml_node n = root;
  while (n) {
    if (pugi::xml_node c = n.first_child()) {
      n = c;
      if (++depth > kMaxNesting) return n;
      continue;
    }
    while (n && n != root && !n.next_sibling()) n = n.parent(), --depth;
    if (!n || n == root) break;
    n = n.next_sibling();
  }
  return {};
}

bool is_name_char(char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; }

}  // namespace

int Node::line() const { return source ? source->line_of(xml.offset_debug()) : 0; }
const std::string& Node::file() const { return source->name; }
std::string Node::where() const {
  return source->name + ":" + std::to_string(line()) + ": " + path;
}
std::string Node::tag() const {
  std::string t = xml.name();
  if (source && source->pre_v2) {
    if (t == "lookAt") return "lookat";
    if (t == "srgb") return "rgb";
  }
  return t;
}

Document::Document(const std::string& path, const std::string& bytes, SceneFiles& files,
                   std::vector<std::string>& warnings)
    : scene_path_(path), files_(files), warnings_(warnings) {
  const Source& src = load(path, bytes, nullptr);
  root_ = Node{src.doc.document_element(), &src, "scene"};
}

Document::~Document() = default;

const Source& Document::load(const std::string& name, const std::string& bytes, const Node* from) {
  auto src = std::make_unique<Source>();
  src->name = name;
  src->bytes = bytes;
  src->line_starts.push_back(0);
  for (size_t i = 0; i < bytes.size(); ++i)
    if (bytes[i] == '\n') src->line_starts.push_back(i + 1);
  pugi::xml_parse_result r = src->doc.load_buffer(src->bytes.data(), src->bytes.size(),
                                                  pugi::parse_default, pugi::encoding_utf8);
  if (r.status == pugi::status_out_of_memory) throw std::bad_alloc();  // not the file's fault
  if (!r)
    throw SceneError(name + ":" + std::to_string(src->line_of(r.offset)) +
                     ": not well-formed XML: " + r.description() +
                     (from ? " (included from " + from->where() + ")" : ""));
  if (pugi::xml_node deep = too_deep(src->doc))
    throw SceneError(name + ":" + std::to_string(src->line_of(deep.offset_debug())) +
                     ": elements nested more than " + std::to_string(kMaxNesting) +
                     " deep (the import limit on nesting)");
  pugi::xml_node scene = src->doc.document_element();
  Node root{scene, src.get(), "scene"};
  if (std::string(scene.name()) != "scene")
    throw SceneError(name + ":" + std::to_string(root.line()) +
                     ": the root element must be <scene>, got <" + scene.name() + ">");
  pugi::xml_attribute version = scene.attribute("version");
  if (!version)
    throw SceneError(name + ":" + std::to_string(root.line()) +
                     ": scene: the 'version' attribute is required (e.g. version=\"3.0.0\")");
  int major = std::atoi(version.value());
  if (major < 2) {
    src->pre_v2 = true;
    warnings_.push_back(root.where() + ": Mitsuba " + version.value() +
                        " file: parameter names upgraded to Mitsuba 3's (camelCase to snake_case)");
  } else if (major > 3) {
    warnings_.push_back(root.where() + ": version " + version.value() +
                        " is newer than the Mitsuba 3 format this importer reads");
  }
  sources_.push_back(std::move(src));
  const Source& s = *sources_.back();
  collect_defaults(s, scene);
  return s;
}

// <default name="x" value="y"/>: the first definition wins (Mitsuba: a value given on its command
// line overrides the file's default; this importer has no such values).
void Document::collect_defaults(const Source& src, pugi::xml_node scene) {
  for (const Qualified& q : qualified_children(scene)) {
    pugi::xml_node d = q.node;
    if (std::string(d.name()) != "default") continue;
    Node n{d, &src, "scene/default" + q.qualifier};
    if (!d.attribute("name")) fail(n, "<default> needs a 'name' attribute");
    if (!d.attribute("value")) fail(n, "<default> needs a 'value' attribute");
    params_.emplace(d.attribute("name").value(), d.attribute("value").value());
  }
}

std::vector<Node> Document::children(const Node& n) {
  std::vector<Node> out;
  for (const Qualified& q : qualified_children(n.xml)) {
    pugi::xml_node c = q.node;
    Node child{c, n.source, n.path + "/" + c.name() + q.qualifier};
    std::string tag = c.name();
    if (tag == "default") continue;  // collected when the file was parsed
    if (tag != "include") {
      out.push_back(child);
      continue;
    }
    if (include_depth_ >= 16) fail(child, "includes nested more than 16 deep (an include cycle?)");
    std::string file = attr(child, "filename");
    std::string bytes =
        with_location(child, [&] { return files_.read(file, child.path + "/@filename"); });
    std::string name = with_location(child, [&] { return files_.name(file, child.path); });
    const Source& src = load(files_.path_of(name), bytes, &child);
    ++include_depth_;
    std::vector<Node> inner = children(Node{src.doc.document_element(), &src, "scene"});
    --include_depth_;
    out.insert(out.end(), inner.begin(), inner.end());
  }
  return out;
}

std::string Document::substitute(const Node& n, const std::string& value,
                                 const char* attribute) const {
  std::string out;
  for (size_t i = 0; i < value.size(); ++i) {
    if (value[i] != '$') {
      out += value[i];
      continue;
    }
    size_t j = i + 1;
    while (j < value.size() && is_name_char(value[j])) ++j;
    std::string key = value.substr(i + 1, j - i - 1);
    if (key.empty()) fail(n, std::string("@") + attribute + ": '$' without a parameter name");
    auto it = params_.find(key);
    if (it == params_.end())
      fail(n, std::string("@") + attribute + ": undefined parameter '$" + key +
                  "' (no <default name=\"" + key + "\" .../> gives it a value)");
    out += it->second;
    i = j - 1;
  }
  return out;
}

std::string Document::attr(const Node& n, const char* attribute) {
  pugi::xml_attribute a = n.xml.attribute(attribute);
  if (!a) fail(n, std::string("<") + n.xml.name() + "> needs a '" + attribute + "' attribute");
  std::string v = substitute(n, a.value(), attribute);
  if (n.source->pre_v2 && std::string(attribute) == "name") v = camel_to_snake(v);
  return v;
}

std::string Document::attr_or(const Node& n, const char* attribute, const std::string& fallback) {
  return n.xml.attribute(attribute) ? attr(n, attribute) : fallback;
}

void Document::fail(const Node& n, const std::string& message) const {
  throw SceneError(n.where() + ": " + message);
}

void Document::warn(const Node& n, const std::string& message) {
  warnings_.push_back(n.where() + ": " + message);
}

std::string Document::strip_scene_path(const std::string& message) const {
  const std::string prefix = scene_path_ + ": ";
  return message.rfind(prefix, 0) == 0 ? message.substr(prefix.size()) : message;
}

}  // namespace rf::mitsuba
