// A glTF file a test builds from arrays (the glTF importer's tests): float and unsigned-short
// accessors in one embedded buffer, meshes, nodes and one animation's channels.
#pragma once

#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "tests/support/test_support.h"

namespace rf::test {

struct GltfFile {
  nlohmann::json j;
  std::string bin;
  GltfFile() {
    j = {{"asset", {{"version", "2.0"}}},
         {"bufferViews", nlohmann::json::array()},
         {"accessors", nlohmann::json::array()},
         {"meshes", nlohmann::json::array()},
         {"nodes", nlohmann::json::array()},
         {"animations",
          {{{"channels", nlohmann::json::array()}, {"samplers", nlohmann::json::array()}}}}};
  }
  // An accessor of `count` elements of `type` over `bytes` bytes at v, in a view of its own.
  size_t add(const void* v, size_t bytes, size_t count, const char* type, int component) {
    while (bin.size() % 4) bin.push_back('\0');
    j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", bytes}});
    bin.append(static_cast<const char*>(v), bytes);
    j["accessors"].push_back({{"bufferView", j["bufferViews"].size() - 1},
                              {"componentType", component},
                              {"count", count},
                              {"type", type}});
    return j["accessors"].size() - 1;
  }
  size_t floats(const std::vector<float>& v, const char* type) {
    const std::string t = type;
    const size_t comps = t == "SCALAR" ? 1 : t == "VEC3" ? 3 : t == "VEC4" ? 4 : 16;
    return add(v.data(), v.size() * 4, v.size() / comps, type, 5126);
  }
  size_t ushorts(const std::vector<uint16_t>& v) {  // VEC4 joint indices
    return add(v.data(), v.size() * 2, v.size() / 4, "VEC4", 5123);
  }
  size_t node(nlohmann::json n) {
    j["nodes"].push_back(n);
    return j["nodes"].size() - 1;
  }
  // A channel of the animation on `node`'s `path`; its values' type follows the path (rotation
  // VEC4, weights SCALAR, translation and scale VEC3).
  void channel(size_t node, const char* path, const char* interp, std::vector<float> times,
               std::vector<float> values) {
    const std::string p = path;
    const char* type = p == "rotation" ? "VEC4" : p == "weights" ? "SCALAR" : "VEC3";
    const size_t in = floats(times, "SCALAR");
    const size_t out = floats(values, type);
    nlohmann::json& a = j["animations"][0];
    a["samplers"].push_back({{"input", in}, {"output", out}, {"interpolation", interp}});
    a["channels"].push_back(
        {{"sampler", a["samplers"].size() - 1}, {"target", {{"node", node}, {"path", path}}}});
  }
  std::string text() {
    j["buffers"] = {{{"byteLength", bin.size()},
                     {"uri", "data:application/octet-stream;base64," + base64(bin)}}};
    return j.dump();
  }
};

}  // namespace rf::test
