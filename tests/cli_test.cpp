// The command line end to end: render, partial renders + merge, refusals, repeatability.
#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>

#include <cmath>
#include <cstdio>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>

#include "engine/buffer_file.h"
#include "engine/digest.h"
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

// The command's stdout alone (run_command adds its stderr).
test::CommandResult stdout_of(const std::string& args) {
  return test::run_command("{ " + cli(args) + " 2>/dev/null; }");
}

TEST(Cli, RenderWritesExrAndPngWithProvenance) {
  std::string dir = test::make_temp_dir("cli-render");
  auto r = test::run_command(cli("render " + kScene + " -o " + dir +
                                 "/c.exr --res 32x32 --spp 16 --passes 4 --max-depth 8"));
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

// What scripts and job runners read: --version; render's summary as JSON lines (one per frame,
// with the files written), --no-png and a half-float EXR; Open Job Description progress lines
// that climb to 100 over a frame range; merge and compare as JSON.
TEST(Cli, JsonSummariesOpenJdProgressHalfExrAndNoPng) {
  std::string dir = test::make_temp_dir("cli-json");
  auto v = stdout_of("--version");
  EXPECT_EQ(v.exit_code, 0) << v.output;
  EXPECT_EQ(v.output.rfind("rayfarm-", 0), 0u) << v.output;

  auto r = stdout_of("render " + kScene + " -o " + dir +
                     "/c.exr --res 32x32 --spp 16 --passes 4 --json --no-png --half "
                     "--partial " +
                     dir + "/c.rfb --pass-range 0-3");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  nlohmann::json j = nlohmann::json::parse(r.output);  // one frame: one line, nothing else
  EXPECT_EQ(j["exr"], dir + "/c.exr");
  EXPECT_TRUE(j["png"].is_null());
  EXPECT_EQ(j["partial"], dir + "/c.rfb");
  EXPECT_EQ(j["spp"], 16.0);
  EXPECT_EQ(j["passes"], 4);
  EXPECT_GT(j["rel_mse"].get<double>(), 0);
  EXPECT_GT(j["rays"].get<double>(), 32 * 32 * 16);
  EXPECT_FALSE(std::filesystem::exists(dir + "/c.png")) << "--no-png";
  Exr half = read_exr(dir + "/c.exr");
  EXPECT_EQ(half.format, "half");
  EXPECT_EQ(half.nch, 7);

  auto one = stdout_of("render " + kScene + " -o " + dir +
                       "/one.exr --res 32x32 --spp 1 --passes 1 --json");
  ASSERT_EQ(one.exit_code, 0) << one.output;
  EXPECT_TRUE(nlohmann::json::parse(one.output)["rel_mse"].is_null())
      << "one pass: no error estimate";
  EXPECT_EQ(read_exr(dir + "/one.exr").format, "float");
  EXPECT_TRUE(std::filesystem::exists(dir + "/one.png"));

  auto p = stdout_of("render " + kScene + " -o " + dir +
                     "/s.####.exr --res 32x32 --spp 8 --passes 4 --frames 1-3 "
                     "--progress openjd");
  ASSERT_EQ(p.exit_code, 0) << p.output;
  std::istringstream lines(p.output);
  std::string line;
  double last = -1;
  int statuses = 0;
  while (std::getline(lines, line)) {
    if (line.rfind("openjd_progress: ", 0) == 0) {
      double percent = std::stod(line.substr(17));
      EXPECT_GT(percent, last) << p.output;
      last = percent;
    } else {
      EXPECT_EQ(line.rfind("openjd_status: ", 0), 0u)
          << "not an Open Job Description line: " << line;
      ++statuses;
    }
  }
  EXPECT_EQ(last, 100.0) << p.output;
  EXPECT_EQ(statuses, 4) << "a line per frame and one at the end: " << p.output;

  auto m = stdout_of("merge " + dir + "/c.rfb -o " + dir + "/m.exr --json --no-png");
  ASSERT_EQ(m.exit_code, 0) << m.output;
  nlohmann::json mj = nlohmann::json::parse(m.output);
  EXPECT_EQ(mj["spp"], 16.0);
  EXPECT_EQ(mj["passes"], "0-3");
  EXPECT_FALSE(std::filesystem::exists(dir + "/m.png"));
  auto c = stdout_of("compare " + dir + "/m.exr " + dir + "/s.0001.exr --json");
  ASSERT_EQ(c.exit_code, 0) << c.output;
  nlohmann::json cj = nlohmann::json::parse(c.output);
  EXPECT_GT(cj["rmse"].get<double>(), 0);
  EXPECT_GT(cj["mae"].get<double>(), 0);
}

// `bundle --json`: what a submit of the scene uploads, found by the importers (the scene file
// and the textures it names), each with its size and the SHA-256 of its bytes; a missing scene
// is a usage error.
TEST(Cli, BundleListsTheFilesASubmitUploadsWithTheirDigests) {
  auto r = stdout_of("bundle scenes/materials/scene.json --json");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  nlohmann::json b = nlohmann::json::parse(r.output);
  EXPECT_EQ(b["scene"], "scene.json");
  std::set<std::string> paths;
  for (const auto& f : b["files"]) {
    const std::string path = b["dir"].get<std::string>() + "/" + f["path"].get<std::string>();
    const std::string bytes = read_file_bytes(path);
    EXPECT_EQ(f["sha256"], sha256_hex(bytes)) << path;
    EXPECT_EQ(f["bytes"], bytes.size()) << path;
    paths.insert(f["path"]);
  }
  EXPECT_EQ(paths, (std::set<std::string>{"scene.json", "textures/floor.png", "textures/sky.exr"}));
  EXPECT_EQ(test::run_command(cli("bundle scenes/no-such/scene.json")).exit_code, 2);
}

// The shipped glTF scene (scenes/gltf-still-life): its file is what its script writes, it
// renders without one importer warning, its cube turns between frames, and a submit bundles the
// texture beside it.
TEST(Cli, TheShippedGltfSceneIsItsScriptsAndRendersWithoutWarnings) {
  std::string dir = test::make_temp_dir("cli-gltf-scene");
  const std::string src = test::source_dir() + "/scenes/gltf-still-life";
  auto made = test::run_command("cd " + dir + " && python3 " + src + "/make_scene.py");
  ASSERT_EQ(made.exit_code, 0) << made.output;
  for (const char* f : {"scene.gltf", "checker.png"})
    EXPECT_TRUE(read_file_bytes(dir + "/" + f) == read_file_bytes(src + "/" + f))
        << f << " differs from what make_scene.py writes: run it again";
  std::string images[2];
  for (int i = 0; i < 2; ++i) {
    const std::string out = dir + "/f" + std::to_string(i) + ".exr";
    auto r = test::run_command(cli("render scenes/gltf-still-life/scene.gltf --res 48x32 --spp 4 "
                                   "--passes 1 --frame " + std::to_string(4 * i) + " -o " + out));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    EXPECT_EQ(r.output.find("warn"), std::string::npos) << r.output;
    images[i] = read_file_bytes(out.substr(0, out.size() - 4) + ".png");
  }
  EXPECT_TRUE(images[0] != images[1]) << "frame 4 turns the cube";
  auto b = stdout_of("bundle scenes/gltf-still-life/scene.gltf --json");
  ASSERT_EQ(b.exit_code, 0) << b.output;
  std::set<std::string> paths;
  const nlohmann::json bundle = nlohmann::json::parse(b.output);
  for (const auto& f : bundle["files"]) paths.insert(f["path"]);
  EXPECT_EQ(paths, (std::set<std::string>{"scene.gltf", "checker.png"}));
}

// The text progress's last line is the frame's end, after its last merge: "passes 4/4 ... done"
// for a full render, and for one stopped on its noise target the passes of that stop. Before,
// a report made between the last task and its merge printed "100% ... passes 3/4 ... done" and
// the true end was never printed; a stop on the target printed no end at all.
TEST(Cli, TheLastProgressLineIsTheFramesEnd) {
  std::string dir = test::make_temp_dir("cli-progress");
  auto last_progress = [](const std::string& output) {
    std::istringstream lines(output);
    std::string line, last;
    while (std::getline(lines, line))
      if (line.rfind("progress: ", 0) == 0) last = line;
    return last;
  };
  auto full = test::run_command(
      cli("render " + kScene + " -o " + dir + "/full.exr --res 32x32 --spp 8 --passes 4 --no-png"));
  ASSERT_EQ(full.exit_code, 0) << full.output;
  std::string end = last_progress(full.output);
  EXPECT_NE(end.find("passes 4/4,"), std::string::npos) << full.output;
  EXPECT_NE(end.find(", done"), std::string::npos) << full.output;
  auto target = test::run_command(
      cli("render " + kScene + " -o " + dir +
          "/target.exr --res 32x32 --spp 1024 --passes 256 --noise-target 0.05 --no-png"));
  ASSERT_EQ(target.exit_code, 0) << target.output;
  std::smatch stop;
  ASSERT_TRUE(std::regex_search(target.output, stop,
                                std::regex("noise target \\S+ reached after (\\d+) of 256")))
      << target.output;
  end = last_progress(target.output);
  EXPECT_NE(end.find("passes " + stop[1].str() + "/256,"), std::string::npos) << target.output;
  EXPECT_NE(end.find(", done"), std::string::npos) << target.output;
}

// The services' logs for a collector: --log-format json makes every line one JSON object (time,
// level, msg); --log-level warn leaves the info lines out; a level that is not one is refused.
// A service's output: `command` (environment assignments first, if any) started, then stopped
// with SIGTERM once its output holds `until` (at most 60 s: a sanitizer build on a loaded
// machine starts slowly), or after 1.5 s when `until` is empty. The log is removed first (an
// earlier run's 'listening' must not end this one) and grep -s is quiet until the started shell
// has made it (its "No such file" went into the output, which must be the service's alone).
test::CommandResult service_output(const std::string& command, const std::string& until,
                                   const std::string& log) {
  const std::string wait = until.empty()
                               ? "sleep 1.5"
                               : "for i in $(seq 600); do grep -qsF '" + until + "' " + log +
                                     " && break; kill -0 $p 2>/dev/null || break; sleep 0.1; done";
  return test::run_command("{ rm -f " + log + "; " + command + " > " + log + " 2>&1 & p=$!; " +
                           wait + "; kill $p; wait $p; cat " + log + "; }");
}

TEST(Cli, ServicesLogJsonLinesAtTheLevelAsked) {
  std::string dir = test::make_temp_dir("cli-logs");
  auto run_for_a_while = [&](const std::string& args, const std::string& until) {
    return service_output(test::rayfarm_binary() + " " + args, until, dir + "/out.log");
  };
  auto json = run_for_a_while(
      "coordinator --listen 127.0.0.1:0 --state-dir " + dir + "/a --log-format json", "listening");
  std::istringstream lines(json.output);
  std::string line;
  int parsed = 0;
  while (std::getline(lines, line)) {
    nlohmann::json j = nlohmann::json::parse(line);  // throws on a line that is not JSON
    EXPECT_TRUE(j["time"].is_string() && j["level"].is_string() && j["msg"].is_string()) << line;
    ++parsed;
  }
  EXPECT_GE(parsed, 2) << json.output;
  EXPECT_NE(json.output.find("coordinator listening on"), std::string::npos) << json.output;
  auto quiet = run_for_a_while(
      "coordinator --listen 127.0.0.1:0 --state-dir " + dir + "/b --log-level warn", "");
  EXPECT_EQ(quiet.output.find("listening"), std::string::npos) << quiet.output;
  EXPECT_EQ(test::run_command(cli("worker --log-level loud")).exit_code, 2);
}

// `completion bash` completes subcommands and each one's own flags, from the binary's own
// definitions (a flag added to a command appears without touching the script).
TEST(Cli, BashCompletionKnowsTheCommandsAndTheirFlags) {
  auto complete = [](const std::string& words, int cword) {
    return test::run_command(
        "bash -c 'source <(" + test::rayfarm_binary() + " completion bash); COMP_WORDS=(" + words +
        "); COMP_CWORD=" + std::to_string(cword) + "; _rayfarm; echo \"${COMPREPLY[*]}\"'");
  };
  auto sub = complete("rayfarm wa", 1);
  ASSERT_EQ(sub.exit_code, 0) << sub.output;
  EXPECT_EQ(sub.output, "watch\n");
  auto flags = complete("rayfarm watch j1 --", 3);
  EXPECT_NE(flags.output.find("--json"), std::string::npos) << flags.output;
  EXPECT_NE(flags.output.find("--progress"), std::string::npos) << flags.output;
  EXPECT_EQ(flags.output.find("--spp"), std::string::npos) << "render's flag: " << flags.output;
  auto render = complete("rayfarm render --h", 2);
  EXPECT_NE(render.output.find("--half"), std::string::npos) << render.output;
}

// Where a flag comes from, in order: the command line, then the --config file (named on the
// command line: a choice made for this run), then a RAYFARM_* variable, then the default; seen
// through the coordinator's --log-format (JSON lines or text).
TEST(Cli, FlagsComeFromTheCommandLineThenTheConfigFileThenTheEnvironment) {
  std::string dir = test::make_temp_dir("cli-config");
  test::write_text(dir + "/json.toml", "[coordinator]\nlog-format = \"json\"\n");
  int run = 0;
  auto logs_json = [&](const std::string& env, const std::string& args,
                       const std::string& flags = "") {
    auto r = service_output(env + " " + test::rayfarm_binary() + " " + args +
                                " coordinator --listen 127.0.0.1:0 --state-dir " + dir + "/s" +
                                std::to_string(run++) + " " + flags,
                            "listening", dir + "/out.log");
    EXPECT_NE(r.output.find("listening"), std::string::npos) << r.output;
    return r.output.rfind("{\"level\":\"info\"", 0) == 0;
  };
  const std::string config = "--config " + dir + "/json.toml";
  EXPECT_FALSE(logs_json("", "")) << "the default: text";
  EXPECT_TRUE(logs_json("", config)) << "the file";
  EXPECT_TRUE(logs_json("RAYFARM_LOG_FORMAT=json", "")) << "the environment";
  EXPECT_TRUE(logs_json("RAYFARM_LOG_FORMAT=text", config)) << "the file over the environment";
  EXPECT_FALSE(logs_json("RAYFARM_LOG_FORMAT=json", config, "--log-format text"))
      << "the command line over both";
  EXPECT_TRUE(logs_json("RAYFARM_LOG_FORMAT=text", "", "--log-format json"));

  // An output flag from the environment: $RAYFARM_PROGRESS=openjd for a job runner's renders,
  // and a --progress given still wins.
  auto render = [&](const std::string& env, const std::string& flags) {
    return test::run_command("{ " + env + " " + test::rayfarm_binary() + " render " +
                             test::source_dir() + "/" + kScene +
                             " --res 8x8 --spp 2 --passes 2 --no-png -o " + dir + "/p.exr " +
                             flags + " 2>/dev/null; }")
        .output;
  };
  EXPECT_NE(render("RAYFARM_PROGRESS=openjd", "").find("openjd_progress: 100.0"),
            std::string::npos);
  EXPECT_EQ(render("RAYFARM_PROGRESS=openjd", "--progress text").find("openjd_"),
            std::string::npos);
  EXPECT_EQ(render("", "").find("openjd_"), std::string::npos);
}

TEST(Cli, PartialRendersMergeToTheFullRender) {
  std::string dir = test::make_temp_dir("cli-merge");
  std::string common = " --res 24x24 --spp 16 --passes 8 --max-depth 6 -q";
  ASSERT_EQ(
      test::run_command(cli("render " + kScene + " -o " + dir + "/full.exr" + common)).exit_code,
      0);
  auto a = test::run_command(
      cli("render " + kScene + common + " --pass-range 0-2 --partial " + dir + "/a.rfb"));
  ASSERT_EQ(a.exit_code, 0) << a.output;
  auto b = test::run_command(
      cli("render " + kScene + common + " --pass-range 3-7 --partial " + dir + "/b.rfb"));
  ASSERT_EQ(b.exit_code, 0) << b.output;
  auto m =
      test::run_command(cli("merge " + dir + "/b.rfb " + dir + "/a.rfb -o " + dir + "/merged.exr"));
  ASSERT_EQ(m.exit_code, 0) << m.output;
  Exr full = read_exr(dir + "/full.exr"), merged = read_exr(dir + "/merged.exr");
  ASSERT_EQ(full.px.size(), merged.px.size());
  size_t bad = 0;
  for (size_t i = 0; i < full.px.size(); ++i) {
    double x = full.px[i], y = merged.px[i];
    // DESIGN.md's merge tolerance, plus float32 rounding of the EXR.
    if (std::fabs(x - y) >
        1e-6 * std::max(std::fabs(x), std::fabs(y)) + 1e-7 * std::fabs(x) + 1e-12)
      ++bad;
  }
  EXPECT_EQ(bad, 0u);

  // Overlapping pass ranges and mismatched headers are refused with a reason.
  auto c = test::run_command(
      cli("render " + kScene + common + " --pass-range 2-4 --partial " + dir + "/c.rfb"));
  ASSERT_EQ(c.exit_code, 0);
  auto overlap =
      test::run_command(cli("merge " + dir + "/a.rfb " + dir + "/c.rfb -o " + dir + "/x.exr"));
  EXPECT_NE(overlap.exit_code, 0);
  EXPECT_NE(overlap.output.find("overlap"), std::string::npos) << overlap.output;
  auto d = test::run_command(cli(
      "render " + kScene +
      " --res 24x24 --spp 16 --passes 8 --max-depth 6 -q --seed 99 --pass-range 5-5 --partial " +
      dir + "/d.rfb"));
  ASSERT_EQ(d.exit_code, 0);
  auto seed =
      test::run_command(cli("merge " + dir + "/a.rfb " + dir + "/d.rfb -o " + dir + "/y.exr"));
  EXPECT_NE(seed.exit_code, 0);
  EXPECT_NE(seed.output.find("seed"), std::string::npos) << seed.output;
  EXPECT_FALSE(std::filesystem::exists(dir + "/y.exr")) << "nothing half-written on refusal";
}

TEST(Cli, SameSeedTwiceGivesTheSamePixels) {
  std::string dir = test::make_temp_dir("cli-repeat");
  std::string args = " --res 16x16 --spp 8 --passes 2 --max-depth 4 -q";
  ASSERT_EQ(test::run_command(cli("render " + kScene + " -o " + dir + "/a.exr" + args)).exit_code,
            0);
  ASSERT_EQ(
      test::run_command(cli("render " + kScene + " -o " + dir + "/b.exr" + args + " --threads 1"))
          .exit_code,
      0);
  Exr a = read_exr(dir + "/a.exr"), b = read_exr(dir + "/b.exr");
  EXPECT_EQ(a.px, b.px) << "bit-identical pixels expected for one build on one machine";
  SampleBuffer pa, pb;
  ASSERT_EQ(test::run_command(
                cli("render " + kScene + args + " --pass-range 0-1 --partial " + dir + "/a.rfb"))
                .exit_code,
            0);
  ASSERT_EQ(test::run_command(cli("render " + kScene + args + " --pass-range 0-1 --partial " + dir +
                                  "/b.rfb --threads 1"))
                .exit_code,
            0);
  pa = read_buffer_file(dir + "/a.rfb");
  pb = read_buffer_file(dir + "/b.rfb");
  EXPECT_EQ(pa.sum, pb.sum);
  EXPECT_EQ(pa.batch_sum_sq, pb.batch_sum_sq);
}

// render --memory: a frame larger than the budget is kept in tiles in unlinked files under
// --spill-dir and written a band at a time; its EXR pixels (with AOVs), its PNG and its partial
// .rfb are the bytes of the same render held whole, and nothing is left in the spill directory.
TEST(Cli, AFrameLargerThanItsMemoryIsKeptInTilesOnDiskAndWrittenTheSame) {
  std::string dir = test::make_temp_dir("cli-spill");
  std::filesystem::create_directories(dir + "/spill");
  // 160x120 with albedo and depth: 2.6 MB of planes against a budget of 1 MiB.
  std::string args =
      " --res 160x120 --spp 8 --passes 4 --max-depth 3 --tile-size 16 "
      "--aov albedo,depth -q";
  std::string spill = " --memory 1M --spill-dir " + dir + "/spill";
  for (const std::string& how : {std::string(""), spill}) {
    std::string name = how.empty() ? "/whole" : "/tiled";
    auto r = test::run_command(cli("render " + kScene + " -o " + dir + name + ".exr" + args + how));
    ASSERT_EQ(r.exit_code, 0) << r.output;
    r = test::run_command(cli("render " + kScene + args + how + " --pass-range 0-2 --partial " +
                              dir + name + ".rfb"));
    ASSERT_EQ(r.exit_code, 0) << r.output;
  }
  Exr whole = read_exr(dir + "/whole.exr"), tiled = read_exr(dir + "/tiled.exr");
  EXPECT_EQ(tiled.names, whole.names);
  EXPECT_EQ(tiled.nch, 12);
  EXPECT_TRUE(tiled.px == whole.px) << "the same pixels, bit for bit";
  EXPECT_EQ(tiled.attr("rayfarm:passes"), whole.attr("rayfarm:passes"));
  EXPECT_EQ(tiled.attr("rayfarm:spp"), whole.attr("rayfarm:spp"));
  EXPECT_TRUE(read_file_bytes(dir + "/tiled.png") == read_file_bytes(dir + "/whole.png"));
  // (Not the .rfb's bytes: core-seconds in its header are measured time.)
  SampleBuffer a = read_buffer_file(dir + "/tiled.rfb"), b = read_buffer_file(dir + "/whole.rfb");
  EXPECT_TRUE(same_samples(a, b));
  EXPECT_EQ(a.header.passes, b.header.passes);
  EXPECT_TRUE(std::filesystem::is_empty(dir + "/spill")) << "the spill files were unlinked";
  auto bad = test::run_command(cli("render " + kScene + " -o " + dir + "/x.exr" + args +
                                   " --memory 1M --spill-dir " + dir + "/missing"));
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find(dir + "/missing"), std::string::npos) << bad.output;
  EXPECT_FALSE(std::filesystem::exists(dir + "/x.exr"));
}

