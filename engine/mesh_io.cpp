#include "engine/mesh_io.h"

#include <spdlog/spdlog.h>

#include <bit>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <exception>
#include <unordered_map>

#include "engine/digest.h"

namespace rf {
namespace {

std::string read_asset(const std::string& path) {
  try {
    return read_file_bytes(path);
  } catch (const std::exception& e) {
    throw SceneError(e.what());
  }
}

std::vector<std::string_view> split_ws(std::string_view s) {
  std::vector<std::string_view> out;
  size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && (s[i] == ' ' || s[i] == '\t' || s[i] == '\r')) ++i;
    size_t j = i;
    while (j < s.size() && s[j] != ' ' && s[j] != '\t' && s[j] != '\r') ++j;
    if (j > i) out.push_back(s.substr(i, j - i));
    i = j;
  }
  return out;
}

// Whole-token number parsing; a leading '+' is accepted because some exporters write it.
template <typename T>
bool parse_number(std::string_view tok, T& out) {
  if (tok.size() > 1 && tok[0] == '+') tok.remove_prefix(1);
  auto [end, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), out);
  return ec == std::errc() && end == tok.data() + tok.size();
}

std::string quoted(std::string_view s) { return "'" + std::string(s) + "'"; }

// ---------------------------------------------------------------------------------------------
// OBJ

struct ObjCorner {
  int64_t v = -1, vt = -1, vn = -1;  // 0-based, -1 when absent
  bool operator==(const ObjCorner&) const = default;
};

struct ObjCornerHash {
  size_t operator()(const ObjCorner& c) const {
    uint64_t h = static_cast<uint64_t>(c.v) * 0x9E3779B97F4A7C15ull;
    h ^= static_cast<uint64_t>(c.vt) + 0x7F4A7C15ull + (h << 6) + (h >> 2);
    h ^= static_cast<uint64_t>(c.vn) + 0x9E3779B9ull + (h << 6) + (h >> 2);
    return static_cast<size_t>(h);
  }
};

class ObjParser {
 public:
  explicit ObjParser(const std::string& name) : name_(name) {}

  MeshData parse(std::string_view text) {
    size_t start = 0;
    while (start <= text.size()) {
      size_t end = text.find('\n', start);
      if (end == std::string_view::npos) end = text.size();
      ++line_;
      statement(text.substr(start, end - start));
      start = end + 1;
    }
    return finish();
  }

 private:
  [[noreturn]] void fail(const std::string& what) const {
    throw SceneError(name_ + ":" + std::to_string(line_) + ": " + what);
  }

  void statement(std::string_view line) {
    if (size_t hash = line.find('#'); hash != std::string_view::npos) line = line.substr(0, hash);
    auto tok = split_ws(line);
    if (tok.empty()) return;
    if (tok[0] == "v") {
      positions_.push_back(read_vec3(tok, "v", 3));
    } else if (tok[0] == "vn") {
      normals_.push_back(read_vec3(tok, "vn", 3));
    } else if (tok[0] == "vt") {
      if (tok.size() < 2) fail("'vt' needs at least 1 number");
      Vec2 uv{read_float(tok[1]), tok.size() > 2 ? read_float(tok[2]) : 0.0f};
      uvs_.push_back(uv);
    } else if (tok[0] == "f") {
      face(tok);
    }
    // Everything else (o, g, s, usemtl, mtllib, l, p, ...) does not affect the triangles.
  }

  float read_float(std::string_view tok) const {
    float v;
    if (!parse_number(tok, v) || !std::isfinite(v))
      fail("expected a finite number, got " + quoted(tok));
    return v;
  }

  Vec3 read_vec3(const std::vector<std::string_view>& tok, const char* what, size_t n) const {
    if (tok.size() < n + 1)
      fail(quoted(what) + " needs 3 numbers, got " + std::to_string(tok.size() - 1));
    return {read_float(tok[1]), read_float(tok[2]), read_float(tok[3])};
  }

  // Resolves a 1-based or negative (relative to the end so far) index to 0-based.
  int64_t resolve(std::string_view tok, size_t count, const char* kind, const char* kinds) const {
    int64_t i;
    if (!parse_number(tok, i)) fail("bad " + std::string(kind) + " index " + quoted(tok));
    int64_t r = i > 0 ? i - 1 : static_cast<int64_t>(count) + i;
    if (i == 0 || r < 0 || r >= static_cast<int64_t>(count))
      fail(std::string(kind) + " index " + std::to_string(i) + " out of range (" +
           std::to_string(count) + " " + (count == 1 ? kind : kinds) + " defined so far)");
    return r;
  }

