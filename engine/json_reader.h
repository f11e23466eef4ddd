// Reading JSON with errors that name the file and the JSON path of the value they are about
// ("scene.json: shapes[3].material: expected a string, got number 4"). Used by the scene parser
// and by every integrator for its own keys (engine/integrators/).
#pragma once

#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "engine/import_limits.h"
#include "engine/math.h"
#include "engine/scene_error.h"

namespace rf {

using Json = nlohmann::json;

// "a.b", "a[3]"; keys that are not plain identifiers are quoted: materials["my wall"].
std::string json_child(const std::string& parent, std::string_view key);
std::string json_child(const std::string& parent, size_t index);
// Short description of a JSON value for "got ..." in messages.
std::string describe_json(const Json& j);
std::string format_number(double v);
std::string join_names(const std::vector<std::string>& names);  // "a, b, c"
bool contains_name(const std::vector<std::string>& names, const std::string& n);

// JSON text -> Json, with positions for syntax errors and a check for duplicate keys (nlohmann
// silently keeps the last one, which would hide e.g. two materials of the same name), and a bound
// on nesting (kMaxNesting). Throws SceneError naming the file, line and column.
Json parse_json_text(const std::string& text, const std::string& file);

// Typed access to JSON values, each failing with the value's path.

class JsonReader {
 public:
  explicit JsonReader(std::string file) : file_(std::move(file)) {}

  [[noreturn]] void fail(const std::string& path, const std::string& what) const {
    throw SceneError(file_ + ": " + (path.empty() ? "(top level)" : path) + ": " + what);
  }

  const std::string& file() const { return file_; }

  void expect_object(const Json& j, const std::string& path) const {
    if (!j.is_object()) fail(path, "expected an object, got " + describe_json(j));
  }

  // j must be an object whose keys are all in `allowed`: typos are errors, not silently ignored.
  void check_keys(const Json& j, const std::string& path,
                  const std::vector<std::string>& allowed) const {
    expect_object(j, path);
    for (auto it = j.begin(); it != j.end(); ++it)
      if (!contains_name(allowed, it.key()))
        fail(json_child(path, it.key()), "unknown key (expected one of: " + join_names(allowed) + ")");
  }

  const Json* find(const Json& j, const std::string& key) const {
    auto it = j.find(key);
    return it == j.end() ? nullptr : &*it;
  }

  const Json& require(const Json& j, const std::string& path, const std::string& key) const {
    const Json* v = find(j, key);
    if (!v) fail(json_child(path, key), "required key is missing");
    return *v;
  }

  // A number that is finite also in single precision (geometry and colours are float).
  float number(const Json& j, const std::string& path) const {
    if (!j.is_number()) fail(path, "expected a number, got " + describe_json(j));
    double v = j.get<double>();
    if (!std::isfinite(static_cast<float>(v)))
      fail(path, "number " + format_number(v) + " is not finite in single precision");
    return static_cast<float>(v);
  }

  double real(const Json& j, const std::string& path) const {
    if (!j.is_number()) fail(path, "expected a number, got " + describe_json(j));
    return j.get<double>();  // finite: nlohmann refuses overflowing literals
  }

  int64_t integer(const Json& j, const std::string& path, int64_t lo, int64_t hi) const {
    if (!j.is_number_integer()) fail(path, "expected an integer, got " + describe_json(j));
    if (j.is_number_unsigned() && j.get<uint64_t>() > static_cast<uint64_t>(hi))
      fail(path, "must be at most " + std::to_string(hi) + ", got " + j.dump());
    int64_t v = j.get<int64_t>();
    if (v < lo) fail(path, "must be at least " + std::to_string(lo) + ", got " + j.dump());
    if (v > hi) fail(path, "must be at most " + std::to_string(hi) + ", got " + j.dump());
    return v;
  }

  uint64_t unsigned_integer(const Json& j, const std::string& path, uint64_t lo) const {
    if (!j.is_number_unsigned()) fail(path, "expected a non-negative integer, got " + describe_json(j));
    uint64_t v = j.get<uint64_t>();
    if (v < lo) fail(path, "must be at least " + std::to_string(lo) + ", got " + j.dump());
    return v;
  }

  bool boolean(const Json& j, const std::string& path) const {
    if (!j.is_boolean()) fail(path, "expected true or false, got " + describe_json(j));
    return j.get<bool>();
  }

  std::string string(const Json& j, const std::string& path) const {
    if (!j.is_string()) fail(path, "expected a string, got " + describe_json(j));
    return j.get<std::string>();
  }

  const Json& array(const Json& j, const std::string& path, size_t n = 0) const {
    if (!j.is_array()) fail(path, "expected an array, got " + describe_json(j));
    if (n && j.size() != n)
      fail(path, "expected " + std::to_string(n) + " elements, got " + std::to_string(j.size()));
    return j;
  }

  Vec3 vec3(const Json& j, const std::string& path) const {
    array(j, path, 3);
    return {number(j[0], json_child(path, 0)), number(j[1], json_child(path, 1)),
            number(j[2], json_child(path, 2))};
  }

  // A colour: [r, g, b] or one number for grey; each component in [0, max].
  RGB rgb(const Json& j, const std::string& path, float max) const {
    if (!j.is_number() && !j.is_array())
      fail(path, "expected [r, g, b] or a number, got " + describe_json(j));
    RGB c = j.is_number() ? RGB(number(j, path)) : vec3(j, path);
    for (int i = 0; i < 3; ++i) {
      std::string p = j.is_number() ? path : json_child(path, i);
      if (c[i] < 0) fail(p, "must be at least 0, got " + format_number(c[i]));
      if (c[i] > max)
        fail(p, "must be at most " + format_number(max) + ", got " + format_number(c[i]));
    }
    return c;
  }

  // 16 numbers, row-major, affine (last row 0 0 0 1) and invertible.
  Mat4 matrix(const Json& j, const std::string& path) const {
    array(j, path, 16);
    Mat4 m;
    for (int i = 0; i < 16; ++i) m.m[i / 4][i % 4] = number(j[i], json_child(path, i));
    if (m.m[3][0] != 0 || m.m[3][1] != 0 || m.m[3][2] != 0 || m.m[3][3] != 1)
      fail(path, "last row must be [0, 0, 0, 1] (affine transforms only)");
    check_invertible(m, path);
    return m;
  }

  // Singular when the rows of the linear part are (nearly) dependent: |det| is small relative to
  // the product of the row lengths (Hadamard's bound, equal to |det| for orthogonal rows).
  void check_invertible(const Mat4& m, const std::string& path) const {
    double bound = 1;
    for (int r = 0; r < 3; ++r)
      bound *= std::sqrt(double(m.m[r][0]) * m.m[r][0] + double(m.m[r][1]) * m.m[r][1] +
                         double(m.m[r][2]) * m.m[r][2]);
    double det = m.det3();
    if (!m.is_finite() || !std::isfinite(det)) fail(path, "matrix is not finite");
    if (bound == 0 || std::fabs(det) <= 1e-6 * bound)
      fail(path, "matrix is singular (determinant " + format_number(det) + ")");
  }

 private:
  std::string file_;
};

}  // namespace rf
