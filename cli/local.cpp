// The local commands: render, merge, compare, bench (DESIGN.md "Local single-node runs").
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <optional>
#include <regex>

#include <spdlog/spdlog.h>
#include "bench/bench.h"
#include "cli/commands.h"
#include "engine/buffer_file.h"
#include "engine/buffer_merge.h"
#include "engine/image_io.h"
#include "engine/local_render.h"
#include "engine/progress.h"
#include "engine/render.h"
#include "farm/frame_range.h"

namespace rf::cli {

namespace {

std::pair<uint32_t, uint32_t> parse_pass_range(const std::string& s, uint32_t passes) {
  // Digits only: sscanf's %u would read "-1" as 4294967295.
  std::smatch m;
  if (!std::regex_match(s, m, std::regex("([0-9]{1,9})(?:-([0-9]{1,9}))?")))
    throw UsageError("--pass-range: expected FIRST-LAST (inclusive, e.g. 0-7), got '" + s + "'");
  uint32_t a = uint32_t(std::stoul(m[1])), b = m[2].matched ? uint32_t(std::stoul(m[2])) : a;
  if (a > b)
    throw UsageError("--pass-range: first pass " + std::to_string(a) + " is after last " +
                     std::to_string(b));
  if (b >= passes)
    throw UsageError("--pass-range: pass " + std::to_string(b) + " does not exist (the job has " +
                     std::to_string(passes) + " passes, 0-" + std::to_string(passes - 1) + ")");
  return {a, b + 1};
}

std::string human(double v) {
  char buf[32];
  if (v >= 1e9)
    std::snprintf(buf, sizeof buf, "%.2f G", v / 1e9);
  else if (v >= 1e6)
    std::snprintf(buf, sizeof buf, "%.2f M", v / 1e6);
  else if (v >= 1e3)
    std::snprintf(buf, sizeof buf, "%.2f k", v / 1e3);
  else
    std::snprintf(buf, sizeof buf, "%.0f ", v);
  return buf;
}

// Progress: on stderr, a bar with the ETA redrawn in place on a terminal, plain lines every 5 s
// otherwise; or (--progress openjd) Open Job Description lines on stdout, `openjd_progress:
// PERCENT` over all the frames of the render (frame `index` of `count`).
class ProgressPrinter {
 public:
  ProgressPrinter(bool quiet, bool openjd, size_t index, size_t count)
      : quiet_(quiet), openjd_(openjd), tty_(::isatty(2)), index_(index), count_(count) {}
  void operator()(const LocalProgress& p) {
    if (p.tasks_total == 0) return;
    double frac = double(p.tasks_done) / double(p.tasks_total);
    if (openjd_) {  // whatever --quiet says: a job runner reads these
      // A frame stopped early (noise target, time budget) is a frame done.
      double percent =
          std::floor(1000.0 * (double(index_) + (p.finished ? 1.0 : frac)) / double(count_)) / 10;
      if (percent != last_percent_) std::printf("openjd_progress: %.1f\n", percent);
      std::fflush(stdout);
      last_percent_ = percent;
      return;
    }
    if (quiet_) return;
    // The time per task so far, over the tasks left (a noise target may stop sooner).
    const std::string eta = p.finished ? "done"
                            : frac > 0 ? "ETA " + duration_text(p.seconds * (1 - frac) / frac)
                                       : "ETA ?";
    if (tty_) {
      int width = 30, filled = int(frac * width);
      std::string bar(size_t(filled), '#');
      bar.append(size_t(width - filled), '.');
      std::fprintf(stderr, "\r[%s] %5.1f%%  passes %u/%u  relMSE %.3g  %.1f s  %s   ", bar.c_str(),
                   100 * frac, p.passes_merged, p.passes_total, p.rel_mse, p.seconds, eta.c_str());
      if (p.finished) std::fprintf(stderr, "\n");
    } else if (p.seconds - last_line_ >= 5.0 || p.finished) {
      last_line_ = p.seconds;
      std::fprintf(stderr, "progress: %.1f%% tasks, passes %u/%u, relMSE %.3g, %.1f s, %s\n",
                   100 * frac, p.passes_merged, p.passes_total, p.rel_mse, p.seconds, eta.c_str());
    }
  }