  ObjCorner corner(std::string_view tok) const {
    ObjCorner c;
    size_t s1 = tok.find('/');
    c.v = resolve(tok.substr(0, s1), positions_.size(), "vertex", "vertices");
    if (s1 == std::string_view::npos) return c;
    std::string_view rest = tok.substr(s1 + 1);
    size_t s2 = rest.find('/');
    std::string_view t = rest.substr(0, s2);
    if (!t.empty()) c.vt = resolve(t, uvs_.size(), "texture coordinate", "texture coordinates");
    if (s2 != std::string_view::npos) {
      std::string_view n = rest.substr(s2 + 1);
      if (!n.empty()) c.vn = resolve(n, normals_.size(), "normal", "normals");
    }
    return c;
  }

  uint32_t vertex_of(const ObjCorner& c) {
    auto [it, inserted] = vertex_ids_.try_emplace(c, static_cast<uint32_t>(out_.positions.size()));
    if (inserted) {
      out_.positions.push_back(positions_[c.v]);
      out_.normals.push_back(c.vn >= 0 ? normals_[c.vn] : Vec3(0.0f));
      out_.uvs.push_back(c.vt >= 0 ? uvs_[c.vt] : Vec2{});
      (c.vn >= 0 ? with_normal_ : without_normal_) = true;
      (c.vt >= 0 ? with_uv_ : without_uv_) = true;
    }
    return it->second;
  }

  void face(const std::vector<std::string_view>& tok) {
    if (tok.size() < 4)
      fail("face needs at least 3 vertices, got " + std::to_string(tok.size() - 1));
    std::vector<uint32_t> ids;
    for (size_t i = 1; i < tok.size(); ++i) ids.push_back(vertex_of(corner(tok[i])));
    for (size_t i = 1; i + 1 < ids.size(); ++i)  // fan around the first corner
      out_.indices.insert(out_.indices.end(), {ids[0], ids[i], ids[i + 1]});
  }

  MeshData finish() {
    if (with_normal_ && without_normal_)
      spdlog::warn("{}: only some face corners have normals; using flat shading", name_);
    if (!with_normal_ || without_normal_) out_.normals.clear();
    if (with_uv_ && without_uv_)
      spdlog::warn("{}: only some face corners have texture coordinates; ignoring them", name_);
    if (!with_uv_ || without_uv_) out_.uvs.clear();
    return std::move(out_);
  }

  const std::string& name_;
  size_t line_ = 0;
  std::vector<Vec3> positions_, normals_;
  std::vector<Vec2> uvs_;
  std::unordered_map<ObjCorner, uint32_t, ObjCornerHash> vertex_ids_;
  MeshData out_;
  bool with_normal_ = false, without_normal_ = false, with_uv_ = false, without_uv_ = false;
};

// ---------------------------------------------------------------------------------------------
// PLY

enum class PlyType : uint8_t { I8, U8, I16, U16, I32, U32, F32, F64 };
enum class PlyFormat : uint8_t { Ascii, BinaryLittle, BinaryBig };

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::F32;  // item type for lists
  bool is_list = false;
  PlyType count_type = PlyType::U8;
};

struct PlyElement {
  std::string name;
  uint64_t count = 0;
  std::vector<PlyProperty> properties;
};

struct PlyHeader {
  PlyFormat format = PlyFormat::Ascii;
  std::vector<PlyElement> elements;
  size_t data_offset = 0;  // first byte after "end_header\n"
  size_t lines = 0;        // header lines, so ascii data lines can be numbered
};

bool ply_type(std::string_view s, PlyType& t) {
  static const std::pair<std::string_view, PlyType> kNames[] = {
      {"char", PlyType::I8},    {"int8", PlyType::I8},     {"uchar", PlyType::U8},
      {"uint8", PlyType::U8},   {"short", PlyType::I16},   {"int16", PlyType::I16},
      {"ushort", PlyType::U16}, {"uint16", PlyType::U16},  {"int", PlyType::I32},
      {"int32", PlyType::I32},  {"uint", PlyType::U32},    {"uint32", PlyType::U32},
      {"float", PlyType::F32},  {"float32", PlyType::F32}, {"double", PlyType::F64},
      {"float64", PlyType::F64}};
  for (auto& [n, ty] : kNames)
    if (s == n) return t = ty, true;
  return false;
}