// render --frames: one render per frame into the template's names, each frame the bits of the
// same frame rendered alone with --frame (a frame selects the seed stream), the frames differing;
// bad combinations are usage errors (exit 2) and a missing per-frame scene file renders nothing.
TEST(Cli, FrameRangesRenderEachFrameAsAlone) {
  std::string dir = test::make_temp_dir("cli-frames");
  const std::string args = " --res 16x16 --spp 4 --passes 1 --max-depth 3 -q";
  auto r = test::run_command(
      cli("render " + kScene + " --frames 2-4 -o " + dir + "/shot.####.exr" + args));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  for (const char* name : {"shot.0002", "shot.0003", "shot.0004"}) {
    EXPECT_TRUE(std::filesystem::exists(dir + "/" + name + ".exr")) << name;
    EXPECT_TRUE(std::filesystem::exists(dir + "/" + name + ".png")) << name;
  }
  r = test::run_command(cli("render " + kScene + " --frame 3 -o " + dir + "/alone.exr" + args));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_EQ(read_exr(dir + "/shot.0003.exr").px, read_exr(dir + "/alone.exr").px);
  EXPECT_NE(read_exr(dir + "/shot.0002.exr").px, read_exr(dir + "/shot.0003.exr").px);

  r = test::run_command(cli("render " + kScene + " --frames 5,7 -o " + dir + "/p.%03d.exr" + args));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_TRUE(std::filesystem::exists(dir + "/p.005.exr"));
  EXPECT_TRUE(std::filesystem::exists(dir + "/p.007.exr"));

  const std::pair<std::string, std::string> usage[] = {
      {" --frame 1 --frames 1-2 -o " + dir + "/u.####.exr", "--frame or --frames"},
      {" --frames 1-3 -o " + dir + "/u.exr", "frame template"},
      {" --frames 1-3 --pass-range 0-0 --partial " + dir + "/u.rfb", "--partial"},
      {" --frames 3-1x -o " + dir + "/u.####.exr", "--frames"},
      {" --shutter 0.5,0.25 -o " + dir + "/u.exr", "--shutter"},
  };
  for (const auto& [extra, said] : usage) {
    r = test::run_command(cli("render " + kScene + extra + args));
    EXPECT_EQ(r.exit_code, 2) << extra << ": " << r.output;
    EXPECT_NE(r.output.find(said), std::string::npos) << extra << ": " << r.output;
  }
  r = test::run_command(
      cli("render " + dir + "/nope.####.json --frames 1-2 -o " + dir + "/n.####.exr" + args));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find("nope.0001.json"), std::string::npos) << r.output;
  EXPECT_FALSE(std::filesystem::exists(dir + "/n.0001.exr"));
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
  // Durations and sizes (retention, the worker's cache) name the flag and what they take.
  for (const std::string& bad :
       {std::string("coordinator --state-dir /tmp/x --keep-finished 7x"),
        std::string("coordinator --state-dir /tmp/x --keep-finished -1d"),
        std::string("coordinator --state-dir /tmp/x --blob-grace never"),
        std::string("worker --cache-bytes 20GB"), std::string("worker --cache-bytes -5")}) {
    r = test::run_command(cli(bad));
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.output;
    const std::string flag = bad.substr(bad.rfind("--"), bad.rfind(' ') - bad.rfind("--"));
    EXPECT_NE(r.output.find(flag), std::string::npos) << bad << ": " << r.output;
    EXPECT_NE(r.output.find("is not a"), std::string::npos) << bad << ": " << r.output;
  }
}

