// Checking a submitted job's scenes without parsing them in the coordinator (DESIGN.md "The
// coordinator", docs/security.md "Scene import"). A scene bundle is a client's bytes: an importer
// bug or a bomb (JSON nested 100,000 deep, includes that fan out to 10^9 parses) must cost the
// client its submit, never the farm its coordinator. So the coordinator runs its own binary as a
// child, `rayfarm check-scenes`, with limits on its memory (RLIMIT_AS), CPU time (RLIMIT_CPU) and
// wall time, on the materialised bundle; the child answers with a SceneSummary per scene file
// (engine/scene_summary.h), and the coordinator plans the job from those.
//
// The protocol, both ends in scene_check.cpp: the child's stdin is the job's encoded spec
// (spec_codec.h); its working directory is the bundle, so messages name bundle paths only; its
// stdout is JSON lines, one {"scene": i, "summary": {...}} per scene file in job_scene_paths()
// order, then {"ok": true} or {"error": MESSAGE, "code": "invalid_argument" |
// "resource_exhausted"}. A child that dies, or says nothing more, is a refusal naming the scene
// file it was importing and the budget it most likely ran out of.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "engine/import_limits.h"
#include "engine/scene_summary.h"
#include "farm/job.h"

namespace rf {

// The budget of one job's scene check (`rayfarm coordinator --limit parse_NAME=VALUE`, and the
// importer's own bounds as import_NAME).
struct SceneCheckLimits {
  uint64_t memory_mb = 4096;    // the child's address space (RLIMIT_AS)
  uint64_t cpu_seconds = 120;   // its CPU time (RLIMIT_CPU)
  uint64_t wall_seconds = 300;  // then it is killed
  uint64_t children = 2;        // checks at once; more submits wait, up to wall_seconds
  ImportLimits import;
};

// The distinct scene files of a job's frames, in frame order (frame 0 alone without a frame
// range). Throws FrameRangeError for a bad range.
std::vector<std::string> job_scene_paths(const JobSpec& spec);

// Parses every scene of the job (job_scene_paths, relative to bundle_dir) with the job's
// overrides, checks that its integrator can render it, and summarises each. Throws
// CoordinatorError: InvalidArgument for a bad scene, ResourceExhausted over a budget.
using SceneChecker =
    std::function<std::vector<SceneSummary>(const std::string& bundle_dir, const JobSpec& spec)>;

// In `binary check-scenes` children under `limits`, at most limits.children at once. The
// coordinator's server uses this one.
SceneChecker child_scene_checker(std::string binary, SceneCheckLimits limits);
// In this process: for tests and fuzzers of the core that need no processes. A bomb hits the
// caller.
SceneChecker in_process_scene_checker(ImportLimits limits = {});

// The child's side (`rayfarm check-scenes --bundle DIR ...`): applies its own limits before
// reading a byte, answers on stdout as above, and returns the exit status.
int run_scene_check_child(const std::string& bundle_dir, const SceneCheckLimits& limits);

}  // namespace rf