size_t ply_size(PlyType t) {
  switch (t) {
    case PlyType::I8:
    case PlyType::U8:
      return 1;
    case PlyType::I16:
    case PlyType::U16:
      return 2;
    case PlyType::I32:
    case PlyType::U32:
    case PlyType::F32:
      return 4;
    case PlyType::F64:
      return 8;
  }
  return 0;
}

bool ply_is_integer(PlyType t) { return t != PlyType::F32 && t != PlyType::F64; }

PlyHeader parse_ply_header(std::string_view bytes, const std::string& name) {
  auto fail = [&](size_t line, const std::string& what) -> void {
    throw SceneError(name + ":" + std::to_string(line) + ": " + what);
  };
  PlyHeader h;
  size_t pos = 0;
  bool ended = false, have_format = false;
  while (!ended) {
    size_t end = bytes.find('\n', pos);
    if (end == std::string_view::npos) fail(h.lines + 1, "PLY header has no 'end_header' line");
    auto tok = split_ws(bytes.substr(pos, end - pos));
    pos = end + 1;
    ++h.lines;
    if (h.lines == 1) {
      if (tok.size() != 1 || tok[0] != "ply") fail(1, "not a PLY file (first line is not 'ply')");
      continue;
    }
    if (tok.empty() || tok[0] == "comment" || tok[0] == "obj_info") continue;
    if (tok[0] == "format") {
      if (tok.size() < 2) fail(h.lines, "'format' needs a format name");
      if (tok[1] == "ascii")
        h.format = PlyFormat::Ascii;
      else if (tok[1] == "binary_little_endian")
        h.format = PlyFormat::BinaryLittle;
      else if (tok[1] == "binary_big_endian")
        h.format = PlyFormat::BinaryBig;
      else
        fail(h.lines, "unknown PLY format " + quoted(tok[1]));
      have_format = true;
    } else if (tok[0] == "element") {
      PlyElement e;
      if (tok.size() != 3 || !parse_number(tok[2], e.count))
        fail(h.lines, "expected 'element <name> <count>'");
      e.name = tok[1];
      h.elements.push_back(std::move(e));
    } else if (tok[0] == "property") {
      if (h.elements.empty()) fail(h.lines, "'property' before any 'element'");
      PlyProperty p;
      bool ok = false;
      if (tok.size() == 3) {
        ok = ply_type(tok[1], p.type);
      } else if (tok.size() == 5 && tok[1] == "list") {
        p.is_list = true;
        ok = ply_type(tok[2], p.count_type) && ply_is_integer(p.count_type) &&
             ply_type(tok[3], p.type);
      }
      if (!ok)
        fail(h.lines,
             "expected 'property <type> <name>' or "
             "'property list <integer type> <type> <name>'");
      p.name = tok.back();
      h.elements.back().properties.push_back(std::move(p));
    } else if (tok[0] == "end_header") {
      ended = true;
    } else {
      fail(h.lines, "unknown PLY header line starting with " + quoted(tok[0]));
    }
  }
  if (!have_format) fail(h.lines, "PLY header has no 'format' line");
  h.data_offset = pos;
  return h;
}

// Reads scalar values one at a time from the data section, ascii or binary.
class PlyReader {
 public:
  PlyReader(std::string_view data, const PlyHeader& h, const std::string& name)
      : data_(data), format_(h.format), name_(name), line_(h.lines + 1) {}

  // Where the reader is, for messages: set by the caller before each row.
  void set_row(const PlyElement& e, uint64_t row) {
    element_ = &e;
    row_ = row;
  }

  [[noreturn]] void fail(const std::string& what) const {
    std::string where = name_;
    if (format_ == PlyFormat::Ascii) where += ":" + std::to_string(line_);
    if (element_)
      where += ": element '" + element_->name + "' row " + std::to_string(row_) + " of " +
               std::to_string(element_->count);
    throw SceneError(where + ": " + what);
  }

  double read(PlyType t) { return format_ == PlyFormat::Ascii ? read_ascii(t) : read_binary(t); }