// Exit codes are 0, 1 (failure at run time), 2 (bad usage, parse errors included) for every
// command; every numeric flag is range-checked (before: --spp -1 wrapped to 2^64-1 and never
// ended, --threads -1, --time-budget -1 and --exposure nan were taken, parse errors exited
// 104-109); -o never writes over the PNG, a device, a FIFO or an input; merge refuses a buffer
// whose sums are not finite or whose counts its header does not explain (before: relMSE nan,
// exit 0).
TEST(Cli, ExitCodesRangesOutputsAndMergeRefusals) {
  std::string dir = test::make_temp_dir("cli-hygiene");
  const std::string render = "render " + kScene + " -o " + dir + "/x.exr --res 8x8 -q ";
  for (const std::string& bad :
       {std::string("--spp -1"), std::string("--spp 0"), std::string("--threads -1"),
        std::string("--time-budget -1"), std::string("--exposure nan"),
        std::string("--exposure inf"), std::string("--passes 0"), std::string("--seed -3"),
        std::string("--noise-target nan"), std::string("--max-depth -2"), std::string("--res 0x10"),
        std::string("--no-such-flag"), std::string("--spp")}) {
    auto r = test::run_command(cli(render + bad));
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.output;
    std::string flag = bad.substr(0, bad.find(' '));
    EXPECT_NE(r.output.find(flag), std::string::npos) << bad << ": " << r.output;
  }
  for (const std::string& bad :
       {std::string("status --timeout 0"), std::string("watch"), std::string("submit"),
        std::string("worker --give-up-after -1"),
        std::string("coordinator --state-dir " + dir + "/s --lease-seconds nan"),
        std::string("nonsense")}) {
    auto r = test::run_command(cli(bad));
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.output;
  }
  EXPECT_EQ(test::run_command(cli("render --help")).exit_code, 0);

  auto png = test::run_command(cli("render " + kScene + " -o " + dir + "/out.png --res 8x8 -q"));
  EXPECT_EQ(png.exit_code, 2) << png.output;
  EXPECT_NE(png.output.find(".exr"), std::string::npos) << png.output;
  ASSERT_EQ(test::run_command("mkfifo " + dir + "/fifo.exr").exit_code, 0);
  auto fifo = test::run_command(cli("render " + kScene + " -o " + dir + "/fifo.exr --res 8x8 -q"));
  EXPECT_EQ(fifo.exit_code, 2) << fifo.output;
  EXPECT_NE(fifo.output.find("not a regular file"), std::string::npos) << fifo.output;
  EXPECT_TRUE(std::filesystem::is_fifo(dir + "/fifo.exr")) << "left as it was";

  // merge: a good partial, the same with a NaN sum, and one with a sample too many.
  const std::string common = " --res 8x8 --spp 4 --passes 2 -q --pass-range 0-0 --partial ";
  ASSERT_EQ(test::run_command(cli("render " + kScene + common + dir + "/a.rfb")).exit_code, 0);
  SampleBuffer a = read_buffer_file(dir + "/a.rfb");
  SampleBuffer nan = a;
  nan.sum[4] = std::nan("");
  write_buffer_file(dir + "/nan.rfb", nan);
  SampleBuffer extra = a;
  extra.count[0] += 1;
  write_buffer_file(dir + "/extra.rfb", extra);
  EXPECT_EQ(test::run_command(cli("merge " + dir + "/a.rfb -o " + dir + "/m.exr")).exit_code, 0);
  for (const char* bad : {"nan", "extra"}) {
    auto r = test::run_command(cli("merge " + dir + "/" + bad + ".rfb -o " + dir + "/m.exr"));
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find(std::string(bad) + ".rfb: refused"), std::string::npos) << r.output;
  }
  auto over = test::run_command(cli("merge " + dir + "/a.rfb -o " + dir + "/a.rfb"));
  EXPECT_EQ(over.exit_code, 2) << over.output;

  // A scene without anything that emits renders (black) with a warning naming it.
  ASSERT_EQ(test::run_command("cp -r " + test::source_dir() + "/scenes/cornell-box/meshes " + dir)
                .exit_code,
            0);
  nlohmann::json scene = nlohmann::json::parse(read_file_bytes(test::source_dir() + "/" + kScene));
  for (auto& shape : scene["shapes"]) shape.erase("emission");
  test::write_text(dir + "/dark.json", scene.dump(2));
  auto d =
      test::run_command(cli("render " + dir + "/dark.json -o " + dir + "/dark.exr --res 8x8 -q"));
  EXPECT_EQ(d.exit_code, 0) << d.output;
  EXPECT_NE(d.output.find("dark.json: the scene has no lights"), std::string::npos) << d.output;
}

