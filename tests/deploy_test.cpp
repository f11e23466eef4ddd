// The deployment recipes in deploy/ run for real where they can without a cluster: the Slurm
// coordinator-less mode, with plain processes standing in for the array tasks (Slurm sets
// SLURM_ARRAY_TASK_ID and SLURM_ARRAY_TASK_COUNT; here the test does), then the afterok merge.
// The merged frame must equal one local render of all the passes (DESIGN.md's determinism
// contract). (deploy/check.sh checks the manifests and scripts statically.)
#include <gtest/gtest.h>

#include <chrono>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <string>
#include <thread>

#include "engine/buffer_file.h"
#include "engine/digest.h"
#include "tests/support/farm.h"
#include "tests/support/process.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

const std::string kScene = "scenes/cornell-box/scene.json";
const std::string kFlags = " --res 32x32 --spp 40 --passes 10 --max-depth 6";

// One script of deploy/slurm run as Slurm would run it, with these environment assignments.
test::CommandResult sbatch_script(const std::string& env, const std::string& script,
                                  const std::string& args) {
  return test::run_command("cd " + test::source_dir() +
                           " && env RAYFARM=" + test::rayfarm_binary() + " " + env +
                           " bash deploy/slurm/" + script + " " + args);
}

// 12 array tasks for 10 passes (two tasks get none), then the merge: the frame equals the local
// render, and its buffer holds every pass once. A leftover part of another render in the parts
// directory makes the merge fail, naming it, instead of blending it in.
TEST(DeploySlurm, CoordinatorLessArrayTasksMergeToOneLocalRender) {
  std::string dir = test::make_temp_dir("deploy-slurm");
  const int tasks = 12;
  for (int t = 0; t < tasks; ++t) {
    test::CommandResult r = sbatch_script(
        "SLURM_ARRAY_TASK_ID=" + std::to_string(t) +
            " SLURM_ARRAY_TASK_COUNT=" + std::to_string(tasks) + " SLURM_CPUS_PER_TASK=1",
        "render-array.sbatch", kScene + " " + dir + "/out" + kFlags);
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  size_t parts = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir + "/out/parts")) {
    EXPECT_EQ(e.path().extension(), ".rfb") << e.path();
    ++parts;
  }
  EXPECT_EQ(parts, 10u) << "one part per task with passes";
  test::CommandResult m = sbatch_script("", "merge.sbatch", dir + "/out " + dir + "/out/frame.exr");
  ASSERT_EQ(m.exit_code, 0) << m.output;
  test::CommandResult local =
      test::run_command("cd " + test::source_dir() + " && " + test::rayfarm_binary() + " render " +
                        kScene + kFlags + " -q -o " + dir + "/local.exr");
  ASSERT_EQ(local.exit_code, 0) << local.output;
  test::expect_same_image(dir + "/out/frame.exr", dir + "/local.exr");
  SampleBuffer merged = decode_buffer(read_file_bytes(dir + "/out/frame.rfb"), "frame.rfb");
  EXPECT_EQ(merged.header.passes.count(), 10u);
  for (uint64_t c : merged.count) ASSERT_EQ(c, 40u) << "every pixel has every pass's samples once";

  // The script sets the pass range and the output itself, and needs the passes to split.
  test::CommandResult own =
      sbatch_script("SLURM_ARRAY_TASK_ID=0 SLURM_ARRAY_TASK_COUNT=2", "render-array.sbatch",
                    kScene + " " + dir + "/x" + kFlags + " --pass-range 0-1");
  EXPECT_EQ(own.exit_code, 2) << own.output;
  test::CommandResult no_passes =
      sbatch_script("SLURM_ARRAY_TASK_ID=0 SLURM_ARRAY_TASK_COUNT=2", "render-array.sbatch",
                    kScene + " " + dir + "/x --res 32x32 --spp 40");
  EXPECT_EQ(no_passes.exit_code, 2) << no_passes.output;
  EXPECT_NE(no_passes.output.find("--passes"), std::string::npos) << no_passes.output;

  // A part of another render (another seed) left in the directory: refused, not merged.
  test::CommandResult stray =
      sbatch_script("SLURM_ARRAY_TASK_ID=0 SLURM_ARRAY_TASK_COUNT=1", "render-array.sbatch",
                    kScene + " " + dir + "/stray" + kFlags + " --seed 99");
  ASSERT_EQ(stray.exit_code, 0) << stray.output;
  std::filesystem::copy_file(dir + "/stray/parts/0.rfb", dir + "/out/parts/old.rfb");
  test::CommandResult bad =
      sbatch_script("", "merge.sbatch", dir + "/out " + dir + "/out/frame2.exr");
  EXPECT_NE(bad.exit_code, 0) << bad.output;
  EXPECT_FALSE(std::filesystem::exists(dir + "/out/frame2.exr"));
}