  // At most how many rows of `e` the rest of the data can hold (each row takes at least a byte
  // per value in ascii, its fixed-size values in binary): a bound for reserving memory.
  uint64_t rows_that_fit(const PlyElement& e) const {
    uint64_t min_row = 0;
    for (const PlyProperty& p : e.properties)
      min_row += format_ == PlyFormat::Ascii ? 1 : ply_size(p.is_list ? p.count_type : p.type);
    return (data_.size() - pos_) / std::max<uint64_t>(min_row, 1);
  }

 private:
  double read_ascii(PlyType t) {
    while (pos_ < data_.size() && std::isspace(static_cast<unsigned char>(data_[pos_]))) {
      if (data_[pos_] == '\n') ++line_;
      ++pos_;
    }
    if (pos_ >= data_.size()) fail("unexpected end of data");
    size_t end = pos_;
    while (end < data_.size() && !std::isspace(static_cast<unsigned char>(data_[end]))) ++end;
    std::string_view tok = data_.substr(pos_, end - pos_);
    pos_ = end;
    double v;
    if (!parse_number(tok, v)) fail("expected a number, got " + quoted(tok));
    if (ply_is_integer(t) && v != std::floor(v)) fail("expected an integer, got " + quoted(tok));
    return v;
  }

  template <typename U>
  U take() {
    U u;
    std::memcpy(&u, data_.data() + pos_, sizeof(U));
    pos_ += sizeof(U);
    bool file_little = format_ == PlyFormat::BinaryLittle;
    if (file_little != (std::endian::native == std::endian::little)) u = byteswap(u);
    return u;
  }

  template <typename U>
  static U byteswap(U u) {
    U r = 0;
    for (size_t i = 0; i < sizeof(U); ++i) r = static_cast<U>((r << 8) | ((u >> (8 * i)) & 0xFF));
    return r;
  }

  double read_binary(PlyType t) {
    if (data_.size() - pos_ < ply_size(t)) fail("unexpected end of data (binary file truncated?)");
    switch (t) {
      case PlyType::I8:
        return static_cast<int8_t>(take<uint8_t>());
      case PlyType::U8:
        return take<uint8_t>();
      case PlyType::I16:
        return static_cast<int16_t>(take<uint16_t>());
      case PlyType::U16:
        return take<uint16_t>();
      case PlyType::I32:
        return static_cast<int32_t>(take<uint32_t>());
      case PlyType::U32:
        return take<uint32_t>();
      case PlyType::F32:
        return std::bit_cast<float>(take<uint32_t>());
      case PlyType::F64:
        return std::bit_cast<double>(take<uint64_t>());
    }
    return 0;
  }

  std::string_view data_;
  PlyFormat format_;
  const std::string& name_;
  size_t pos_ = 0, line_;
  const PlyElement* element_ = nullptr;
  uint64_t row_ = 0;
};

int find_property(const PlyElement& e, std::initializer_list<std::string_view> names) {
  for (std::string_view n : names)
    for (size_t i = 0; i < e.properties.size(); ++i)
      if (e.properties[i].name == n && !e.properties[i].is_list) return static_cast<int>(i);
  return -1;
}

// Reads one row: scalars into `values`, the list at `list_index` (if any) into `list`; other
// lists are read and discarded.
void read_ply_row(PlyReader& r, const PlyElement& e, int list_index, std::vector<double>& values,
                  std::vector<double>& list) {
  values.assign(e.properties.size(), 0.0);
  list.clear();
  for (size_t i = 0; i < e.properties.size(); ++i) {
    const PlyProperty& p = e.properties[i];
    if (!p.is_list) {
      values[i] = r.read(p.type);
      continue;
    }
    double n = r.read(p.count_type);
    if (n < 0) r.fail("negative list length in property '" + p.name + "'");
    for (uint64_t k = 0; k < static_cast<uint64_t>(n); ++k) {
      double v = r.read(p.type);
      if (static_cast<int>(i) == list_index) list.push_back(v);
    }
  }
}