// What a probe found lenient or unclear on the command line, each now a usage error (exit 2)
// naming the flag, or a run-time error (exit 1) that says what is wrong: names the engine does
// not know, spp not a multiple of passes and a resolution over the engine's bound (were exit 1
// from the engine), a pass range with a minus sign (was "first pass 4294967295"), an address
// that is not one or a port past 65535 (gRPC bound 99999 as 34463), TLS half given, a directory
// as the scene (was "syntax error while parsing value"), merge of a directory or a device (was
// "refusing to replace an input"), compare of a PNG preview with an EXR (exited 0), and merge of
// a re-signed buffer with a negative sum or core_seconds of 1e308 (were merged).
TEST(Cli, ProbeFindingsAreUsageErrorsOrSayWhatIsWrong) {
  std::string dir = test::make_temp_dir("cli-probe");
  const std::string render = "render " + kScene + " -o " + dir + "/x.exr -q ";
  for (const auto& [bad, flag] : std::vector<std::pair<std::string, std::string>>{
           {"--integrator magic", "unknown integrator 'magic'"},
           {"--filter lanczos", "unknown filter 'lanczos'"},
           {"--sampler halton", "unknown sampler 'halton'"},
           {"--aov bogus", "--aov"},
           {"--spp 4 --passes 3", "must be a multiple of --passes"},
           {"--res 40000x40000", "1..32768"},
           {"--partial " + dir + "/p.rfb --pass-range -1-2", "expected FIRST-LAST"}}) {
    auto r = test::run_command(cli(render + bad));
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find(flag), std::string::npos) << bad << ": " << r.output;
  }
  const std::string coord = "coordinator --state-dir " + dir + "/state ";
  for (const auto& [bad, says] : std::vector<std::pair<std::string, std::string>>{
           {"--listen 127.0.0.1:99999", "outside 0..65535"},
           {"--listen nonsense", "is not an address"},
           {"--metrics-listen 1.2.3.4", "is not an address"},
           {"--tls-key " + dir + "/k.pem", "--tls-key needs --tls-cert"}}) {
    auto r = test::run_command(cli(coord + bad));
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.output;
    EXPECT_NE(r.output.find(says), std::string::npos) << bad << ": " << r.output;
  }
  auto d = test::run_command(cli("render " + dir + " -o " + dir + "/y.exr -q"));
  EXPECT_EQ(d.exit_code, 1) << d.output;
  EXPECT_NE(d.output.find("is a directory, not a scene file"), std::string::npos) << d.output;
  for (const auto& [input, says] : std::vector<std::pair<std::string, std::string>>{
           {"/dev/null", "is not a regular file"}, {dir, "is a directory"}}) {
    auto r = test::run_command(cli("merge " + input + " -o " + dir + "/m.exr"));
    EXPECT_EQ(r.exit_code, 2) << r.output;
    EXPECT_NE(r.output.find(says), std::string::npos) << r.output;
  }
  ASSERT_EQ(test::run_command(cli(render + "--res 8x8 --spp 2 --passes 2")).exit_code, 0);
  auto cmp = test::run_command(cli("compare " + dir + "/x.png " + dir + "/x.exr"));
  EXPECT_EQ(cmp.exit_code, 2) << cmp.output;
  EXPECT_NE(cmp.output.find("8-bit display values"), std::string::npos) << cmp.output;

  // --time-budget stops a pass in flight: a pass of 10^12 samples per pixel (before: rendered
  // until killed, since the budget was checked between passes only).
  auto t0 = std::chrono::steady_clock::now();
  auto huge =
      test::run_command(cli(render + "--res 8x8 --spp 1000000000000 --passes 1 --time-budget 1"));
  double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(huge.exit_code, 1) << huge.output;
  EXPECT_NE(huge.output.find("ran out before the first pass completed"), std::string::npos)
      << huge.output;
  EXPECT_LT(took, 10) << "the budget is 1 s";

  // Buffers re-signed (written by the encoder, so their checksums are right) with values no
  // honest render makes.
  ASSERT_EQ(test::run_command(cli("render " + kScene +
                                  " --res 8x8 --spp 4 --passes 2 -q "
                                  "--pass-range 0-0 --partial " +
                                  dir + "/a.rfb"))
                .exit_code,
            0);
  SampleBuffer a = read_buffer_file(dir + "/a.rfb");
  SampleBuffer negative = a, forever = a;
  negative.sum[4] = -1e300;
  forever.header.core_seconds = 1e308;
  write_buffer_file(dir + "/negative.rfb", negative);
  write_buffer_file(dir + "/forever.rfb", forever);
  for (const auto& [name, says] : std::vector<std::pair<std::string, std::string>>{
           {"negative", "a sum of radiance is negative"}, {"forever", "core_seconds"}}) {
    auto r = test::run_command(cli("merge " + dir + "/" + name + ".rfb -o " + dir + "/m.exr"));
    EXPECT_EQ(r.exit_code, 1) << r.output;
    EXPECT_NE(r.output.find(name + ".rfb: refused: " + says), std::string::npos) << r.output;
  }
}

