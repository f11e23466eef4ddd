// The rayfarm command line: render, merge, compare, bench, and the farm (coordinator, worker,
// submit, status, watch, fetch, cancel, health; client/commands.h).
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <unistd.h>

#include <OpenImageIO/imageio.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "bench/bench.h"
#include "client/commands.h"
#include "coordinator/service.h"
#include "engine/film.h"
#include "engine/image_io.h"
#include "engine/local_render.h"
#include "engine/progress.h"
#include "engine/render.h"
#include "engine/scene.h"
#include "worker/worker.h"

namespace {

// Thrown for bad command-line values that CLI11 cannot check by itself.
struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

std::pair<int, int> parse_resolution(const std::string& s) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  if (std::sscanf(s.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X'))
    throw UsageError("--res: expected WIDTHxHEIGHT (e.g. 640x480), got '" + s + "'");
  return {w, h};
}

std::pair<uint32_t, uint32_t> parse_pass_range(const std::string& s, uint32_t passes) {
  unsigned a = 0, b = 0;
  char dash = 0, extra = 0;
  int n = std::sscanf(s.c_str(), "%u%c%u%c", &a, &dash, &b, &extra);
  if (n == 1)
    b = a;
  else if (n != 3 || dash != '-')
    throw UsageError("--pass-range: expected FIRST-LAST (inclusive, e.g. 0-7), got '" + s + "'");
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

// Progress on stderr: a bar redrawn in place on a terminal, plain lines every 5 s otherwise.
class ProgressPrinter {
 public:
  explicit ProgressPrinter(bool quiet) : quiet_(quiet), tty_(::isatty(2)) {}
  void operator()(const rf::LocalProgress& p) {
    if (quiet_ || p.tasks_total == 0) return;
    double frac = double(p.tasks_done) / double(p.tasks_total);
    if (tty_) {
      int width = 30, filled = int(frac * width);
      std::string bar(size_t(filled), '#');
      bar.append(size_t(width - filled), '.');
      std::fprintf(stderr, "\r[%s] %5.1f%%  passes %u/%u  relMSE %.3g  %.1f s   ", bar.c_str(),
                   100 * frac, p.passes_merged, p.passes_total, p.rel_mse, p.seconds);
      if (p.tasks_done == p.tasks_total) std::fprintf(stderr, "\n");
    } else if (p.seconds - last_line_ >= 5.0 || p.tasks_done == p.tasks_total) {
      if (p.tasks_done == p.tasks_total && done_printed_) return;
      done_printed_ = p.tasks_done == p.tasks_total;
      last_line_ = p.seconds;
      std::fprintf(stderr, "progress: %.1f%% tasks, passes %u/%u, relMSE %.3g, %.1f s\n",
                   100 * frac, p.passes_merged, p.passes_total, p.rel_mse, p.seconds);
    }
  }

 private:
  bool quiet_, tty_;
  double last_line_ = -1e9;
  bool done_printed_ = false;
};

std::string png_path_for(const std::string& exr) {
  std::filesystem::path p(exr);
  p.replace_extension(".png");
  return p.string();
}

void warn_nonfinite(const rf::SampleBuffer& b) {
  if (b.nonfinite_samples)
    spdlog::warn("{} NaN/Inf samples were dropped (counted as zero radiance)", b.nonfinite_samples);
}

void print_summary(const rf::SampleBuffer& frame, double seconds, uint64_t rays) {
  double spp = rf::samples_per_pixel(frame);
  double samples = spp * double(frame.rect.area());
  std::printf("spp %.0f | %.2f s | %ssamples/s | %srays/s | relMSE %.4g (%u passes)\n",
              spp, seconds, human(samples / seconds).c_str(),
              human(double(rays) / seconds).c_str(), frame.rel_mse(), frame.header.passes.count());
}

struct RenderArgs {
  std::string scene, output, partial, pass_range, res, integrator, filter, sampler;
  std::optional<uint64_t> spp, seed;
  std::optional<uint32_t> passes, frame;
  std::optional<int> max_depth;
  std::optional<double> noise_target;
  double time_budget = 0;
  int threads = 0, tile = 32;
  float exposure = 0;
  bool quiet = false;
};

rf::SceneOverrides overrides_of(const RenderArgs& a) {
  rf::SceneOverrides ov;
  ov.spp = a.spp;
  ov.passes = a.passes;
  ov.seed = a.seed;
  ov.frame = a.frame;
  ov.max_depth = a.max_depth;
  ov.noise_target = a.noise_target;
  if (!a.integrator.empty()) ov.integrator = a.integrator;
  if (!a.filter.empty()) ov.filter = a.filter;
  if (!a.sampler.empty()) ov.sampler = a.sampler;
  if (!a.res.empty()) std::tie(ov.width, ov.height) = parse_resolution(a.res);
  return ov;
}

// The overrides `render` and `submit` share.
void add_override_options(CLI::App& cmd, RenderArgs& ra) {
  cmd.add_option("--spp", ra.spp, "samples per pixel (all passes)");
  cmd.add_option("--passes", ra.passes, "number of passes (spp must be a multiple)");
  cmd.add_option("--integrator", ra.integrator, "integrator name");
  cmd.add_option("--seed", ra.seed, "job seed");
  cmd.add_option("--res", ra.res, "resolution WIDTHxHEIGHT");
  cmd.add_option("--max-depth", ra.max_depth, "max scattering events");
  cmd.add_option("--filter", ra.filter, "pixel filter (box, triangle, gaussian)");
  cmd.add_option("--sampler", ra.sampler, "sampler (independent, sobol)");
  cmd.add_option("--noise-target", ra.noise_target, "stop when relMSE <= this");
}

int cmd_render(const RenderArgs& a) {
  rf::SceneOverrides ov = overrides_of(a);
  if (a.output.empty() && a.partial.empty())
    throw UsageError("render: give -o OUT.exr or --partial OUT.rfb");
  if (!a.partial.empty() && a.pass_range.empty())
    throw UsageError("--partial needs --pass-range FIRST-LAST");

  rf::Scene scene = rf::load_scene(a.scene, ov);
  rf::LocalRenderOptions opt;
  opt.tile_size = a.tile;
  if (!a.pass_range.empty()) {
    auto [p0, p1] = parse_pass_range(a.pass_range, scene.render.passes);
    opt.first_pass = p0;
    opt.pass_count = p1 - p0;
    if (scene.render.noise_target > 0 && !a.partial.empty())
      spdlog::warn("--noise-target is ignored for a partial render: the merge decides");
  }
  if (a.partial.empty()) opt.noise_target = scene.render.noise_target;
  opt.time_budget_s = a.time_budget;
  ProgressPrinter printer(a.quiet);
  opt.progress = [&](const rf::LocalProgress& p) { printer(p); };

  rf::Renderer renderer(scene);
  rf::LocalRenderResult res = rf::render_local(renderer, opt);
  warn_nonfinite(res.frame);
  if (!a.partial.empty()) {
    rf::write_buffer_file(a.partial, res.frame);
    std::fprintf(stderr, "wrote %s (passes %s)\n", a.partial.c_str(),
                 res.frame.header.passes.to_string().c_str());
  }
  if (!a.output.empty()) {
    rf::write_exr(a.output, res.frame);
    rf::write_png(png_path_for(a.output), res.frame, a.exposure);
    std::fprintf(stderr, "wrote %s and %s\n", a.output.c_str(), png_path_for(a.output).c_str());
  }
  if (res.stopped_on_target)
    std::fprintf(stderr, "noise target %.4g reached after %u of %u passes\n",
                 scene.render.noise_target, res.passes_merged, scene.render.passes);
  if (res.stopped_on_time)
    std::fprintf(stderr, "time budget %.1f s reached after %u of %u passes\n", a.time_budget,
                 res.passes_merged, scene.render.passes);
  print_summary(res.frame, res.seconds, res.rays);
  return 0;
}

int cmd_merge(const std::vector<std::string>& inputs, const std::string& output, float exposure) {
  if (inputs.empty()) throw UsageError("merge: no input files");
  rf::SampleBuffer acc = rf::read_buffer_file(inputs[0]);
  for (size_t i = 1; i < inputs.size(); ++i) {
    rf::SampleBuffer b = rf::read_buffer_file(inputs[i]);
    try {
      rf::merge_into(acc, b);
    } catch (const rf::MergeError& e) {
      throw rf::MergeError(inputs[i] + ": cannot merge into " + inputs[0] + " ...: " + e.what());
    }
  }
  warn_nonfinite(acc);
  std::string ext = std::filesystem::path(output).extension().string();
  if (ext == ".rfb") {
    rf::write_buffer_file(output, acc);
  } else {
    rf::write_exr(output, acc);
    rf::write_png(png_path_for(output), acc, exposure);
  }
  std::fprintf(stderr, "merged %zu files: passes %s, spp %.0f, relMSE %.4g -> %s\n", inputs.size(),
               acc.header.passes.to_string().c_str(), rf::samples_per_pixel(acc), acc.rel_mse(),
               output.c_str());
  return 0;
}

// RGB of an image file, as floats.
std::vector<float> read_rgb(const std::string& path, int& w, int& h) {
  auto in = OIIO::ImageInput::open(path);
  if (!in) throw std::runtime_error(path + ": cannot open: " + OIIO::geterror());
  const OIIO::ImageSpec& spec = in->spec();
  if (spec.nchannels < 3) throw std::runtime_error(path + ": needs at least 3 channels");
  w = spec.width, h = spec.height;
  std::vector<float> px(size_t(w) * h * 3);
  if (!in->read_image(0, 0, 0, 3, OIIO::TypeDesc::FLOAT, px.data()))
    throw std::runtime_error(path + ": " + in->geterror());
  return px;
}

// Error of an image against a reference: RMSE, relMSE (pbrt-v4's convention, the same as the
// render's noise figure) and the mean absolute error, over pixels and RGB.
// `window` (x0,y0,x1,y1, pixels, half-open; empty = the whole image) restricts the comparison to
// a region, e.g. the caustic that one integrator finds and another does not.
int cmd_compare(const std::string& image, const std::string& reference,
                const std::vector<int>& window) {
  int w, h, rw, rh;
  std::vector<float> a = read_rgb(image, w, h), b = read_rgb(reference, rw, rh);
  if (w != rw || h != rh)
    throw UsageError("compare: " + image + " is " + std::to_string(w) + "x" + std::to_string(h) +
                     ", " + reference + " is " + std::to_string(rw) + "x" + std::to_string(rh));
  int x0 = 0, y0 = 0, x1 = w, y1 = h;
  if (!window.empty()) {
    if (window.size() != 4 || window[0] < 0 || window[1] < 0 || window[2] > w ||
        window[3] > h || window[0] >= window[2] || window[1] >= window[3])
      throw UsageError("compare: --window must be X0,Y0,X1,Y1 with 0 <= X0 < X1 <= " +
                       std::to_string(w) + " and 0 <= Y0 < Y1 <= " + std::to_string(h));
    x0 = window[0], y0 = window[1], x1 = window[2], y1 = window[3];
  }
  double se = 0, rel = 0, abs_err = 0;
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x)
      for (int c = 0; c < 3; ++c) {
        size_t i = (size_t(y) * w + x) * 3 + c;
        double d = double(a[i]) - double(b[i]);
        se += d * d;
        rel += d * d / (double(b[i]) * b[i] + 0.01);
        abs_err += std::fabs(d);
      }
  double n = double(x1 - x0) * (y1 - y0) * 3;
  std::printf("rmse %.6g relmse %.6g mae %.6g\n", std::sqrt(se / n), rel / n, abs_err / n);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"rayfarm: a distributed batch renderer (render, merge, bench)"};
  app.require_subcommand(1);
  int threads = 0;
  app.add_option("--threads", threads, "worker threads (default: all cores)");

  RenderArgs ra;
  auto* render = app.add_subcommand("render", "render a scene locally to EXR + PNG");
  render->add_option("scene", ra.scene, "scene file (JSON)")->required();
  render->add_option("-o,--output", ra.output, "output EXR (a PNG preview is written beside it)");
  add_override_options(*render, ra);
  render->add_option("--frame", ra.frame, "frame number (selects the seed stream)");
  render->add_option("--threads", threads, "worker threads (default: all cores)");
  render->add_option(
      "--time-budget", ra.time_budget,
      "stop after this many seconds, on a completed prefix of passes (not reproducible)");
  render->add_option("--pass-range", ra.pass_range, "render only passes FIRST-LAST (inclusive)");
  render->add_option("--partial", ra.partial, "write the sample buffer (.rfb) of the pass range");
  render->add_option("--tile-size", ra.tile, "tile size in pixels")->check(CLI::PositiveNumber);
  render->add_option("--exposure", ra.exposure, "PNG exposure in stops");
  render->add_flag("-q,--quiet", ra.quiet, "no progress output");

  std::vector<std::string> merge_inputs;
  std::string merge_output;
  float merge_exposure = 0;
  auto* merge = app.add_subcommand("merge", "merge partial sample buffers (.rfb) into an image");
  merge->add_option("inputs", merge_inputs, "partial results")->required();
  merge->add_option("-o,--output", merge_output, "output .exr (plus .png) or .rfb")->required();
  merge->add_option("--exposure", merge_exposure, "PNG exposure in stops");

  std::string cmp_image, cmp_reference;
  auto* compare = app.add_subcommand("compare", "error of an image against a reference image");
  compare->add_option("image", cmp_image, "the image (EXR)")->required();
  compare->add_option("reference", cmp_reference, "the reference (EXR, same size)")->required();
  std::vector<int> cmp_window;
  compare->add_option("--window", cmp_window, "compare only pixels X0,Y0,X1,Y1 (half-open)")
      ->delimiter(',');

  rf::BenchOptions bo;
  auto* bench = app.add_subcommand("bench", "throughput of the path tracer vs a bare Embree loop");
  rf::add_bench_options(*bench, bo);
  bench->add_option("--threads", threads, "worker threads (default: all cores)");

  // The farm.
  std::string addr = rf::default_coordinator();
  auto add_addr = [&](CLI::App* c) {
    c->add_option("--coordinator", addr,
                  "coordinator address (default: $RAYFARM_COORDINATOR, else 127.0.0.1:7070)");
  };
  rf::CoordinatorOptions co;
  auto* coord = app.add_subcommand("coordinator", "serve jobs to workers (gRPC)");
  coord->add_option("--listen", co.listen, "address to listen on (HOST:PORT; port 0 picks one)");
  coord->add_option("--state-dir", co.state_dir, "durable state: database, checkpoints, blobs")
      ->required();
  coord->add_option("--lease-seconds", co.lease_seconds, "lease time of a task")
      ->check(CLI::PositiveNumber);
  coord->add_option("--window", co.window_frames, "frames open at once per job")
      ->check(CLI::PositiveNumber);

  rf::WorkerOptions wo;
  auto* worker = app.add_subcommand("worker", "lease and render tasks from a coordinator");
  add_addr(worker);
  worker->add_option("--cache-dir", wo.cache_dir, "blob cache (default ~/.cache/rayfarm)");
  worker->add_option("--drain-seconds", wo.drain_seconds,
                     "on SIGTERM, finish the task in flight if done within this, else hand it back");
  worker->add_flag("--exit-when-idle", wo.exit_when_idle,
                   "exit once the coordinator has no queued or leased work left");
  worker->add_option("--max-tasks", wo.max_tasks, "exit after this many tasks");
  worker->add_option("--threads", threads, "render threads (default: all cores)");

  RenderArgs sa;
  rf::SubmitArgs sub;
  auto* submit = app.add_subcommand("submit", "submit a job; prints its id");
  add_addr(submit);
  submit->add_option("scene", sub.scene, "scene file, or a per-frame pattern (shot.####.json)")
      ->required();
  add_override_options(*submit, sa);
  submit->add_option("--frames", sub.frames, "frames, Open Job Description syntax (1-10:2,15)");
  submit->add_option("--priority", sub.priority, "higher runs first");
  submit->add_option("--name", sub.name, "job name (default: the scene's file name)");
  submit->add_option("--tile-size", sub.tile_size, "tile size in pixels")->check(CLI::PositiveNumber);

  std::string job;
  bool json = false;
  auto* status = app.add_subcommand("status", "all jobs (or one), one line each");
  add_addr(status);
  status->add_option("job", job, "one job");
  status->add_flag("--json", json, "machine-readable");
  auto* watch = app.add_subcommand("watch", "follow a job until it ends (exit 0: completed)");
  add_addr(watch);
  watch->add_option("job", job, "job id")->required();
  std::string fetch_dir;
  std::optional<uint32_t> fetch_frame;
  float fetch_exposure = 0;
  auto* fetch = app.add_subcommand("fetch", "write a job's frames (EXR + PNG), also mid-job");
  add_addr(fetch);
  fetch->add_option("job", job, "job id")->required();
  fetch->add_option("-o,--output", fetch_dir, "output directory")->required();
  fetch->add_option("--frame", fetch_frame, "only this frame");
  fetch->add_option("--exposure", fetch_exposure, "PNG exposure in stops");
  auto* cancel = app.add_subcommand("cancel", "cancel a job");
  add_addr(cancel);
  cancel->add_option("job", job, "job id")->required();
  bool services = false;
  std::string health_addr;
  auto* health = app.add_subcommand("health", "check a coordinator's gRPC health service");
  add_addr(health);
  health->add_option("address", health_addr, "HOST:PORT (default: as --coordinator)");
  health->add_flag("--services", services, "also list its services (server reflection)");

  CLI11_PARSE(app, argc, argv);
  std::unique_ptr<tbb::global_control> limit;
  if (threads > 0)
    limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                  size_t(threads));
  spdlog::set_pattern("%^%l%$: %v");
  // Long-running services log with timestamps.
  if (coord->parsed() || worker->parsed()) spdlog::set_pattern("[%Y-%m-%d %H:%M:%S.%e] %^%l%$: %v");
  try {
    if (render->parsed()) return cmd_render(ra);
    if (merge->parsed()) return cmd_merge(merge_inputs, merge_output, merge_exposure);
    if (bench->parsed()) return rf::run_bench(bo);
    if (compare->parsed()) return cmd_compare(cmp_image, cmp_reference, cmp_window);
    if (coord->parsed()) return rf::run_coordinator(co);
    if (worker->parsed()) {
      wo.coordinator = addr;
      return rf::run_worker(wo);
    }
    if (submit->parsed()) {
      sub.overrides = overrides_of(sa);
      return rf::cmd_submit(addr, sub);
    }
    if (status->parsed()) return rf::cmd_status(addr, job, json);
    if (watch->parsed()) return rf::cmd_watch(addr, job);
    if (fetch->parsed()) return rf::cmd_fetch(addr, job, fetch_dir, fetch_frame, fetch_exposure);
    if (cancel->parsed()) return rf::cmd_cancel(addr, job);
    if (health->parsed()) return rf::cmd_health(health_addr.empty() ? addr : health_addr, services);
  } catch (const rf::FarmError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return e.exit_status;
  } catch (const UsageError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
