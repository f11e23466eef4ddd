// The coordinator's scene check (coordinator/scene_check.h) and the importers' bounds on work
// (engine/import_limits.h): scene bombs a hostile client can submit cost it its submit, and never
// the coordinator. The bombs are the ones a probe of the farm found: JSON nested 100,000 deep in
// a glTF file's extras (it crashed the coordinator with SIGSEGV), pbrt and Mitsuba includes that
// fan out (10^9 parses), and scenes that outgrow a child's memory, CPU or wall time.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <future>
#include <sstream>
#include <thread>

#include "coordinator/core.h"
#include "coordinator/scene_check.h"
#include "engine/scene.h"
#include "engine/scene_summary.h"
#include "tests/support/farm.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

namespace fs = std::filesystem;
namespace pb = rayfarm::v1;

// ---- Bombs, made here rather than committed (the glTF one is 200 KB).

std::string nested_gltf(int depth) {
  return "{\"asset\": {\"version\": \"2.0\", \"extras\": " + std::string(size_t(depth), '[') +
         std::string(size_t(depth), ']') + "}}";
}

std::string nested_json_scene(int depth) {
  return "{\"format\": \"rayfarm-scene\", \"version\": 1, \"x\": " +
         std::string(size_t(depth), '[') + std::string(size_t(depth), ']') + "}";
}

std::string nested_xml(int depth) {
  std::string s = "<scene version=\"3.0.0\">";
  for (int i = 0; i < depth; ++i) s += "<a>";
  for (int i = 0; i < depth; ++i) s += "</a>";
  return s + "</scene>";
}

const char* kPbrtHead =
    "LookAt 0 0 5  0 0 0  0 1 0\nCamera \"perspective\"\n"
    "Film \"rgb\" \"integer xresolution\" 16 \"integer yresolution\" 16\nWorldBegin\n"
    "LightSource \"point\" \"rgb I\" [1 1 1]\nShape \"sphere\"\n";

// scene.pbrt includes f0.pbrt `fanout` times, f_i includes f_{i+1} `fanout` times, up to
// f_{levels-1}: fanout^levels parses of the last file.
std::vector<test::BundleFile> pbrt_fanout(int levels, int fanout) {
  std::vector<test::BundleFile> files{{"scene.pbrt", std::string(kPbrtHead)}};
  for (int k = 0; k < fanout; ++k) files[0].bytes += "Include \"f0.pbrt\"\n";
  for (int i = 0; i < levels; ++i) {
    std::string body = "# level " + std::to_string(i) + "\n";
    if (i + 1 < levels)
      for (int k = 0; k < fanout; ++k) body += "Include \"f" + std::to_string(i + 1) + ".pbrt\"\n";
    files.push_back({"f" + std::to_string(i) + ".pbrt", body});
  }
  return files;
}

std::vector<test::BundleFile> mitsuba_fanout(int levels, int fanout) {
  const std::string head =
      "<scene version=\"3.0.0\"><sensor type=\"perspective\"><film type=\"hdrfilm\">"
      "<integer name=\"width\" value=\"16\"/><integer name=\"height\" value=\"16\"/></film>"
      "</sensor><emitter type=\"constant\"/>";
  std::vector<test::BundleFile> files{{"scene.xml", head + "<include filename=\"f0.xml\"/>"
                                                           "</scene>"}};
  for (int i = 0; i < levels; ++i) {
    std::string body = "<scene version=\"3.0.0\">";
    if (i + 1 < levels)
      for (int k = 0; k < fanout; ++k)
        body += "<include filename=\"f" + std::to_string(i + 1) + ".xml\"/>";
    files.push_back({"f" + std::to_string(i) + ".xml", body + "</scene>"});
  }
  return files;
}

// A bundle on disk, as the coordinator materialises one.
std::string bundle_dir(const std::string& tag, const std::vector<test::BundleFile>& files) {
  std::string dir = test::make_temp_dir(tag) + "/bundle";
  for (const test::BundleFile& f : files) test::write_text(dir + "/" + f.path, f.bytes);
  return dir;
}