// Against a silent coordinator (a port that completes TCP handshakes and never says a word),
// `worker --give-up-after 2` and `watch --timeout 3` give up on time: within a second of the
// limit plus the process's own start-up, measured here (about 0.2 s in a release build, over a
// second under the sanitizers on a loaded machine). Without the fix they took 10 s and 6.7 s.
TEST(Cli, ClientsGiveUpOnASilentCoordinatorOnTime) {
  int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  ASSERT_EQ(::listen(fd, 64), 0);  // never accepted: the kernel answers the handshake, no one else
  socklen_t len = sizeof addr;
  ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len);
  const std::string at = " --coordinator 127.0.0.1:" + std::to_string(ntohs(addr.sin_port));
  std::string dir = test::make_temp_dir("cli-silent");
  auto timed = [&](const std::string& args, double* seconds) {
    auto t0 = std::chrono::steady_clock::now();
    test::CommandResult r = test::run_command(cli(args + at));
    *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    return r;
  };
  double took = 0;
  auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(test::run_command(cli("--help")).exit_code, 0);
  const double startup =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  auto worker = timed("worker --give-up-after 2 --cache-dir " + dir, &took);
  EXPECT_EQ(worker.exit_code, 1) << worker.output;
  EXPECT_NE(worker.output.find("--give-up-after"), std::string::npos) << worker.output;
  EXPECT_LT(took, 2 + startup + 1) << "start-up " << startup << " s; " << worker.output;
  auto watch = timed("watch j000001 --timeout 3", &took);
  EXPECT_EQ(watch.exit_code, 1) << watch.output;
  EXPECT_NE(watch.output.find("--timeout"), std::string::npos) << watch.output;
  EXPECT_LT(took, 3 + startup + 1) << "start-up " << startup << " s; " << watch.output;
  ::close(fd);
}