void read_ply_vertices(PlyReader& r, const PlyElement& e, MeshData& m) {
  int x = find_property(e, {"x"}), y = find_property(e, {"y"}), z = find_property(e, {"z"});
  if (x < 0 || y < 0 || z < 0) r.fail("element 'vertex' needs properties x, y and z");
  int nx = find_property(e, {"nx"}), ny = find_property(e, {"ny"}), nz = find_property(e, {"nz"});
  bool has_n = nx >= 0 && ny >= 0 && nz >= 0;
  int u = find_property(e, {"u", "s", "texture_u", "texture_s"});
  int v = find_property(e, {"v", "t", "texture_v", "texture_t"});
  bool has_uv = u >= 0 && v >= 0;
  std::vector<double> val, unused;
  // Sized once (the count is checked against the data as the rows are read, so a lying header
  // costs at most this reservation, capped): a million vertices would otherwise be copied ~20
  // times as the vectors grow.
  const size_t expect = size_t(std::min<uint64_t>(e.count, r.rows_that_fit(e)));
  m.positions.reserve(expect);
  if (has_n) m.normals.reserve(expect);
  if (has_uv) m.uvs.reserve(expect);
  for (uint64_t row = 0; row < e.count; ++row) {
    r.set_row(e, row);
    read_ply_row(r, e, -1, val, unused);
    Vec3 p{float(val[x]), float(val[y]), float(val[z])};
    if (!is_finite(p)) r.fail("vertex position is not finite");
    m.positions.push_back(p);
    if (has_n) m.normals.emplace_back(float(val[nx]), float(val[ny]), float(val[nz]));
    if (has_uv) m.uvs.push_back({float(val[u]), float(val[v])});
  }
}

void read_ply_faces(PlyReader& r, const PlyElement& e, uint64_t vertex_count, MeshData& m) {
  int list = -1;
  for (size_t i = 0; i < e.properties.size(); ++i)
    if (e.properties[i].is_list &&
        (e.properties[i].name == "vertex_indices" || e.properties[i].name == "vertex_index"))
      list = static_cast<int>(i);
  if (list < 0) r.fail("element 'face' needs a list property 'vertex_indices' or 'vertex_index'");
  if (!ply_is_integer(e.properties[list].type)) r.fail("face vertex indices must be integers");
  std::vector<double> val, ids;
  m.indices.reserve(3 * size_t(std::min<uint64_t>(e.count, r.rows_that_fit(e))));  // triangles
  for (uint64_t row = 0; row < e.count; ++row) {
    r.set_row(e, row);
    read_ply_row(r, e, list, val, ids);
    if (ids.size() < 3) r.fail("face needs at least 3 vertices, got " + std::to_string(ids.size()));
    for (double id : ids)
      if (id < 0 || id >= static_cast<double>(vertex_count))
        r.fail("vertex index " + std::to_string(static_cast<int64_t>(id)) + " out of range (" +
               std::to_string(vertex_count) + " vertices)");
    for (size_t i = 1; i + 1 < ids.size(); ++i)  // fan around the first corner
      m.indices.insert(m.indices.end(), {uint32_t(ids[0]), uint32_t(ids[i]), uint32_t(ids[i + 1])});
  }
}

}  // namespace

MeshData parse_obj(std::string_view text, const std::string& name) {
  return ObjParser(name).parse(text);
}

MeshData parse_ply(std::string_view bytes, const std::string& name) {
  PlyHeader h = parse_ply_header(bytes, name);
  uint64_t vertex_count = 0;
  bool has_vertex_element = false;
  for (const PlyElement& e : h.elements)
    if (e.name == "vertex") vertex_count = e.count, has_vertex_element = true;
  if (!has_vertex_element) throw SceneError(name + ": PLY file has no 'vertex' element");
  if (vertex_count > UINT32_MAX)
    throw SceneError(name + ": too many vertices (" + std::to_string(vertex_count) + ")");
  MeshData m;
  PlyReader r(bytes.substr(h.data_offset), h, name);
  std::vector<double> val, unused;
  for (const PlyElement& e : h.elements) {
    if (e.name == "vertex") {
      read_ply_vertices(r, e, m);
    } else if (e.name == "face") {
      read_ply_faces(r, e, vertex_count, m);
    } else {
      for (uint64_t row = 0; row < e.count; ++row) {
        r.set_row(e, row);
        read_ply_row(r, e, -1, val, unused);
      }
    }
  }
  return m;
}

MeshData load_obj(const std::string& path) { return parse_obj(read_asset(path), path); }
MeshData load_ply(const std::string& path) { return parse_ply(read_asset(path), path); }

}  // namespace rf
