#include "coordinator/versions.h"

#include <nlohmann/json.hpp>
#include <stdexcept>

namespace rf {

std::string encode_versions(const JobVersions& v) {
  if (v.empty()) return "";
  nlohmann::json added = nlohmann::json::array();
  for (const SceneVersion& s : v.added) {
    nlohmann::json files = nlohmann::json::array();
    for (const BundleEntry& f : s.files) files.push_back({f.path, f.sha256});
    added.push_back({{"scene_path", s.scene_path}, {"frames", s.frames}, {"files", files}});
  }
  nlohmann::json frames = nlohmann::json::array();
  for (const auto& [n, r] : v.frames) frames.push_back({n, r.version, r.run});
  return nlohmann::json{{"versions", added}, {"frames", frames}, {"request_id", v.request_id}}
      .dump();
}

JobVersions decode_versions(const std::string& text) {
  JobVersions v;
  if (text.empty()) return v;
  try {
    nlohmann::json j = nlohmann::json::parse(text);
    for (const nlohmann::json& s : j.at("versions")) {
      SceneVersion sv{s.at("scene_path").get<std::string>(), {}, s.at("frames").get<std::string>()};
      for (const nlohmann::json& f : s.at("files")) {
        BundleEntry e{f.at(0).get<std::string>(), f.at(1).get<std::string>()};
        if (!is_sha256_hex(e.sha256)) throw std::runtime_error("'" + e.sha256 + "' is no SHA-256");
        sv.files.push_back(std::move(e));
      }
      v.added.push_back(std::move(sv));
    }
    for (const nlohmann::json& f : j.at("frames")) {
      FrameRun r{f.at(1).get<uint32_t>(), f.at(2).get<uint32_t>()};
      if (r.version > v.added.size())
        throw std::runtime_error("a frame names scene version " + std::to_string(r.version) +
                                 " of " + std::to_string(v.added.size()));
      v.frames[f.at(0).get<FrameNumber>()] = r;
    }
    v.request_id = j.value("request_id", "");
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(std::string("scene versions do not parse: ") + e.what());
  }
  return v;
}

std::string frame_folder(FrameNumber frame, uint32_t run) {
  std::string name = "frame-" + std::to_string(frame);
  return run == 0 ? name : name + ".r" + std::to_string(run);
}

std::string bundle_folder(uint32_t version) {
  return version == 0 ? "bundle" : "bundle-v" + std::to_string(version);
}

}  // namespace rf
