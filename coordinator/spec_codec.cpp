#include "coordinator/spec_codec.h"

#include <cstring>
#include <nlohmann/json.hpp>

namespace rf {

namespace {

using Json = nlohmann::json;

constexpr int kVersion = 1;  // "v" in the JSON: a later layout says so

Json overrides_json(const SceneOverrides& o) {
  Json j = Json::object();
  if (o.spp) j["spp"] = *o.spp;
  if (o.passes) j["passes"] = *o.passes;
  if (o.integrator) j["integrator"] = *o.integrator;
  if (o.seed) j["seed"] = *o.seed;
  if (o.width) j["width"] = *o.width;
  if (o.height) j["height"] = *o.height;
  if (o.max_depth) j["max_depth"] = *o.max_depth;
  if (o.filter) j["filter"] = *o.filter;
  if (o.noise_target) j["noise_target"] = *o.noise_target;
  if (o.sampler) j["sampler"] = *o.sampler;
  if (o.aovs) j["aovs"] = *o.aovs;
  if (o.light_selection) j["light_selection"] = *o.light_selection;
  if (o.shutter) j["shutter"] = *o.shutter;
  return j;
}

template <class T>
void read_optional(const Json& j, const char* key, std::optional<T>& out) {
  if (j.contains(key)) out = j.at(key).get<T>();
}

SceneOverrides overrides_from(const Json& j) {
  SceneOverrides o;
  read_optional(j, "spp", o.spp);
  read_optional(j, "passes", o.passes);
  read_optional(j, "integrator", o.integrator);
  read_optional(j, "seed", o.seed);
  read_optional(j, "width", o.width);
  read_optional(j, "height", o.height);
  read_optional(j, "max_depth", o.max_depth);
  read_optional(j, "filter", o.filter);
  read_optional(j, "noise_target", o.noise_target);
  read_optional(j, "sampler", o.sampler);
  read_optional(j, "aovs", o.aovs);
  read_optional(j, "light_selection", o.light_selection);
  read_optional(j, "shutter", o.shutter);
  return o;
}

std::optional<JobSpec> from_json(const std::string& text) {
  Json j = Json::parse(text, nullptr, false);
  if (j.is_discarded() || !j.is_object() || j.value("v", 0) != kVersion) return std::nullopt;
  try {
    JobSpec s;
    s.name = j.at("name").get<std::string>();
    s.scene_path = j.at("scene_path").get<std::string>();
    for (const Json& f : j.at("files"))
      s.files.push_back({f.at(0).get<std::string>(), f.at(1).get<std::string>()});
    s.frames = j.at("frames").get<std::string>();
    s.overrides = overrides_from(j.at("overrides"));
    s.priority = j.at("priority").get<int>();
    s.tile_size = j.at("tile_size").get<uint32_t>();
    s.build_id = j.at("build_id").get<std::string>();
    s.request_id = j.at("request_id").get<std::string>();
    if (j.contains("required_tags"))
      s.required_tags = j.at("required_tags").get<std::vector<std::string>>();
    return s;
  } catch (const Json::exception&) {
    return std::nullopt;
  }
}

// ---- Earlier builds' protobuf wire bytes (rayfarm.v1.JobSpec and its messages): varints,
// length-delimited fields and a fixed64 double; unknown fields skipped by their wire type.

class Wire {
 public:
  explicit Wire(std::string_view b) : b_(b) {}
  bool done() const { return at_ >= b_.size(); }
  bool varint(uint64_t& v) {
    v = 0;
    for (int shift = 0; shift < 64 && at_ < b_.size(); shift += 7) {
      uint8_t c = uint8_t(b_[at_++]);
      v |= uint64_t(c & 0x7f) << shift;
      if (!(c & 0x80)) return true;
    }
    return false;
  }
  bool bytes(std::string_view& out) {
    uint64_t n = 0;
    if (!varint(n) || n > b_.size() - at_) return false;
    out = b_.substr(at_, size_t(n));
    at_ += size_t(n);
    return true;
  }
  bool fixed64(uint64_t& v) {
    if (b_.size() - at_ < 8) return false;
    v = 0;
    for (int i = 7; i >= 0; --i) v = (v << 8) | uint8_t(b_[at_ + size_t(i)]);
    at_ += 8;
    return true;
  }
  bool skip(int wire_type) {
    uint64_t v = 0;
    std::string_view s;
    switch (wire_type) {
      case 0:
        return varint(v);
      case 1:
        return fixed64(v);
      case 2:
        return bytes(s);
      case 5:
        if (b_.size() - at_ < 4) return false;
        at_ += 4;
        return true;
      default:  // groups: never in these messages
        return false;
    }
  }

