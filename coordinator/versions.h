// A job's scene versions (`requeue`, DESIGN.md "Job operations"): a requeue may give frames a new
// scene bundle, and renders them again from scratch. Version 0 is the submitted spec's bundle;
// each requeue with a new scene adds the next. Every requeue of a frame starts a new run of it:
// run R's checkpoint lives in its own folder (frame-N, then frame-N.rR), so the store's record of
// the versions is the requeue's commit point and a crash on either side of it leaves one
// consistent frame. Stored as text in the job's row and in its folder (versions.json).
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "engine/frame.h"
#include "farm/blob_store.h"

namespace rf {

struct SceneVersion {
  std::string scene_path;          // the scene file in the bundle (a frame pattern)
  std::vector<BundleEntry> files;  // the bundle
  std::string frames;              // the frames it was given (range syntax): its scene check's
  bool operator==(const SceneVersion&) const = default;
};

struct FrameRun {
  uint32_t version = 0;  // the scene version it renders
  uint32_t run = 0;      // how many times it was requeued
  bool operator==(const FrameRun&) const = default;
};

struct JobVersions {
  std::vector<SceneVersion> added;         // versions 1, 2, ... (0 is the job's spec)
  std::map<FrameNumber, FrameRun> frames;  // the frames requeued at least once
  std::string request_id;                  // the latest requeue's: a repeat of it changes nothing
  bool empty() const { return added.empty() && frames.empty() && request_id.empty(); }
  bool operator==(const JobVersions&) const = default;
};

std::string encode_versions(const JobVersions& v);  // "" for none
// Throws std::runtime_error naming what is wrong (a version a frame names that does not exist,
// a bad digest or path).
JobVersions decode_versions(const std::string& text);

// A frame's checkpoint folder in its job's folder, and a scene version's bundle folder.
std::string frame_folder(FrameNumber frame, uint32_t run);  // frame-N, frame-N.rR
std::string bundle_folder(uint32_t version);                // bundle, bundle-vK

}  // namespace rf