// A coordinator whose state directory is on a full disk, or on a read-only one, says so and how
// to go on (before: the advice for a damaged database, exit 4; and "No such file or directory").
// Each runs in a mount namespace of its own on a small tmpfs; skipped where that is not allowed.
TEST(Cli, ACoordinatorOnAFullOrReadOnlyDiskSaysSo) {
  std::string dir = test::make_temp_dir("cli-disk");
  auto in_tmpfs = [&](const std::string& options, const std::string& then) {
    return test::run_command("unshare -m sh -c 'mount -t tmpfs -o " + options + " tmpfs " + dir +
                             " && " + then + "' 2>&1");
  };
  if (in_tmpfs("size=1m", "true").exit_code != 0)
    GTEST_SKIP() << "no mount namespace here (needs root or CAP_SYS_ADMIN)";
  const std::string start = test::rayfarm_binary() + " coordinator --listen 127.0.0.1:0 " +
                            "--state-dir " + dir + "/state";
  auto full = in_tmpfs("size=256k",
                       "dd if=/dev/zero of=" + dir + "/fill bs=4k count=100 2>/dev/null; " + start);
  EXPECT_EQ(full.exit_code, 1) << full.output;
  EXPECT_TRUE(full.output.find("disk is full") != std::string::npos ||
              full.output.find("No space left on device") != std::string::npos)
      << full.output;
  EXPECT_EQ(full.output.find("To recover"), std::string::npos) << "not a damaged database";
  auto ro = in_tmpfs("ro", start);
  EXPECT_EQ(ro.exit_code, 1) << ro.output;
  EXPECT_NE(ro.output.find("Read-only file system"), std::string::npos) << ro.output;
  EXPECT_NE(ro.output.find("writable --state-dir"), std::string::npos) << ro.output;
}

