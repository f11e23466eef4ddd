// An upgrade: a state directory the build before the task ledger wrote (tests/data/upgrade/,
// made by tests/upgrade/make_fixture.sh with that build's binary: its job store holds job specs
// as protobuf wire bytes, its checkpoints that build's buffers) resumes under this build. Its
// completed, cancelled and failed jobs stay so and serve what they merged; its running job
// finishes on this build's workers; every frame equals the local render of the same job.
#include <gtest/gtest.h>

#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "engine/build_info.h"
#include "tests/support/farm.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

TEST(Upgrade, AStateDirectoryOfTheBuildBeforeResumes) {
  test::Farm farm("upgrade");
  farm.stop_coordinator();
  const std::string state = farm.dir() + "/state";
  test::CommandResult r =
      test::run_command("rm -rf " + state + " && tar -C " + farm.dir() + " -xzf " +
                        test::source_dir() + "/tests/data/upgrade/state.tar.gz");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  std::map<std::string, std::string> args;  // job -> its render arguments
  std::ifstream in(state + "/jobs.txt");
  for (std::string line; std::getline(in, line);) {
    size_t space = line.find(' ');
    args[line.substr(0, space)] = "scenes/cornell-box/scene.json " + line.substr(space + 1);
  }
  ASSERT_EQ(args.size(), 4u);
  farm.start_coordinator(farm.port());

  EXPECT_EQ(farm.status("j000001")["state"], "completed");
  EXPECT_EQ(farm.status("j000002")["state"], "cancelled");
  EXPECT_EQ(farm.status("j000003")["state"], "failed");
  EXPECT_EQ(farm.status("j000004")["state"], "running");
  farm.worker();
  EXPECT_EQ(farm.client("watch j000004").exit_code, 0);

  // The fixture's merged passes were rendered on an AVX2 machine ("x86_64-avx2"), and results are
  // deterministic per build and CPU kind: on that kind they equal this build's local render; on
  // another (AVX-512 hits differ in the last bits), the reference is the fixture's checkpoint as
  // it was written, merged to an image by this build (the job it served is the one it stored).
  const bool fixture_kind = cpu_isa() == "x86_64-avx2";
  const std::string fixture = farm.dir() + "/fixture";
  r = test::run_command("mkdir -p " + fixture + " && tar -C " + fixture + " -xzf " +
                        test::source_dir() + "/tests/data/upgrade/state.tar.gz");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  auto stored = [&](const std::string& job) {
    const std::string out = farm.dir() + "/stored-" + job + ".exr";
    test::CommandResult m =
        test::run_command(test::rayfarm_binary() + " merge " + fixture + "/state/jobs/" + job +
                          "/frame-0/prefix.rfb -o " + out);
    EXPECT_EQ(m.exit_code, 0) << m.output;
    return out;
  };
  for (const std::string job : {"j000001", "j000004"}) {
    ASSERT_EQ(farm.client("fetch " + job + " -o " + farm.dir() + "/out-" + job).exit_code, 0);
    // j000004 merged nothing before: this build renders it all.
    test::expect_same_image(farm.fetched(job, 0), fixture_kind || job == "j000004"
                                                      ? farm.local(args[job], 0)
                                                      : stored(job));
  }
  // The cancelled job serves its first pass: the local render of that pass.
  ASSERT_EQ(farm.client("fetch j000002 -o " + farm.dir() + "/out-j000002").exit_code, 0);
  const std::string partial = farm.dir() + "/pass0.rfb", local = farm.dir() + "/pass0.exr";
  r = test::run_command("cd " + test::source_dir() + " && " + test::rayfarm_binary() + " render " +
                        args["j000002"] + " -q --pass-range 0-0 --partial " + partial + " && " +
                        test::rayfarm_binary() + " merge " + partial + " -o " + local);
  ASSERT_EQ(r.exit_code, 0) << r.output;
  test::expect_same_image(farm.fetched("j000002", 0), fixture_kind ? local : stored("j000002"));
  // The failed job merged nothing: fetch says so.
  test::CommandResult failed = farm.client("fetch j000003 -o " + farm.dir() + "/out-j000003");
  EXPECT_EQ(failed.exit_code, 1) << failed.output;
  // New jobs get ids after the old ones.
  EXPECT_EQ(farm.submit(args["j000001"]), "j000005");
}

}  // namespace
}  // namespace rf
