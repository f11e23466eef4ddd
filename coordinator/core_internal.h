// What the coordinator's files share (core.cpp, intake.cpp, recovery.cpp, workers.cpp,
// results.cpp: one Coordinator, split by concept): a job's and a frame's records, and the helpers
// every refusal and log line uses. Not for use outside coordinator/.
#pragma once

#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "coordinator/checkpoint.h"
#include "coordinator/core.h"
#include "coordinator/versions.h"
#include "engine/frame.h"
#include "engine/frame_accumulator.h"

namespace rf {

namespace core_detail {

// A client-supplied string as it may appear in a message or a log line: at most 64 bytes.
inline std::string clip(const std::string& s) {
  if (s.size() <= 64) return printable(s);
  return printable(s.substr(0, 48)) + "...(" + std::to_string(s.size()) + " bytes)";
}

[[noreturn]] inline void refuse(ErrorCode code, const std::string& message) {
  throw CoordinatorError(code, message);
}

// How an ended job ended, for messages: "completed", "failed", "been cancelled".
inline const char* ended_verb(JobState s) {
  return s == JobState::Completed ? "completed"
         : s == JobState::Failed  ? "failed"
                                  : "been cancelled";
}

inline double unix_now() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

}  // namespace core_detail

// One frame of a job: its merge state, durable checkpoint and progress figures.
struct FrameRecord {
  FrameNumber number = 0;
  std::string scene_path;                 // in the bundle
  BufferHeader base;                      // what every task buffer of this frame must match
  std::mutex m;                           // serializes merges and checkpoints of this frame
  std::unique_ptr<FrameAccumulator> acc;  // created on the first result; dropped when done
  std::unique_ptr<FrameCheckpoint> checkpoint;
  // Under the coordinator's mutex: the figures of the last merge (the ETA is taken when
  // reported), and when the frame's first task was leased in this run.
  FrameProgress progress;
  double first_lease_at = -1;
  bool leases_dropped = false;  // its lease rows were deleted when it was done
  bool held = false;            // unfinished and left out of a `retry --frames`: not queued
  uint32_t version = 0;         // the scene version it renders (versions.h)
  uint32_t run = 0;             // requeued this many times: its checkpoint's folder
  // Under the coordinator's mutex: the prefix's growth in this run (frame_history), every
  // `history_stride`-th prefix length kept, so at most kHistoryPoints.
  std::vector<ProgressPoint> history;
  uint32_t history_stride = 1;
  // Under the frame's lock: tasks (pass, tile) whose results are being made durable, their
  // frame lock let go meanwhile; another result of one of them is not needed.
  std::set<std::pair<uint32_t, uint32_t>> storing;
};

struct JobRecord {
  std::string id;
  uint64_t seq = 0;
  JobSpec spec;
  JobState state = JobState::Queued;
  std::string error;
  int64_t submitted_unix = 0;
  double core_seconds = 0;
  // Results merged by this run of the coordinator and their worker CPU seconds: how long its
  // tasks take, which decides whether a lease hands out several (Coordinator::lease).
  uint64_t tasks_timed = 0;
  double timed_core_seconds = 0;
  std::string tenant;
  std::string build_id;        // results of this build only; empty: the first merged result's
  std::string cpu_kind;        // and of this CPU kind only (BufferHeader::isa), the same way
  bool pin_pending = false;    // build_id / cpu_kind taken by a result, not yet stored
  std::string bundle_problem;  // restored without its bundle (its blobs are gone): why
  bool paused = false;         // no new leases (`pause`); leases in flight finish and merge
  int priority = 0;            // the spec's, or what `priority JOB N` set since
  bool deleted = false;        // `delete`: gone from the coordinator; a merge in flight stops
  int64_t ended_unix = 0;      // when it last ended (retention counts --keep-finished from it)
  uint64_t endings = 0;        // times it entered an ended state (the ledger counts them)
  uint64_t released_at = 0;    // `endings` when retention last dropped its accumulators
  JobVersions versions;        // scene versions and requeued frames (`requeue`)
  TileGrid tiles;  // how its frames split into tasks (three numbers, whatever the tile count)
  bool splats = false;
  uint32_t passes = 0;
  uint64_t spp_per_pass = 0;
  double noise_target = 0;
  std::vector<std::unique_ptr<FrameRecord>> frames;
  std::map<FrameNumber, FrameRecord*> by_number;

  // The bundle of scene version v (0: the spec's).
  const std::vector<BundleEntry>& files_of(uint32_t v) const {
    return v == 0 ? spec.files : versions.added.at(v - 1).files;
  }
  ProgressiveOptions merge_options() const { return {0, passes, noise_target}; }
  std::vector<FrameNumber> frame_numbers() const {
    std::vector<FrameNumber> out;
    for (const auto& f : frames) out.push_back(f->number);
    return out;
  }
};

namespace core_detail {

// The job's frames a client's range names (InvalidArgument for a bad range or a frame the job
// lacks); every frame of the job for an empty range.
std::set<FrameNumber> named_frames(const JobRecord& job, const std::string& frames);

}  // namespace core_detail

}  // namespace rf
