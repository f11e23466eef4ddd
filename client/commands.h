// The farm's client commands (`rayfarm submit | status | watch | fetch | cancel | pause | resume |
// priority | workers | health`).
#pragma once

#include <optional>
#include <stdexcept>
#include <string>

#include "engine/scene.h"
#include "farm/channel.h"

namespace rf {

// A client-side failure with the process exit status to use (2: bad input, 1: anything else).
struct FarmError : std::runtime_error {
  FarmError(const std::string& what, int exit_status)
      : std::runtime_error(what), exit_status(exit_status) {}
  int exit_status;
};

// $RAYFARM_COORDINATOR, else 127.0.0.1:7070.
std::string default_coordinator();

// A coordinator and how to show ourselves to it (farm/channel.h).
// timeout: the command's overall deadline in seconds (--timeout). Calls answered UNAVAILABLE (the
// coordinator is down, restarting or overloaded) are retried with capped, jittered backoff until
// then; `watch` gives up once it has been disconnected that long.
struct Endpoint {
  std::string address;
  ClientCredentials creds;
  double timeout = 300;
};

struct SubmitArgs {
  std::string scene;   // a file, or a per-frame pattern ("shot.####.json")
  std::string frames;  // Open Job Description range; empty: the scene's frame
  std::string name;
  SceneOverrides overrides;
  int priority = 0;
  int tile_size = 0;     // 0: the coordinator's default
  std::string build_id;  // merge results of this build only (empty: the first result's)
  std::vector<std::string> required_tags;  // worker tags the job needs (farm/tags.h)
};

// How `watch` prints (and `submit --wait`): lines for people (relMSE "n/a" before two passes; a
// frame's line only when more than its ETA changed), JSON lines (`{"event": "frame", ...}` per
// changed frame, `{"event": "end", ...}` last), or Open Job Description progress lines
// (`openjd_progress: 42.0` as passes merge, `openjd_status: ...` as frames and the job end).
struct WatchOutput {
  bool json = false;
  bool openjd = false;
};
// Prints the job id (with json: {"job_id": ...}); with `wait`, then watches it as `watch` does
// and returns its exit status.
// `bundle SCENE`: the files a submit of the scene uploads (the scene file, or each frame's of a
// per-frame pattern over `frames`, and every asset they name, found by the importers), with
// their SHA-256 and size: what another client (clients/python) uploads, by the CLI's rules.
int cmd_bundle(const std::string& scene, const std::string& frames, bool json);
int cmd_submit(const Endpoint& ep, const SubmitArgs& args, bool json = false,
               std::optional<WatchOutput> wait = std::nullopt);
// `status` without a job pages through the list: at most `limit` jobs (0: all) after `after`.
struct StatusPage {
  uint64_t limit = 0;
  std::string after;
};
int cmd_status(const Endpoint& ep, const std::string& job, bool json, const StatusPage& page);
// 0 completed, 1 failed, 3 cancelled.
int cmd_watch(const Endpoint& ep, const std::string& job, const WatchOutput& output = {});
// fetch: every frame with a complete pass, or those of `frames` (a frame range; empty: all), to
// `out`: a directory (JOB.####.exr and .png in it) or an output template ending in .exr
// (shot.####.exr, shot.%04d.exr; a plain name for one frame only).
// With json, one line per frame written on stdout (its files and figures).
struct FetchOutput {
  float exposure = 0;  // of the PNG
  bool png = true;     // a PNG preview beside each EXR
  bool half = false;   // half-float EXR
  bool json = false;
};
int cmd_fetch(const Endpoint& ep, const std::string& job, const std::string& out,
              const std::string& frames, const FetchOutput& output);
int cmd_cancel(const Endpoint& ep, const std::string& job);
// pause (no new leases; leases in flight finish) or resume; idempotent.
int cmd_pause(const Endpoint& ep, const std::string& job, bool pause);
int cmd_priority(const Endpoint& ep, const std::string& job, int priority);
// Failed or cancelled work runs again: the frames in `frames` (a range; empty: all unfinished);
// the others unfinished are held until a later retry. Idempotent.
int cmd_retry(const Endpoint& ep, const std::string& job, const std::string& frames);
// The frames in `frames` (a range; required) render again from scratch, with the job's seed and
// settings; with `scene` (a file or a per-frame pattern), from that scene, uploaded as a submit
// uploads its bundle, as the job's next scene version. An ended job runs again.
int cmd_requeue(const Endpoint& ep, const std::string& job, const std::string& frames,
                const std::string& scene);
// Removes an ended job and its files (a queued or running one only with `force`).
int cmd_delete(const Endpoint& ep, const std::string& job, bool force);
// A job's task attempts (of one frame or one task when given): worker, start and end, outcome
// and reason, and each attempt's log lines; the most recent `limit` (0: 100).
int cmd_logs(const Endpoint& ep, const std::string& job, std::optional<FrameNumber> frame,
             const std::string& task, uint32_t limit, bool json);
// The registered workers: tasks, failures, last contact (--json: machine-readable).
int cmd_workers(const Endpoint& ep, bool json);
int cmd_health(const Endpoint& ep, bool list_services, bool json = false);

}  // namespace rf