 private:
  bool quiet_, openjd_, tty_;
  size_t index_, count_;
  double last_line_ = -1e9, last_percent_ = -1;
};

std::string png_path_for(const std::string& exr) {
  std::filesystem::path p(exr);
  p.replace_extension(".png");
  return p.string();
}

void warn_nonfinite(const SampleBuffer& b) {
  if (b.nonfinite_samples)
    spdlog::warn("{} NaN/Inf samples were dropped (counted as zero radiance)", b.nonfinite_samples);
}

void print_summary(const FrameBands& frame, double seconds, uint64_t rays) {
  const SampleBuffer& info = frame.info();
  double spp = samples_per_pixel(frame);
  double samples = spp * double(info.rect.area());
  std::printf("spp %.0f | %.2f s | %ssamples/s | %srays/s | relMSE %.4g (%u passes)\n", spp,
              seconds, human(samples / seconds).c_str(), human(double(rays) / seconds).c_str(),
              frame.rel_mse(), info.header.passes.count());
}

// A double for JSON: null when it is not finite (JSON has no NaN).
nlohmann::json number_or_null(double v) { return std::isfinite(v) ? nlohmann::json(v) : nullptr; }

// The summary as one JSON line (render --json): a frame's figures and the files written.
nlohmann::json summary_json(const FrameBands& frame, double seconds, uint64_t rays) {
  const SampleBuffer& info = frame.info();
  double spp = samples_per_pixel(frame);
  uint32_t passes = info.header.passes.count();
  return {{"spp", spp},
          {"seconds", seconds},
          {"samples_per_second", number_or_null(spp * double(info.rect.area()) / seconds)},
          {"rays_per_second", number_or_null(double(rays) / seconds)},
          {"rays", rays},
          {"passes", passes},
          {"rel_mse", passes >= 2 ? number_or_null(frame.rel_mse()) : nullptr}};
}

// The default of render --memory: a quarter of the machine's memory (a frame held whole may need
// about twice its size with a pass of results in flight).
uint64_t default_memory_budget() {
  long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGESIZE);
  if (pages <= 0 || page <= 0) return uint64_t(4) << 30;
  return uint64_t(pages) * uint64_t(page) / 4;
}

struct RenderArgs {
  std::string scene, output, partial, pass_range, frames, spill_dir;
  uint64_t memory = 0;  // 0: default_memory_budget()
  OverrideArgs overrides;
  std::optional<FrameNumber> frame;
  double time_budget = 0;
  int tile = 32;
  float exposure = 0;
  bool quiet = false;
  bool json = false;  // the summary as JSON lines on stdout
  bool png = true;    // --no-png: the EXR only
  bool half = false;  // half-float EXR
  std::string progress = "text";
};

// One frame of a render: its number and its files (the scene, -o and --partial expanded).
struct FrameFiles {
  FrameNumber frame;
  std::string scene, output, partial;
};

// The frames a render covers (--frame, --frames, or frame 0) and their files. Several frames need
// a frame template in every output; the scene may be one file or a per-frame pattern.
std::vector<FrameFiles> frame_files(const RenderArgs& a) {
  if (a.frame && !a.frames.empty()) throw UsageError("render: give --frame or --frames, not both");
  std::vector<FrameNumber> frames;
  if (a.frames.empty()) {
    frames = {a.frame.value_or(0)};
  } else {
    try {
      frames = parse_frame_range(a.frames);
    } catch (const FrameRangeError& e) {
      throw UsageError(std::string("--frames: ") + e.what());
    }
  }
  if (frames.size() > 1)
    for (const auto& [flag, path] : {std::pair{"-o", a.output}, std::pair{"--partial", a.partial}})
      if (!path.empty() && !is_frame_pattern(path, true))
        throw UsageError(std::string(flag) + " " + path + ": " + std::to_string(frames.size()) +
                         " frames need a frame template in the name (shot.####.exr or "
                         "shot.%04d.exr)");
  std::vector<FrameFiles> files;
  for (FrameNumber f : frames)
    files.push_back({f, expand_frame_pattern(a.scene, f), expand_frame_pattern(a.output, f, true),
                     expand_frame_pattern(a.partial, f, true)});
  return files;
}

// Renders one frame of a loaded scene and writes its files.
void render_frame(const RenderArgs& a, const Scene& scene, const Renderer& renderer,
                  const FrameFiles& f, size_t index, size_t count) {
  const bool name_frame = count > 1;
  LocalRenderOptions opt;
  opt.tile_size = a.tile;
  opt.frame = f.frame;
  if (!a.pass_range.empty()) {
    auto [p0, p1] = parse_pass_range(a.pass_range, scene.render.passes);
    opt.first_pass = p0;
    opt.pass_count = p1 - p0;
    if (scene.render.noise_target > 0 && !a.partial.empty())
      spdlog::warn("--noise-target is ignored for a partial render: the merge decides");
  }
  if (a.partial.empty()) opt.noise_target = scene.render.noise_target;
  opt.time_budget_s = a.time_budget;
  opt.memory_budget = a.memory ? a.memory : default_memory_budget();
  // Beside the output by default: /tmp is often a RAM disk, which would defeat the point.
  opt.spill_dir = a.spill_dir;
  if (opt.spill_dir.empty()) {
    std::filesystem::path beside =
        std::filesystem::path(f.output.empty() ? f.partial : f.output).parent_path();
    opt.spill_dir = beside.empty() ? "." : beside.string();
  }
  ProgressPrinter printer(a.quiet, a.progress == "openjd", index, count);
  opt.progress = [&](const LocalProgress& p) { printer(p); };
  if (name_frame && !a.quiet) std::fprintf(stderr, "frame %d\n", f.frame);
  if (a.progress == "openjd")
    std::printf("openjd_status: rendering frame %d (%zu of %zu)\n", f.frame, index + 1, count);
  LocalRenderResult res;
  try {
    res = render_local(renderer, opt);
  } catch (const std::bad_alloc&) {
    double gib = double(scene.film.width) * double(scene.film.height) *
                 double(FrameAccumulator::bytes_per_pixel(scene.render.aovs)) / double(1 << 30);
    char buf[240];
    std::snprintf(buf, sizeof buf,
                  "out of memory rendering a %dx%d film (about %.1f GiB for the frame, held "
                  "whole up to --memory %.1f GiB; give a smaller --memory to keep it in tiles "
                  "on disk)",
                  scene.film.width, scene.film.height, gib,
                  double(opt.memory_budget) / double(1 << 30));
    throw std::runtime_error(f.scene + ": " + buf);
  }
  if (res.passes_merged == 0 && res.stopped_on_time)
    throw std::runtime_error(
        f.scene + ": the time budget of " + std::to_string(a.time_budget) +
        " s ran out before the first pass completed (a pass here is " +
        std::to_string(scene.render.spp_per_pass()) +
        " samples per pixel); nothing is written. Give more --passes, fewer --spp or more time");
  warn_nonfinite(res.frame);
  const WholeFrame whole(res.frame);
  const FrameBands& image = res.tiles ? static_cast<const FrameBands&>(*res.tiles) : whole;
  for (const std::string& path : {f.partial, f.output})  // out/shot.####.exr: out/ made here
    if (std::filesystem::path parent = std::filesystem::path(path).parent_path(); !parent.empty())
      std::filesystem::create_directories(parent);
  if (!f.partial.empty()) {
    write_buffer_file(f.partial, image);
    std::fprintf(stderr, "wrote %s (passes %s)\n", f.partial.c_str(),
                 res.frame.header.passes.to_string().c_str());
  }
  if (!f.output.empty()) {
    write_exr(f.output, image, {}, a.half ? ExrFormat::Half : ExrFormat::Float);
    if (a.png) write_png(png_path_for(f.output), image, a.exposure);
    if (!a.quiet)
      std::fprintf(stderr, "wrote %s%s\n", f.output.c_str(),
                   a.png ? (" and " + png_path_for(f.output)).c_str() : "");
  }
  if (res.stopped_on_target)
    std::fprintf(stderr, "noise target %.4g reached after %u of %u passes\n",
                 scene.render.noise_target, res.passes_merged, scene.render.passes);
  if (res.stopped_on_time)
    std::fprintf(stderr, "time budget %.1f s reached after %u of %u passes\n", a.time_budget,
                 res.passes_merged, scene.render.passes);
  if (a.json) {
    nlohmann::json line = summary_json(image, res.seconds, res.rays);
    line["frame"] = f.frame;
    line["scene"] = f.scene;
    line["exr"] = f.output.empty() ? nullptr : nlohmann::json(f.output);
    line["png"] = f.output.empty() || !a.png ? nullptr : nlohmann::json(png_path_for(f.output));
    line["partial"] = f.partial.empty() ? nullptr : nlohmann::json(f.partial);
    line["stopped_on_target"] = res.stopped_on_target;
    line["stopped_on_time"] = res.stopped_on_time;
    std::printf("%s\n", line.dump().c_str());
    std::fflush(stdout);
  } else if (a.progress != "openjd") {
    print_summary(image, res.seconds, res.rays);
  }
}

// A frame, or a frame range: frames of one scene file share its parse and its BVH (a frame only
// selects the seed stream); a per-frame pattern loads each frame's file. Every name is checked
// and every per-frame scene file found before the first frame renders.
int cmd_render(const RenderArgs& a) {
  SceneOverrides ov = overrides_of(a.overrides);
  if (a.output.empty() && a.partial.empty())
    throw UsageError("render: give -o OUT.exr or --partial OUT.rfb");
  if (!a.partial.empty() && a.pass_range.empty())
    throw UsageError("--partial needs --pass-range FIRST-LAST");
  if (!a.output.empty()) check_extension("-o", a.output, {".exr"});
  const std::vector<FrameFiles> frames = frame_files(a);
  // Each frame's names (distinct frames get distinct names from a template).
  for (const FrameFiles& f : frames)
    check_outputs({{"-o", f.output},
                   {"the PNG preview", f.output.empty() || !a.png ? "" : png_path_for(f.output)},
                   {"--partial", f.partial}});
  if (frames.size() > 1 && is_frame_pattern(a.scene))
    for (const FrameFiles& f : frames) {
      std::error_code ec;
      if (!std::filesystem::is_regular_file(f.scene, ec))
        throw std::runtime_error(f.scene + ": frame " + std::to_string(f.frame) +
                                 "'s scene file does not exist (scene pattern " + a.scene +
                                 "); nothing is rendered");
    }

  std::unique_ptr<Scene> scene;
  std::unique_ptr<Renderer> renderer;
  for (const FrameFiles& f : frames) {
    if (!scene || f.scene != scene->path) {
      renderer.reset();
      const auto t0 = std::chrono::steady_clock::now();
      scene = std::make_unique<Scene>(load_scene(f.scene, ov));
      const auto t1 = std::chrono::steady_clock::now();
      renderer = std::make_unique<Renderer>(*scene);
      if (frames.size() > 1)  // a shot's set-up, against the frames' own (bench/motion.sh)
        spdlog::info("{}: parsed in {:.3f} s, renderer set up in {:.3f} s", f.scene,
                     std::chrono::duration<double>(t1 - t0).count(),
                     std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count());
      if (!renderer->has_lights() && integrator_needs_lights(scene->render.integrator.method))
        spdlog::warn(
            "{}: the scene has no lights (no emitter, light or environment): the {} image "
            "will be black",
            f.scene, scene->render.integrator.type());
    }
    render_frame(a, *scene, *renderer, f, size_t(&f - frames.data()), frames.size());
  }
  if (a.progress == "openjd")
    std::printf("openjd_status: rendered %zu frame%s\n", frames.size(),
                frames.size() > 1 ? "s" : "");
  return 0;
}

struct MergeArgs {
  std::vector<std::string> inputs;
  std::string output;
  float exposure = 0;
  bool png = true, half = false, json = false;
};

int cmd_merge(const MergeArgs& a) {
  const std::vector<std::string>& inputs = a.inputs;
  const std::string& output = a.output;
  if (inputs.empty()) throw UsageError("merge: no input files");
  check_extension("-o", output, {".exr", ".rfb"});
  bool rfb = std::filesystem::path(output).extension() == ".rfb";
  std::vector<std::pair<std::string, std::string>> paths = {
      {"-o", output}, {"the PNG preview", rfb || !a.png ? "" : png_path_for(output)}};
  for (const std::string& in : inputs) {
    std::error_code ec;
    if (std::filesystem::is_directory(in, ec))
      throw UsageError("merge: " + in + " is a directory, not a sample buffer (.rfb)");
    if (!std::filesystem::is_regular_file(in, ec))
      throw UsageError("merge: " + in +
                       (std::filesystem::exists(in, ec)
                            ? " is not a regular file (a device or FIFO)"
                            : " does not exist"));
    paths.push_back({"input " + in, in});
  }
  check_outputs(paths);  // also: -o names none of the inputs
  std::vector<std::unique_ptr<FrameBands>> files;
  for (const std::string& in : inputs)  // each checked whole (its checksum) as it opens
    files.push_back(std::make_unique<BufferFileBands>(in, uint64_t(64) << 20));
  MergedBands merged(std::move(files), inputs);
  if (std::string ext = std::filesystem::path(output).extension().string(); ext == ".rfb") {
    write_buffer_file(output, merged);
  } else {
    write_exr(output, merged, {}, a.half ? ExrFormat::Half : ExrFormat::Float);
    if (a.png) write_png(png_path_for(output), merged, a.exposure);
  }
  warn_nonfinite(merged.info());
  const uint32_t passes = merged.info().header.passes.count();
  if (a.json) {
    std::printf(
        "%s\n",
        nlohmann::json({{"output", output},
                        {"png", rfb || !a.png ? nullptr : nlohmann::json(png_path_for(output))},
                        {"inputs", inputs.size()},
                        {"passes", merged.info().header.passes.to_string()},
                        {"spp", samples_per_pixel(merged)},
                        {"rel_mse", passes >= 2 ? number_or_null(merged.rel_mse()) : nullptr}})
            .dump()
            .c_str());
    return 0;
  }
  std::fprintf(stderr, "merged %zu files: passes %s, spp %.0f, relMSE %.4g -> %s\n", inputs.size(),
               merged.info().header.passes.to_string().c_str(), samples_per_pixel(merged),
               merged.rel_mse(), output.c_str());
  return 0;
}

// Error of an image against a reference: RMSE, relMSE and mean absolute error (image_error).
// `window` (x0,y0,x1,y1, pixels, half-open; empty = the whole image) restricts the comparison to
// a region, e.g. the caustic that one integrator finds and another does not.
int cmd_compare(const std::string& image, const std::string& reference,
                const std::vector<int>& window, bool json) {
  // A PNG preview holds tone-mapped 8-bit display values, an EXR linear radiance: their
  // difference measures the tone mapping, not the render.
  auto display = [](const std::string& path) {
    std::string ext = std::filesystem::path(path).extension().string();
    for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
    return ext == ".png" || ext == ".jpg" || ext == ".jpeg";
  };
  if (display(image) != display(reference))
    throw UsageError("compare: " + (display(image) ? image : reference) +
                     " holds 8-bit display values (a tone-mapped preview) and " +
                     (display(image) ? reference : image) +
                     " linear radiance: compare the EXRs (or two previews)");
  if (display(image))
    std::fprintf(stderr,
                 "note: comparing 8-bit display values (tone-mapped previews), not "
                 "radiance\n");
  RgbImage a = read_rgb(image), b = read_rgb(reference);
  PixelWindow win{0, 0, a.width, a.height};
  if (!window.empty()) {
    if (window.size() != 4)
      throw UsageError("compare: --window must be X0,Y0,X1,Y1, got " +
                       std::to_string(window.size()) + " numbers");
    win = PixelWindow{window[0], window[1], window[2], window[3]};
  }
  ImageError e;
  try {
    e = image_error(a, b, win);
  } catch (const std::invalid_argument& err) {
    throw UsageError("compare: " + image + " against " + reference + ": " + err.what());
  }
  if (json)
    std::printf("%s\n", nlohmann::json({{"rmse", number_or_null(e.rmse)},
                                        {"rel_mse", number_or_null(e.rel_mse)},
                                        {"mae", number_or_null(e.mae)}})
                            .dump()
                            .c_str());
  else
    std::printf("rmse %.6g relmse %.6g mae %.6g\n", e.rmse, e.rel_mse, e.mae);
  return 0;
}

}  // namespace

