// A job and its tasks in plain types (DESIGN.md "Work units"), shared by the client that submits
// a job, the coordinator that splits and leases it and the worker that renders it. No protobuf
// here: farm/convert.h maps these to the wire.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <tuple>
#include <vector>

#include "engine/frame.h"
#include "engine/scene.h"
#include "farm/blob_store.h"

namespace rf {

struct JobSpec {
  std::string name;
  std::string scene_path;          // the scene file's path in the bundle; may hold '#' digits
  std::vector<BundleEntry> files;  // the bundle: every scene file of the job and its assets
  std::string frames;              // Open Job Description range (frame_range.h); empty: the
                                   // scene's own frame
  SceneOverrides overrides;        // the job's settings over the scene file's
  int priority = 0;                // higher first
  uint32_t tile_size = 0;          // pixels; 0: the coordinator's default
  std::string build_id;            // results only from this build; empty: the first result's
  std::string request_id;          // the submit's idempotency key (client-made; may be empty)
  std::vector<std::string> required_tags;  // worker tags it needs (farm/tags.h), e.g. pool=gpu
  bool operator==(const JobSpec&) const = default;
};

// One task of a job: a pass of one tile (by its index in the frame's split) of one frame.
struct TaskRef {
  std::string job_id;
  FrameNumber frame = 0;
  uint32_t pass = 0, tile = 0;
  bool operator<(const TaskRef& o) const {
    return std::tie(job_id, frame, pass, tile) < std::tie(o.job_id, o.frame, o.pass, o.tile);
  }
  bool operator==(const TaskRef&) const = default;
};

// Why a client's text (a job name, a request id, a bundle path) cannot be stored and printed, or ""
// when it can: control characters (a newline or an ANSI escape would write into an operator's
// terminal or forge a log line) or bytes that are not UTF-8.
std::string text_problem(std::string_view text);
// The text with control characters and bytes that are not UTF-8 written as \xHH: safe to print
// in a terminal or a log line, whatever a client sent.
std::string printable(std::string_view text);

// A task attempt's log lines (`rayfarm logs`): a worker sends at most kAttemptLogLines lines of
// at most kAttemptLogLineBytes; bounded_log cuts what is beyond (keeping the first lines and the
// last, with a line saying how many went between) and makes every line printable.
inline constexpr size_t kAttemptLogLines = 64, kAttemptLogLineBytes = 512;
std::vector<std::string> bounded_log(const std::vector<std::string>& lines);

// "job/frame/pass/tile": a task's id on the wire and in logs.
std::string task_id_text(const TaskRef& task);
// The task an id names; nothing for text that is not such an id.
std::optional<TaskRef> parse_task_id(std::string_view text);

}  // namespace rf