// The container health checks (deploy/healthcheck.sh): a worker's is its heartbeat file, which
// must stay fresh while the worker idles and while its coordinator is away (the check is of the
// worker itself: a coordinator outage must not make every worker unhealthy and restarted).
TEST(DeployHealth, AWorkersHeartbeatStaysFreshWhileItWaitsForItsCoordinator) {
  test::Farm farm("deploy-heartbeat", /*lease_seconds=*/3);
  std::string beat = farm.dir() + "/worker.heartbeat";
  test::Process& worker = farm.worker({"--heartbeat-file", beat});
  auto mtime = [&] {
    std::error_code ec;
    auto t = std::filesystem::last_write_time(beat, ec);
    return ec ? std::filesystem::file_time_type::min() : t;
  };
  auto fresh_within = [&](double seconds) {  // a beat newer than now - seconds appears in time
    auto start = std::filesystem::file_time_type::clock::now();
    for (int i = 0; i < int(seconds * 20) + 40; ++i) {
      if (mtime() >= start) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
  };
  ASSERT_TRUE(fresh_within(5)) << worker.log();
  ASSERT_TRUE(fresh_within(5)) << "idle, it beats at each poll: " << worker.log();
  farm.stop_coordinator();
  std::this_thread::sleep_for(std::chrono::seconds(2));
  // Waiting for the coordinator with backoff (at most 15 s between tries).
  EXPECT_TRUE(fresh_within(20)) << worker.log();
  EXPECT_TRUE(worker.running()) << worker.log();
  std::string text;
  std::ifstream(beat) >> text;
  EXPECT_NEAR(std::stod(text), double(std::time(nullptr)), 30) << "it holds its Unix time";
  farm.start_coordinator(farm.port());
}

// The image's HEALTHCHECK script (deploy/healthcheck.sh) run for real: a coordinator and a
// worker each as PID 1 of their own PID namespace (as in a container; unshare), the script
// entered into that namespace (nsenter). The coordinator's check asks its health-only port and
// fails on a port nobody serves; the worker's reads its heartbeat and fails when it is too old.
TEST(DeployHealth, TheImagesHealthCheckAsksTheCoordinatorAndTheWorkerThemselves) {
  if (test::run_command("unshare --pid --fork --mount-proc true").exit_code != 0)
    GTEST_SKIP() << "this machine forbids PID namespaces (unshare needs root or CAP_SYS_ADMIN)";
  std::string dir = test::make_temp_dir("deploy-healthcheck");
  std::string bin = std::filesystem::path(test::rayfarm_binary()).parent_path().string();
  auto as_pid1 = [&](const std::string& name, std::vector<std::string> args) {
    std::vector<std::string> argv = {"/usr/bin/unshare", "--pid",        "--fork",
                                     "--mount-proc",     "--kill-child", test::rayfarm_binary()};
    argv.insert(argv.end(), args.begin(), args.end());
    return std::make_unique<test::Process>(argv, dir + "/" + name + ".log");
  };
  // The script inside the namespace of `p` (whose child is that namespace's PID 1).
  auto check = [&](const test::Process& p, const std::string& env) {
    test::CommandResult child = test::run_command("pgrep -P " + std::to_string(p.pid()));
    std::string pid = child.output.substr(0, child.output.find('\n'));
    return test::run_command("nsenter --target " + pid + " --pid --mount env PATH=" + bin +
                             ":$PATH " + env + " sh " + test::source_dir() +
                             "/deploy/healthcheck.sh");
  };

  auto coordinator =
      as_pid1("coordinator", {"coordinator", "--listen", "127.0.0.1:0", "--health-listen",
                              "127.0.0.1:0", "--state-dir", dir + "/state"});
  ASSERT_TRUE(coordinator->wait_for_log("(health port", 60)) << coordinator->log();
  std::smatch m;
  std::string log = coordinator->log();
  ASSERT_TRUE(std::regex_search(log, m, std::regex("\\(port ([0-9]+)\\)"))) << log;
  std::string port = m[1];
  ASSERT_TRUE(std::regex_search(log, m, std::regex("health port ([0-9]+)"))) << log;
  std::string health = m[1];
  test::CommandResult ok = check(*coordinator, "RAYFARM_HEALTH_ADDR=127.0.0.1:" + health);
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_NE(ok.output.find("SERVING"), std::string::npos) << ok.output;
  test::CommandResult nobody = check(*coordinator, "RAYFARM_HEALTH_ADDR=127.0.0.1:1");
  EXPECT_NE(nobody.exit_code, 0) << nobody.output;

  std::string beat = dir + "/worker.heartbeat";
  auto worker = as_pid1("worker", {"worker", "--coordinator", "127.0.0.1:" + port,
                                   "--heartbeat-file", beat, "--cache-dir", dir + "/cache"});
  ASSERT_TRUE(worker->wait_for_log("connected", 60)) << worker->log();
  test::CommandResult fresh = check(*worker, "RAYFARM_HEARTBEAT_FILE=" + beat);
  EXPECT_EQ(fresh.exit_code, 0) << fresh.output;
  EXPECT_NE(fresh.output.find("heartbeat"), std::string::npos) << fresh.output;
  test::CommandResult old =
      check(*worker, "RAYFARM_HEARTBEAT_FILE=" + beat + " RAYFARM_HEARTBEAT_MAX_AGE=0");
  EXPECT_EQ(old.exit_code, 1) << old.output;
  test::CommandResult none = check(*worker, "RAYFARM_HEARTBEAT_FILE=" + dir + "/absent");
  EXPECT_EQ(none.exit_code, 1) << none.output;
}

}  // namespace
}  // namespace rf