void add_local_commands(CLI::App& app, SharedOptions& shared, std::vector<Command>& out) {
  auto ra = std::make_shared<RenderArgs>();
  auto* render = app.add_subcommand("render", "render a scene locally to EXR + PNG");
  render
      ->add_option("scene", ra->scene,
                   "scene file (rayfarm JSON, pbrt-v4 .pbrt, Mitsuba 3 .xml, glTF .gltf/.glb), "
                   "or a per-frame pattern (shot.####.json)")
      ->required();
  render->add_option("-o,--output", ra->output, "output EXR (a PNG preview is written beside it)");
  add_override_options(*render, ra->overrides);
  render->add_option("--frame", ra->frame, "frame number (selects the seed stream)")
      ->check(finite_in(-2147483648.0, 2147483647.0));
  render->add_option("--frames", ra->frames,
                     "frame range (1-24, 1-24:2, 1,5,9): one render per frame; -o and --partial "
                     "then need a frame template (shot.####.exr or shot.%04d.exr), and the scene "
                     "may be one file or a per-frame pattern (shot.####.json)");
  render->add_option("--threads", shared.threads, "worker threads (default: all cores)")
      ->check(finite_in(0, 4096));
  render
      ->add_option(
          "--time-budget", ra->time_budget,
          "stop after this many seconds, on a completed prefix of passes (not reproducible)")
      ->check(finite_in(1e-3, 1e9));
  render->add_option("--pass-range", ra->pass_range, "render only passes FIRST-LAST (inclusive)");
  render->add_option("--partial", ra->partial, "write the sample buffer (.rfb) of the pass range");
  render->add_option("--tile-size", ra->tile, "tile size in pixels")->check(finite_in(1, 65536));
  render->add_option_function<std::string>(
      "--memory",
      [ra](const std::string& v) {
        ra->memory = byte_size_option("--memory", v);
        if (ra->memory < (uint64_t(1) << 20))
          throw CLI::ValidationError("--memory", "'" + v + "' is less than 1M");
      },
      "bytes of frame held in memory (512M, 8G); a larger frame is kept in tiles on disk "
      "(default: a quarter of the machine's memory)");
  render->add_option("--spill-dir", ra->spill_dir,
                     "where a frame kept in tiles goes (unlinked files; default: the output's "
                     "directory)");
  render->add_option("--exposure", ra->exposure, "PNG exposure in stops")
      ->check(finite_in(-64, 64));
  render->add_flag("-q,--quiet", ra->quiet, "no progress output");
  render->add_flag("--json", ra->json,
                   "the summary as one JSON line per frame on stdout (figures and files written)");
  render->add_flag("!--no-png", ra->png, "no PNG preview beside the EXR");
  render->add_flag("--half", ra->half, "half-float EXR channels (half the file)");
  add_progress_option(render, &ra->progress);
  out.push_back({render, [ra] { return cmd_render(*ra); }});

  auto ma = std::make_shared<MergeArgs>();
  auto* merge = app.add_subcommand("merge", "merge partial sample buffers (.rfb) into an image");
  merge->add_option("inputs", ma->inputs, "partial results")->required();
  merge->add_option("-o,--output", ma->output, "output .exr (plus .png) or .rfb")->required();
  merge->add_option("--exposure", ma->exposure, "PNG exposure in stops")->check(finite_in(-64, 64));
  merge->add_flag("!--no-png", ma->png, "no PNG preview beside the EXR");
  merge->add_flag("--half", ma->half, "half-float EXR channels (half the file)");
  merge->add_flag("--json", ma->json, "the result as one JSON line on stdout");
  out.push_back({merge, [ma] { return cmd_merge(*ma); }});

  struct CompareArgs {
    std::string image, reference;
    std::vector<int> window;
    bool json = false;
  };
  auto ca = std::make_shared<CompareArgs>();
  auto* compare = app.add_subcommand("compare", "error of an image against a reference image");
  compare->add_option("image", ca->image, "the image (EXR)")->required();
  compare->add_option("reference", ca->reference, "the reference (EXR, same size)")->required();
  compare->add_option("--window", ca->window, "compare only pixels X0,Y0,X1,Y1 (half-open)")
      ->delimiter(',')
      ->check(finite_in(0, 1e6));
  compare->add_flag("--json", ca->json, "{\"rmse\": ..., \"rel_mse\": ..., \"mae\": ...}");
  out.push_back(
      {compare, [ca] { return cmd_compare(ca->image, ca->reference, ca->window, ca->json); }});

  auto bo = std::make_shared<BenchOptions>();
  auto* bench = app.add_subcommand("bench", "throughput of the path tracer vs a bare Embree loop");
  add_bench_options(*bench, *bo);
  bench->add_option("--threads", shared.threads, "worker threads (default: all cores)")
      ->check(finite_in(0, 4096));
  out.push_back({bench, [bo] { return run_bench(*bo); }});
}

}  // namespace rf::cli
