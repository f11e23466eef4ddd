// The command line end to end: render, partial renders + merge, refusals, repeatability.
#include <gtest/gtest.h>

#include <cstdio>

#include <filesystem>

#include "engine/buffer_file.h"
#include "tests/support/exr.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

using test::Exr;
using test::read_exr;

const std::string kScene = "scenes/cornell-box/scene.json";

std::string cli(const std::string& args) {
  return "cd " + test::source_dir() + " && " + test::rayfarm_binary() + " " + args;
}

TEST(Cli, RenderWritesExrAndPngWithProvenance) {
  std::string dir = test::make_temp_dir("cli-render");
  auto r = test::run_command(cli("render " + kScene + " -o " + dir + "/c.exr --res 32x32 --spp 16 --passes 4 --max-depth 8"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("samples/s"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("relMSE"), std::string::npos);
  EXPECT_TRUE(std::filesystem::exists(dir + "/c.png"));
  Exr e = read_exr(dir + "/c.exr");
  EXPECT_EQ(e.w, 32);
  EXPECT_EQ(e.nch, 7);
  EXPECT_EQ(e.attr("rayfarm:integrator"), "path");
  EXPECT_EQ(e.attr("rayfarm:passes"), "0-3");
  EXPECT_EQ(e.attr("rayfarm:scene_digest").size(), 64u);
}

TEST(Cli, PartialRendersMergeToTheFullRender) {
  std::string dir = test::make_temp_dir("cli-merge");
  std::string common = " --res 24x24 --spp 16 --passes 8 --max-depth 6 -q";
  ASSERT_EQ(test::run_command(cli("render " + kScene + " -o " + dir + "/full.exr" + common)).exit_code, 0);
  auto a = test::run_command(cli("render " + kScene + common + " --pass-range 0-2 --partial " + dir + "/a.rfb"));
  ASSERT_EQ(a.exit_code, 0) << a.output;
  auto b = test::run_command(cli("render " + kScene + common + " --pass-range 3-7 --partial " + dir + "/b.rfb"));
  ASSERT_EQ(b.exit_code, 0) << b.output;
  auto m = test::run_command(cli("merge " + dir + "/b.rfb " + dir + "/a.rfb -o " + dir + "/merged.exr"));
  ASSERT_EQ(m.exit_code, 0) << m.output;
  Exr full = read_exr(dir + "/full.exr"), merged = read_exr(dir + "/merged.exr");
  ASSERT_EQ(full.px.size(), merged.px.size());
  size_t bad = 0;
  for (size_t i = 0; i < full.px.size(); ++i) {
    double x = full.px[i], y = merged.px[i];
    // DESIGN.md's merge tolerance, plus float32 rounding of the EXR.
    if (std::fabs(x - y) > 1e-6 * std::max(std::fabs(x), std::fabs(y)) + 1e-7 * std::fabs(x) + 1e-12) ++bad;
  }
  EXPECT_EQ(bad, 0u);

  // Overlapping pass ranges and mismatched headers are refused with a reason.
  auto c = test::run_command(cli("render " + kScene + common + " --pass-range 2-4 --partial " + dir + "/c.rfb"));
  ASSERT_EQ(c.exit_code, 0);
  auto overlap = test::run_command(cli("merge " + dir + "/a.rfb " + dir + "/c.rfb -o " + dir + "/x.exr"));
  EXPECT_NE(overlap.exit_code, 0);
  EXPECT_NE(overlap.output.find("overlap"), std::string::npos) << overlap.output;
  auto d = test::run_command(cli("render " + kScene + " --res 24x24 --spp 16 --passes 8 --max-depth 6 -q --seed 99 --pass-range 5-5 --partial " + dir + "/d.rfb"));
  ASSERT_EQ(d.exit_code, 0);
  auto seed = test::run_command(cli("merge " + dir + "/a.rfb " + dir + "/d.rfb -o " + dir + "/y.exr"));
  EXPECT_NE(seed.exit_code, 0);
  EXPECT_NE(seed.output.find("seed"), std::string::npos) << seed.output;
  EXPECT_FALSE(std::filesystem::exists(dir + "/y.exr")) << "nothing half-written on refusal";
}

TEST(Cli, SameSeedTwiceGivesTheSamePixels) {
  std::string dir = test::make_temp_dir("cli-repeat");
  std::string args = " --res 16x16 --spp 8 --passes 2 --max-depth 4 -q";
  ASSERT_EQ(test::run_command(cli("render " + kScene + " -o " + dir + "/a.exr" + args)).exit_code, 0);
  ASSERT_EQ(test::run_command(cli("render " + kScene + " -o " + dir + "/b.exr" + args + " --threads 1")).exit_code, 0);
  Exr a = read_exr(dir + "/a.exr"), b = read_exr(dir + "/b.exr");
  EXPECT_EQ(a.px, b.px) << "bit-identical pixels expected for one build on one machine";
  SampleBuffer pa, pb;
  ASSERT_EQ(test::run_command(cli("render " + kScene + args + " --pass-range 0-1 --partial " + dir + "/a.rfb")).exit_code, 0);
  ASSERT_EQ(test::run_command(cli("render " + kScene + args + " --pass-range 0-1 --partial " + dir + "/b.rfb --threads 1")).exit_code, 0);
  pa = read_buffer_file(dir + "/a.rfb");
  pb = read_buffer_file(dir + "/b.rfb");
  EXPECT_EQ(pa.sum, pb.sum);
  EXPECT_EQ(pa.batch_sum_sq, pb.batch_sum_sq);
}

TEST(Cli, BadArgumentsAreNamed) {
  auto r = test::run_command(cli("render " + kScene + " -o /tmp/x.exr --res 32by32"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.output.find("--res"), std::string::npos) << r.output;
  r = test::run_command(cli("render " + kScene + " --partial /tmp/x.rfb --pass-range 0-99"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("--pass-range"), std::string::npos) << r.output;
  r = test::run_command(cli("render scenes/nope/missing.json -o /tmp/x.exr"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.output.find("missing.json"), std::string::npos) << r.output;
}

// `compare`: an image against itself has no error; against a differently seeded render of the
// same scene it has (relMSE of the two images' noise); a window is checked against the image.
TEST(Cli, CompareReportsTheErrorAndRefusesABadWindow) {
  std::string dir = test::make_temp_dir("cli-compare");
  std::string args = " --res 16x16 --spp 4 --passes 2 --max-depth 4 -q";
  ASSERT_EQ(test::run_command(cli("render " + kScene + " -o " + dir + "/a.exr" + args)).exit_code, 0);
  ASSERT_EQ(test::run_command(cli("render " + kScene + " -o " + dir + "/b.exr --seed 5" + args)).exit_code, 0);
  auto same = test::run_command(cli("compare " + dir + "/a.exr " + dir + "/a.exr"));
  ASSERT_EQ(same.exit_code, 0) << same.output;
  EXPECT_NE(same.output.find("rmse 0 relmse 0 mae 0"), std::string::npos) << same.output;
  auto other = test::run_command(cli("compare " + dir + "/a.exr " + dir + "/b.exr --window 0,0,8,8"));
  ASSERT_EQ(other.exit_code, 0) << other.output;
  double rmse = -1, rel = -1, mae = -1;
  ASSERT_EQ(std::sscanf(other.output.c_str(), "rmse %lf relmse %lf mae %lf", &rmse, &rel, &mae), 3)
      << other.output;
  EXPECT_GT(rmse, 0);
  EXPECT_GT(rel, 0);
  EXPECT_GT(mae, 0);
  auto bad = test::run_command(cli("compare " + dir + "/a.exr " + dir + "/b.exr --window 0,0,17,8"));
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.output.find("window"), std::string::npos) << bad.output;
}

TEST(Cli, BenchQuickRuns) {
  auto r = test::run_command(cli("bench --quick"));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("ratio"), std::string::npos) << r.output;
}

}  // namespace
}  // namespace rf