// `compare`: an image against itself has no error; against a differently seeded render of the
// same scene it has (relMSE of the two images' noise); a window is checked against the image.
TEST(Cli, CompareReportsTheErrorAndRefusesABadWindow) {
  std::string dir = test::make_temp_dir("cli-compare");
  std::string args = " --res 16x16 --spp 4 --passes 2 --max-depth 4 -q";
  ASSERT_EQ(test::run_command(cli("render " + kScene + " -o " + dir + "/a.exr" + args)).exit_code,
            0);
  ASSERT_EQ(test::run_command(cli("render " + kScene + " -o " + dir + "/b.exr --seed 5" + args))
                .exit_code,
            0);
  auto same = test::run_command(cli("compare " + dir + "/a.exr " + dir + "/a.exr"));
  ASSERT_EQ(same.exit_code, 0) << same.output;
  EXPECT_NE(same.output.find("rmse 0 relmse 0 mae 0"), std::string::npos) << same.output;
  auto other =
      test::run_command(cli("compare " + dir + "/a.exr " + dir + "/b.exr --window 0,0,8,8"));
  ASSERT_EQ(other.exit_code, 0) << other.output;
  double rmse = -1, rel = -1, mae = -1;
  ASSERT_EQ(std::sscanf(other.output.c_str(), "rmse %lf relmse %lf mae %lf", &rmse, &rel, &mae), 3)
      << other.output;
  EXPECT_GT(rmse, 0);
  EXPECT_GT(rel, 0);
  EXPECT_GT(mae, 0);
  auto bad =
      test::run_command(cli("compare " + dir + "/a.exr " + dir + "/b.exr --window 0,0,17,8"));
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