JobSpec spec_of(const std::string& scene_path) {
  JobSpec s;
  s.scene_path = scene_path;
  return s;
}

SceneCheckLimits test_limits() {
  SceneCheckLimits l;
  l.memory_mb = 1536;
  l.cpu_seconds = 30;
  l.wall_seconds = 60;
  return l;
}

// The check's refusal: its code and message (a test failure if it accepted).
struct Refusal {
  ErrorCode code = ErrorCode::Internal;
  std::string message;
};
Refusal refusal_of(const SceneChecker& check, const std::string& dir, const JobSpec& spec) {
  try {
    check(dir, spec);
    ADD_FAILURE() << spec.scene_path << " was accepted";
  } catch (const CoordinatorError& e) {
    return {e.code, e.what()};
  }
  return {};
}

bool has(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

// A stand-in for the rayfarm binary: a shell script run as `SCRIPT check-scenes --bundle ...`.
std::string fake_binary(const std::string& tag, const std::string& body) {
  std::string path = test::make_temp_dir(tag) + "/fake-rayfarm";
  test::write_text(path, "#!/bin/sh\n" + body + "\n");
  ::chmod(path.c_str(), 0755);
  return path;
}

std::string cornell_json() {
  std::ifstream in(test::source_dir() + "/scenes/cornell-box/scene.json");
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

// ---- The child: what it answers, and how it is refused.

// The child's summary is the engine's, field by field (the coordinator plans the job from it).
TEST(SceneCheck, TheChildSummarisesAsTheEngineDoes) {
  std::string dir = test::make_temp_dir("check-same");
  fs::copy(test::source_dir() + "/scenes/cornell-box", dir + "/bundle",
           fs::copy_options::recursive);
  JobSpec spec = spec_of("scene.json");
  spec.overrides.spp = 8;
  spec.overrides.passes = 2;
  spec.overrides.integrator = "bdpt";
  std::vector<SceneSummary> got =
      child_scene_checker(test::rayfarm_binary(), test_limits())(dir + "/bundle", spec);
  ASSERT_EQ(got.size(), 1u);
  SceneSummary want = summarize(load_scene(dir + "/bundle/scene.json", spec.overrides));
  EXPECT_EQ(got[0], want);
  EXPECT_TRUE(got[0].splats);
  EXPECT_EQ(got[0].spp_per_pass, 4u);
  EXPECT_EQ(in_process_scene_checker()(dir + "/bundle", spec)[0], want);
}

// A frame range over a per-frame pattern: one summary per distinct file, in frame order; a file
// that is refused is named, and its message names bundle paths only (no server directory).
TEST(SceneCheck, EveryFrameFileIsCheckedAndABadOneIsNamedWithoutServerPaths) {
  std::string good = cornell_json();
  std::string dir = test::make_temp_dir("check-frames");
  fs::copy(test::source_dir() + "/scenes/cornell-box", dir + "/bundle",
           fs::copy_options::recursive);
  fs::copy_file(dir + "/bundle/scene.json", dir + "/bundle/shot.0001.json");
  fs::copy_file(dir + "/bundle/scene.json", dir + "/bundle/shot.0002.json");
  JobSpec spec = spec_of("shot.####.json");
  spec.frames = "2,1";
  EXPECT_EQ(job_scene_paths(spec), (std::vector<std::string>{"shot.0002.json", "shot.0001.json"}));
  SceneChecker check = child_scene_checker(test::rayfarm_binary(), test_limits());
  EXPECT_EQ(check(dir + "/bundle", spec).size(), 2u);
  test::write_text(dir + "/bundle/shot.0002.json",
                   "{\"format\": \"rayfarm-scene\", \"camera\": 3}");
  Refusal r = refusal_of(check, dir + "/bundle", spec);
  EXPECT_EQ(r.code, ErrorCode::InvalidArgument);
  EXPECT_TRUE(has(r.message, "shot.0002.json")) << r.message;
  EXPECT_FALSE(has(r.message, dir)) << r.message;
}

// Nesting bombs: refused before a recursive reader sees them, naming the file, the line and the
// bound, locally (render's import) and in the child. Before the bound, the glTF one crashed the
// importer with SIGSEGV (tinygltf's recursive JSON reader).
TEST(SceneCheck, NestingBombsAreRefusedNamingFileLineAndBound) {
  struct Case {
    std::string file, bytes;
  } cases[] = {{"deep.gltf", nested_gltf(100000)},
               {"deep.json", nested_json_scene(100000)},
               {"deep.xml", nested_xml(100000)},
               {"deep.pbrt", std::string(kPbrtHead) + [] {
                  std::string s;
                  for (int i = 0; i < 100000; ++i) s += "AttributeBegin\n";
                  return s;
                }()}};
  SceneChecker check = child_scene_checker(test::rayfarm_binary(), test_limits());
  for (const Case& c : cases) {
    std::string dir = bundle_dir("check-nest", {{c.file, c.bytes}});
    try {
      load_scene(dir + "/" + c.file);
      ADD_FAILURE() << c.file << " was imported";
    } catch (const SceneError& e) {
      EXPECT_TRUE(has(e.what(), c.file)) << e.what();
      EXPECT_TRUE(has(e.what(), "nested more than 512")) << e.what();
    }
    Refusal r = refusal_of(check, dir, spec_of(c.file));
    EXPECT_EQ(r.code, ErrorCode::InvalidArgument) << r.message;
    EXPECT_TRUE(has(r.message, c.file + ":")) << r.message;
    EXPECT_TRUE(has(r.message, "the import limit on nesting")) << r.message;
  }
  // 500 levels are within the bound.
  std::string dir = bundle_dir("check-nest-ok", {{"ok.json", nested_json_scene(500)}});
  try {
    load_scene(dir + "/ok.json");
  } catch (const SceneError& e) {
    EXPECT_FALSE(has(e.what(), "nested")) << e.what();  // refused for its missing camera only
  }
}

// Include fan-out: every read counts against import_files, so 10 files that each include the
// next 10 times (10^9 parses) are refused after 10,000 reads, naming the include and the bound.
// With the bound lifted, the child's CPU and wall budgets stop the work instead.
TEST(SceneCheck, IncludeFanOutIsBoundedByFileReadsThenByTheChildsBudget) {
  for (const auto& [scene, files] : {std::pair{std::string("scene.pbrt"), pbrt_fanout(10, 10)},
                                     std::pair{std::string("scene.xml"), mitsuba_fanout(9, 10)}}) {
    std::string dir = bundle_dir("check-fanout", files);
    auto t0 = std::chrono::steady_clock::now();
    Refusal r =
        refusal_of(child_scene_checker(test::rayfarm_binary(), test_limits()), dir, spec_of(scene));
    double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(r.code, ErrorCode::InvalidArgument) << r.message;
    EXPECT_TRUE(has(r.message, "more than 10000 file reads (the import limit files")) << r.message;
    EXPECT_LT(took, 30) << "10,000 small reads, not 10^9";

    SceneCheckLimits cpu = test_limits();
    cpu.import.files = uint64_t(1) << 40;
    cpu.cpu_seconds = 2;
    r = refusal_of(child_scene_checker(test::rayfarm_binary(), cpu), dir, spec_of(scene));
    EXPECT_EQ(r.code, ErrorCode::ResourceExhausted) << r.message;
    EXPECT_TRUE(has(r.message, "scene '" + scene + "'")) << r.message;
    // Mitsuba keeps every included document, so its fan-out may run out of memory first.
    EXPECT_TRUE(has(r.message, "parse_cpu_seconds") || has(r.message, "parse_memory_mb"))
        << r.message;

    SceneCheckLimits wall = cpu;
    wall.cpu_seconds = 1000;
    wall.wall_seconds = 2;
    r = refusal_of(child_scene_checker(test::rayfarm_binary(), wall), dir, spec_of(scene));
    EXPECT_EQ(r.code, ErrorCode::ResourceExhausted) << r.message;
    EXPECT_TRUE(has(r.message, "parse_wall_seconds") || has(r.message, "parse_memory_mb"))
        << r.message;
  }
}

// A scene that needs more memory than the child's address space is refused naming the budget;
// one that fits is not.
TEST(SceneCheck, AnImportOverTheMemoryBudgetIsRefusedNamingIt) {
  if (test::kAddressSanitizer) GTEST_SKIP() << "ASan reserves terabytes of address space";
  std::string shapes;
  for (int i = 0; i < 4; ++i)
    shapes += std::string(i ? "," : "") +
              "{\"type\": \"sphere\", \"material\": \"m\", \"tessellation\": [4000, 4000]}";
  std::string scene =
      "{\"format\": \"rayfarm-scene\", \"version\": 1, \"camera\": {\"fov_deg\": 40, "
      "\"look_at\": {\"eye\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}, "
      "\"film\": {\"resolution\": [16, 16]}, "
      "\"materials\": {\"m\": {\"type\": \"diffuse\", \"reflectance\": [0.5, 0.5, 0.5]}}, "
      "\"shapes\": [" +
      shapes +
      "], \"lights\": [{\"type\": \"point\", \"position\": [0, 0, 5], "
      "\"intensity\": [1, 1, 1]}]}";
  std::string dir = bundle_dir("check-memory", {{"big.json", scene}});
  SceneCheckLimits l = test_limits();
  l.memory_mb = 1024;
  Refusal r = refusal_of(child_scene_checker(test::rayfarm_binary(), l), dir, spec_of("big.json"));
  EXPECT_EQ(r.code, ErrorCode::ResourceExhausted) << r.message;
  EXPECT_TRUE(has(r.message, "scene 'big.json'")) << r.message;
  EXPECT_TRUE(has(r.message, "1024 MiB of memory (the limit parse_memory_mb)")) << r.message;
}

// The parent's side against children that misbehave: one that crashes, one that hangs, one that
// answers part of the job and dies. Each is a refusal naming the scene and the budget; the
// caller (the coordinator) goes on.
TEST(SceneCheck, AChildThatCrashesHangsOrStopsShortIsARefusalNamingTheScene) {
  std::string dir = bundle_dir("check-fake", {{"a.json", "{}"}, {"b.json", "{}"}});
  JobSpec spec = spec_of("#.json");
  spec.frames = "0";
  spec.scene_path = "a.json";
  SceneCheckLimits l = test_limits();
  Refusal r =
      refusal_of(child_scene_checker(fake_binary("fake-segv", "kill -SEGV $$"), l), dir, spec);
  EXPECT_EQ(r.code, ErrorCode::InvalidArgument);
  EXPECT_TRUE(has(r.message, "scene 'a.json': the importer crashed (SIGSEGV)")) << r.message;
  EXPECT_TRUE(has(r.message, "parse_memory_mb")) << r.message;

  l.wall_seconds = 1;
  auto t0 = std::chrono::steady_clock::now();
  r = refusal_of(child_scene_checker(fake_binary("fake-hang", "exec sleep 60"), l), dir, spec);
  double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.code, ErrorCode::ResourceExhausted);
  EXPECT_TRUE(has(r.message, "stopped after 1 s (the limit parse_wall_seconds)")) << r.message;
  EXPECT_LT(took, 5);

  // Two files; the child answers for the first and exits.
  JobSpec two = spec_of("x.json");
  two.frames = "1-2";
  two.scene_path = "#.json";
  fs::copy_file(dir + "/a.json", dir + "/1.json");
  fs::copy_file(dir + "/a.json", dir + "/2.json");
  std::string summary =
      to_json(SceneSummary{"d", 1, "path", "s", 4, 4, {}, 1, 1, 1, 0, false}).dump();
  r = refusal_of(
      child_scene_checker(
          fake_binary("fake-short", "echo '{\"scene\": 0, \"summary\": " + summary + "}'; exit 3"),
          test_limits()),
      dir, two);
  EXPECT_EQ(r.code, ErrorCode::InvalidArgument);
  EXPECT_TRUE(has(r.message, "scene '2.json': the scene check exited with status 3")) << r.message;
}

// At most parse_children checks run at once; the others wait their turn.
TEST(SceneCheck, ChecksBeyondParseChildrenWaitTheirTurn) {
  std::string dir = bundle_dir("check-gate", {{"a.json", "{}"}});
  SceneCheckLimits l = test_limits();
  l.children = 1;
  std::string marks = test::make_temp_dir("check-gate-marks");
  // Each child notes its start and end; with one slot no two overlap.
  SceneChecker check = child_scene_checker(
      fake_binary("fake-slow", "echo start >> " + marks + "/log; sleep 0.3; echo end >> " + marks +
                                   "/log; echo '{\"ok\": true}'"),
      l);
  std::vector<std::future<void>> runs;
  for (int i = 0; i < 3; ++i)
    runs.push_back(std::async(std::launch::async, [&] {
      try {
        check(dir, spec_of("a.json"));
      } catch (const CoordinatorError&) {  // "answered 0 scenes" is fine: only the order matters
      }
    }));
  for (auto& r : runs) r.get();
  std::ifstream in(marks + "/log");
  std::string line, order;
  while (std::getline(in, line)) order += line + " ";
  EXPECT_EQ(order, "start end start end start end ");
}

// The budgets are set by name (`coordinator --limit`), and a budget of 0 is refused.
TEST(SceneCheck, BudgetsAreSetByNameAndZeroIsRefused) {
  JobLimits l;
  EXPECT_TRUE(l.set("parse_memory_mb", 2048));
  EXPECT_TRUE(l.set("parse_cpu_seconds", 7));
  EXPECT_TRUE(l.set("parse_wall_seconds", 9));
  EXPECT_TRUE(l.set("parse_children", 3));
  EXPECT_TRUE(l.set("import_files", 11));
  EXPECT_TRUE(l.set("import_bytes", 12));
  EXPECT_TRUE(l.set("import_elements", 13));
  EXPECT_EQ(l.scene_check.memory_mb, 2048u);
  EXPECT_EQ(l.scene_check.cpu_seconds, 7u);
  EXPECT_EQ(l.scene_check.wall_seconds, 9u);
  EXPECT_EQ(l.scene_check.children, 3u);
  EXPECT_EQ(l.scene_check.import.files, 11u);
  EXPECT_EQ(l.scene_check.import.bytes, 12u);
  EXPECT_EQ(l.scene_check.import.elements, 13u);
  EXPECT_FALSE(l.set("import_nothing", 1));
  EXPECT_THROW(l.set("parse_cpu_seconds", 0), std::invalid_argument);
  EXPECT_THROW(l.set("parse_memory_mb", 1000), std::invalid_argument);
  for (const std::string& n : JobLimits::names()) EXPECT_TRUE(l.set(n, 2048)) << n;
}

// ---- The importers' other bounds.

TEST(ImportLimits, BytesAndElementsAreBoundedNamingTheFileAndTheBound) {
  std::string dir = test::make_temp_dir("import-limits");
  fs::copy(test::source_dir() + "/scenes/cornell-box", dir + "/cb", fs::copy_options::recursive);
  load_scene(dir + "/cb/scene.json");  // within the defaults
  ImportLimits bytes;
  bytes.bytes = 4096;
  try {
    load_scene(dir + "/cb/scene.json", {}, bytes);
    ADD_FAILURE() << "read past the bytes bound";
  } catch (const SceneError& e) {
    EXPECT_TRUE(has(e.what(), "cb/scene.json")) << e.what();
    EXPECT_TRUE(has(e.what(), "(the import limit bytes)")) << e.what();
  }
  ImportLimits elements;
  elements.elements = 5;
  try {
    load_scene(dir + "/cb/scene.json", {}, elements);
    ADD_FAILURE() << "more elements than the bound";
  } catch (const SceneError& e) {
    EXPECT_TRUE(has(e.what(), "the import limit elements is 5")) << e.what();
  }
  // An emissive object placed many times: its world-space copies count, triangle by triangle.
  std::string shapes;
  for (int i = 0; i < 100; ++i)
    shapes += std::string(i ? "," : "") +
              "{\"object\": \"lamp\", \"transform\": {\"translate\": [" + std::to_string(i) +
              ", 0, 0]}}";
  std::string scene =
      "{\"format\": \"rayfarm-scene\", \"version\": 1, \"camera\": {\"fov_deg\": 40, "
      "\"look_at\": {\"eye\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}, "
      "\"film\": {\"resolution\": [16, 16]}, "
      "\"materials\": {\"m\": {\"type\": \"diffuse\", \"reflectance\": [0.5, 0.5, 0.5]}}, "
      "\"objects\": [{\"name\": \"lamp\", \"shapes\": [{\"type\": \"sphere\", \"material\": "
      "\"m\", \"tessellation\": [64, 128], \"emission\": {\"radiance\": [1, 1, 1]}}]}], "
      "\"shapes\": [], \"instances\": [" +
      shapes + "]}";
  test::write_text(dir + "/lamps.json", scene);
  ImportLimits copies;
  copies.elements = 100000;
  try {
    Scene s = load_scene(dir + "/lamps.json", {}, copies);
    ADD_FAILURE() << "copied " << s.meshes.size() << " emitters past the bound";
  } catch (const SceneError& e) {
    EXPECT_TRUE(has(e.what(), "placed 100 times")) << e.what();
    EXPECT_TRUE(has(e.what(), "the import limit elements is 100000")) << e.what();
  }
  EXPECT_EQ(load_scene(dir + "/lamps.json").meshes.size(), 100u);
}

// Scene input the probe found unclear: a tessellation of 16384 x 16384 (was "out of memory"
// with no file or field), a NUL in a pbrt Include (the message stopped at the NUL, before the
// reason), and a blackbody of 1e30 K (rendered without a word).
TEST(ImportLimits, ProbeScenesAreRefusedOrWarnedAboutByName) {
  std::string dir = test::make_temp_dir("import-probe");
  test::write_text(dir + "/tess.json",
                   "{\"format\": \"rayfarm-scene\", \"version\": 1, \"camera\": {\"fov_deg\": 40, "
                   "\"look_at\": {\"eye\": [0, 0, 5], \"target\": [0, 0, 0], \"up\": [0, 1, 0]}}, "
                   "\"film\": {\"resolution\": [8, 8]}, \"materials\": {\"m\": {\"type\": "
                   "\"diffuse\", \"reflectance\": [0.5, 0.5, 0.5]}}, \"shapes\": [{\"type\": "
                   "\"sphere\", \"material\": \"m\", \"tessellation\": [16384, 16384]}]}");
  try {
    load_scene(dir + "/tess.json");
    ADD_FAILURE() << "a 16384 x 16384 tessellation was accepted";
  } catch (const SceneError& e) {
    EXPECT_TRUE(has(e.what(), "tess.json: shapes[0].tessellation: 16384 x 16384 makes "))
        << e.what();
    EXPECT_TRUE(has(e.what(), "at most 16777216")) << e.what();
  }
  std::string include = "Include \"a";
  include += '\0';
  include += "b.pbrt\"\n";
  test::write_text(dir + "/nul.pbrt", std::string(kPbrtHead) + include);
  try {
    load_scene(dir + "/nul.pbrt");
    ADD_FAILURE() << "a NUL was accepted";
  } catch (const SceneError& e) {
    EXPECT_TRUE(has(e.what(), "nul.pbrt:7: a NUL byte (pbrt scene files are text)")) << e.what();
  }
  test::write_text(dir + "/hot.pbrt",
                   std::string(kPbrtHead) +
                       "AttributeBegin\nAreaLightSource \"diffuse\" \"blackbody L\" [1e30]\n"
                       "Shape \"sphere\" \"float radius\" 0.1\nAttributeEnd\n");
  Scene hot = load_scene(dir + "/hot.pbrt");
  bool warned = false;
  for (const std::string& w : hot.warnings) warned |= has(w, "outside 500..100000 K");
  EXPECT_TRUE(warned) << "no warning for 1e30 K";
}

// Mitsuba's exact spheres carry no mesh, so 50,000 of them import in well under a second of
// work per 10,000 (docs/performance.md has the times); XML paths are qualified in one pass.
TEST(ImportLimits, MitsubaSpheresAreExactWithoutAMeshEach) {
  std::string s =
      "<scene version=\"3.0.0\"><sensor type=\"perspective\"><film type=\"hdrfilm\"><integer "
      "name=\"width\" value=\"16\"/><integer name=\"height\" value=\"16\"/></film></sensor>"
      "<emitter type=\"constant\"/>";
  for (int i = 0; i < 2000; ++i)
    s += "<shape type=\"sphere\"><point name=\"center\" x=\"" + std::to_string(i) +
         "\" y=\"0\" z=\"0\"/><float name=\"radius\" value=\"0.1\"/></shape>";
  s += "<shape type=\"sphere\"><transform name=\"to_world\"><scale x=\"1\" y=\"2\" z=\"1\"/>"
       "</transform></shape></scene>";
  std::string dir = test::make_temp_dir("mitsuba-spheres");
  test::write_text(dir + "/s.xml", s);
  Scene scene = load_scene(dir + "/s.xml");
  ASSERT_EQ(scene.meshes.size(), 2001u);
  for (size_t i = 0; i < 2000; ++i) {
    EXPECT_TRUE(scene.meshes[i].sphere.has_value());
    EXPECT_TRUE(scene.meshes[i].positions.empty()) << i;
  }
  EXPECT_FALSE(scene.meshes[2000].sphere.has_value());  // a stretched sphere is a mesh
  EXPECT_EQ(scene.meshes[2000].triangle_count(), 2u * 64 * 128 - 2 * 128);
}

// ---- Against a real coordinator.

// The bombs over the wire: each submit is refused with its code, the coordinator's memory stays
// near its own (the child's is bounded by parse_memory_mb), and it serves a real job afterwards.
TEST(SceneCheck, HostileSubmitsCostTheirSubmitAndTheCoordinatorServesOn) {
  test::Farm farm("check-farm", 30, "",
                  {"--limit", "parse_cpu_seconds=3", "--limit", "parse_memory_mb=1536"});
  auto jobs = pb::JobService::NewStub(farm.channel());
  grpc::Status st = test::submit_files(*jobs, "deep.gltf", {{"deep.gltf", nested_gltf(100000)}});
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << st.error_message();
  EXPECT_TRUE(has(st.error_message(), "deep.gltf: line 1")) << st.error_message();
  EXPECT_FALSE(has(st.error_message(), farm.dir())) << st.error_message();

  st = test::submit_files(*jobs, "scene.pbrt", pbrt_fanout(10, 10));
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << st.error_message();
  EXPECT_TRUE(has(st.error_message(), "import limit files")) << st.error_message();
  EXPECT_FALSE(has(st.error_message(), farm.dir())) << st.error_message();
  farm.stop_coordinator();

  // With the file bound lifted, the CPU budget ends the fan-out.
  test::Farm lifted("check-farm-cpu", 30, "",
                    {"--limit", "parse_cpu_seconds=3", "--limit", "import_files=1000000000000"});
  auto jobs2 = pb::JobService::NewStub(lifted.channel());
  st = test::submit_files(*jobs2, "scene.pbrt", pbrt_fanout(10, 10));
  EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << st.error_message();
  EXPECT_TRUE(has(st.error_message(), "scene 'scene.pbrt'")) << st.error_message();
  EXPECT_TRUE(has(st.error_message(), "parse_cpu_seconds")) << st.error_message();
  if (!test::kAddressSanitizer) {
    long peak = test::proc_status_kib(lifted.coordinator().pid(), "VmHWM");
    EXPECT_GT(peak, 0);
    EXPECT_LT(peak, 400 * 1024) << "the coordinator's own peak RSS, KB";
  }
  // Still serving: a real job renders to the end, and its frame equals the local render.
  std::string job = lifted.submit("scenes/cornell-box/scene.json --spp 4 --passes 2 --res 32x32");
  lifted.worker();
  test::CommandResult w = lifted.client("watch " + job + " --timeout 120");
  EXPECT_EQ(w.exit_code, 0) << w.output;
  EXPECT_TRUE(lifted.coordinator().running());
}

}  // namespace
}  // namespace rf