 private:
  std::string_view b_;
  size_t at_ = 0;
};

// Calls field(number, wire_type, wire) for each field; false on malformed bytes.
template <class Field>
bool for_fields(std::string_view bytes, Field&& field) {
  Wire w(bytes);
  while (!w.done()) {
    uint64_t key = 0;
    if (!w.varint(key) || key >> 3 == 0) return false;
    if (!field(uint32_t(key >> 3), int(key & 7), w)) return false;
  }
  return true;
}

bool legacy_string(Wire& w, int type, std::string& out) {
  std::string_view s;
  if (type != 2 || !w.bytes(s)) return false;
  out.assign(s);
  return true;
}

template <class T>
bool legacy_varint(Wire& w, int type, T& out) {
  uint64_t v = 0;
  if (type != 0 || !w.varint(v)) return false;
  out = T(v);  // int32 fields: the low 32 bits of a sign-extended varint
  return true;
}

template <class T>
bool legacy_optional_varint(Wire& w, int type, std::optional<T>& out) {
  T v{};
  if (!legacy_varint(w, type, v)) return false;
  out = v;
  return true;
}

bool legacy_optional_string(Wire& w, int type, std::optional<std::string>& out) {
  std::string v;
  if (!legacy_string(w, type, v)) return false;
  out = std::move(v);
  return true;
}

bool legacy_overrides(std::string_view bytes, SceneOverrides& o) {
  return for_fields(bytes, [&](uint32_t n, int type, Wire& w) {
    switch (n) {
      case 1:
        return legacy_optional_varint(w, type, o.spp);
      case 2:
        return legacy_optional_varint(w, type, o.passes);
      case 3:
        return legacy_optional_string(w, type, o.integrator);
      case 4:
        return legacy_optional_varint(w, type, o.seed);
      case 5: {
        uint32_t v = 0;
        if (!legacy_varint(w, type, v)) return false;
        o.width = int(v);
        return true;
      }
      case 6: {
        uint32_t v = 0;
        if (!legacy_varint(w, type, v)) return false;
        o.height = int(v);
        return true;
      }
      case 7: {
        int32_t v = 0;
        if (!legacy_varint(w, type, v)) return false;
        o.max_depth = int(v);
        return true;
      }
      case 8:
        return legacy_optional_string(w, type, o.filter);
      case 9: {
        uint64_t bits = 0;
        if (type != 1 || !w.fixed64(bits)) return false;
        double d;
        std::memcpy(&d, &bits, sizeof d);
        o.noise_target = d;
        return true;
      }
      case 10:
        return legacy_optional_string(w, type, o.sampler);
      case 11:
        return legacy_optional_string(w, type, o.aovs);
      case 12:
        return legacy_optional_string(w, type, o.light_selection);
      default:
        return w.skip(type);
    }
  });
}

std::optional<JobSpec> from_legacy(const std::string& bytes) {
  JobSpec s;
  bool ok = for_fields(bytes, [&](uint32_t n, int type, Wire& w) {
    switch (n) {
      case 1:
        return legacy_string(w, type, s.name);
      case 2:
        return legacy_string(w, type, s.scene_path);
      case 3: {
        std::string_view file;
        if (type != 2 || !w.bytes(file)) return false;
        BundleEntry e;
        bool fine = for_fields(file, [&](uint32_t m, int t, Wire& fw) {
          if (m == 1) return legacy_string(fw, t, e.path);
          if (m == 2) return legacy_string(fw, t, e.sha256);
          return fw.skip(t);
        });
        s.files.push_back(std::move(e));
        return fine;
      }
      case 4:
        return legacy_string(w, type, s.frames);
      case 5: {
        std::string_view o;
        return type == 2 && w.bytes(o) && legacy_overrides(o, s.overrides);
      }
      case 6: {
        int32_t v = 0;
        if (!legacy_varint(w, type, v)) return false;
        s.priority = v;
        return true;
      }
      case 7:
        return legacy_varint(w, type, s.tile_size);
      case 8:
        return legacy_string(w, type, s.build_id);
      case 9:
        return legacy_string(w, type, s.request_id);
      default:
        return w.skip(type);
    }
  });
  if (!ok) return std::nullopt;
  return s;
}

}  // namespace

std::string encode_spec(const JobSpec& s) {
  Json files = Json::array();
  for (const BundleEntry& f : s.files) files.push_back({f.path, f.sha256});
  Json j = {{"v", kVersion},
            {"name", s.name},
            {"scene_path", s.scene_path},
            {"files", files},
            {"frames", s.frames},
            {"overrides", overrides_json(s.overrides)},
            {"priority", s.priority},
            {"tile_size", s.tile_size},
            {"build_id", s.build_id},
            {"request_id", s.request_id}};
  if (!s.required_tags.empty())
    j["required_tags"] = s.required_tags;  // specs without it encode as before
  // Submitted text is checked to be UTF-8 (text_problem); replace guards the rest.
  return j.dump(-1, ' ', false, Json::error_handler_t::replace);
}

std::optional<JobSpec> decode_spec(const std::string& bytes) {
  if (!bytes.empty() && bytes.front() == '{') return from_json(bytes);
  return from_legacy(bytes);
}

}  // namespace rf
