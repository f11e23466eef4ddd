#include "engine/render.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <time.h>

#include <atomic>
#include <map>
#include <mutex>

#include "engine/build_info.h"
#include "engine/camera.h"
#include "engine/filter.h"
#include "engine/integrator.h"
#include "engine/sampler.h"

namespace rf {

namespace {
double thread_cpu_seconds() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

const char* filter_name(FilterType t) {
  switch (t) {
    case FilterType::Box:
      return "box";
    case FilterType::Triangle:
      return "triangle";
    case FilterType::Gaussian:
      return "gaussian";
  }
  return "?";
}
}  // namespace

std::string settings_text(const Scene& s) {
  const IntegratorSettings& i = s.render.integrator;
  char buf[512];
  int n = std::snprintf(buf, sizeof buf,
                        "max_depth=%d;rr_min_depth=%d;spp_per_pass=%llu;filter=%s:%g:%g;sampler=%s",
                        i.max_depth, i.rr_min_depth, (unsigned long long)s.render.spp_per_pass(),
                        filter_name(s.film.filter.type), double(s.film.filter.radius),
                        double(s.film.filter.sigma), s.render.sampler.c_str());
  if (i.type == "ao")
    std::snprintf(buf + n, sizeof buf - size_t(n), ";ao=%g:%s:%d", double(i.ao_max_distance),
                  i.ao_cosine ? "cosine" : "uniform", i.ao_samples);
  if (i.type == "direct")
    std::snprintf(buf + n, sizeof buf - size_t(n), ";direct=%d:%s:%d:%d", int(i.direct_strategy),
                  i.power_heuristic ? "power" : "balance", i.light_samples, i.bsdf_samples);
  if (i.type == "ir")
    std::snprintf(buf + n, sizeof buf - size_t(n), ";ir=%d:%.9g:%s", i.ir_vpl_paths,
                  double(i.ir_clamp_distance), i.ir_compensation ? "comp" : "nocomp");
  if (i.type == "ppm")
    std::snprintf(buf + n, sizeof buf - size_t(n), ";ppm=%d:%.9g:%.9g", i.ppm_photons,
                  double(i.ppm_radius), double(i.ppm_alpha));
  return buf;
}

Renderer::Renderer(const Scene& scene)
    : scene_(scene),
      kind_(integrator_kind(scene.render.integrator.type)),
      frame_(scene.render.frame),
      accel_(std::make_unique<Accel>(scene)),
      lights_(std::make_unique<LightSet>(scene)),
      textures_(std::make_unique<TextureEvaluator>(scene)) {
  check_renderable(scene);
}

void check_renderable(const Scene& scene) {
  // Integrators whose light paths start on the lights cannot use lights without a finite
  // emission position: refuse the scene before any task runs.
  IntegratorKind kind = integrator_kind(scene.render.integrator.type);
  if (kind == IntegratorKind::LightTracing || kind == IntegratorKind::InstantRadiosity ||
      kind == IntegratorKind::PhotonMapping) {
    bool directional = false;
    for (const Light& l : scene.lights) directional |= l.type == LightType::Directional;
    if (scene.environment || directional)
      throw SceneError(scene.path + ": integrator '" + scene.render.integrator.type +
                       "' cannot start light paths on " +
                       std::string(scene.environment ? "an environment" : "a directional light") +
                       " (no finite emission position); use path or bdpt for this scene");
  }
}

BufferHeader frame_header(const Scene& scene, const PassSet& passes) {
  BufferHeader h;
  h.scene_digest = scene.digest;
  h.seed = scene.render.seed;
  h.frame = scene.render.frame;
  h.integrator = scene.render.integrator.type;
  h.settings = settings_text(scene);
  h.width = scene.film.width;
  h.height = scene.film.height;
  h.passes = passes;
  h.build_id = build_id();
  h.isa = cpu_isa();
  return h;
}

std::vector<Rect> frame_tiles(const Scene& scene, int tile_size) {
  int w = scene.film.width, h = scene.film.height;
  if (integrator_splats(integrator_kind(scene.render.integrator.type)) || tile_size <= 0)
    return {Rect{0, 0, w, h}};
  std::vector<Rect> out;
  for (int y = 0; y < h; y += tile_size)
    for (int x = 0; x < w; x += tile_size)
      out.push_back({x, y, std::min(tile_size, w - x), std::min(tile_size, h - y)});
  return out;
}

BufferHeader Renderer::header(const PassSet& passes) const {
  BufferHeader h = frame_header(scene_, passes);
  h.frame = frame_;
  return h;
}

void Renderer::set_frame(uint32_t frame) { frame_ = frame; }

std::vector<Rect> Renderer::tiles(int tile_size) const { return frame_tiles(scene_, tile_size); }

RenderContext Renderer::context() const {
  RenderContext ctx{scene_, *accel_, *lights_, *textures_};
  ctx.frame = frame_;
  float t = std::tan(0.5f * scene_.camera.fov_deg * kPi / 180.0f);
  ctx.pixel_spread = 2 * t / float(std::min(scene_.film.width, scene_.film.height));
  return ctx;
}

SampleBuffer Renderer::render_task(const Rect& rect, uint32_t pass, bool parallel) const {
  if (kind_ == IntegratorKind::LightTracing) return render_light_paths(pass, parallel);
  if (kind_ == IntegratorKind::Bdpt) return render_bdpt(pass, parallel);
  return render_camera_paths(rect, pass, parallel);
}

SampleBuffer Renderer::render_camera_paths(const Rect& rect, uint32_t pass, bool parallel) const {
  SampleBuffer buf(header(PassSet::range(pass, pass + 1)), rect, false);
  const RenderSettings& rs = scene_.render;
  PerspectiveCamera camera(scene_.camera, scene_.film.width, scene_.film.height);
  RenderContext ctx = context();
  std::atomic<uint64_t> rays{0};
  // IR and PPM precompute per pass (virtual point lights, photons); the rest need nothing.
  std::shared_ptr<const VplSet> vpls;
  std::shared_ptr<const PhotonMap> photons;
  if (kind_ == IntegratorKind::InstantRadiosity) vpls = pass_vpls(pass, rays);
  if (kind_ == IntegratorKind::PhotonMapping) photons = pass_photons(pass, rays);
  auto radiance = [&](Ray ray, Sampler& sampler, TraceCounters& counters) {
    switch (kind_) {
      case IntegratorKind::Whitted: return whitted_radiance(ctx, ray, sampler, counters);
      case IntegratorKind::AmbientOcclusion: return ao_radiance(ctx, ray, sampler, counters);
      case IntegratorKind::Direct: return direct_radiance(ctx, ray, sampler, counters);
      case IntegratorKind::InstantRadiosity: return ir_radiance(ctx, *vpls, ray, sampler, counters);
      case IntegratorKind::PhotonMapping: return ppm_radiance(ctx, *photons, ray, sampler, counters);
      default: return path_radiance(ctx, ray, sampler, counters);
    }
  };
  uint64_t spp = rs.spp_per_pass();
  std::atomic<uint64_t> cpu_ns{0};
  std::atomic<uint64_t> nonfinite{0};

  auto render_rows = [&](int y_begin, int y_end) {
    double t0 = thread_cpu_seconds();
    TraceCounters counters;
    uint64_t local_nonfinite = 0;
    Sampler sampler(kind_from_name(scene_.render.sampler));
    for (int y = y_begin; y < y_end; ++y)
      for (int x = rect.x0; x < rect.x1(); ++x)
        for (uint64_t s = 0; s < spp; ++s) {
          sampler.start_camera_sample(rs.seed, frame_, pass, x, y, s);
          FilterSample fs = sample_filter(scene_.film.filter, sampler.get_2d());
          Vec2 u_lens = sampler.get_2d();
          Ray ray = camera.generate_ray(float(x) + 0.5f + fs.offset.x,
                                        float(y) + 0.5f + fs.offset.y, u_lens);
          RGB l = radiance(ray, sampler, counters);
          // Rows are disjoint: no two threads share a pixel.
          buf.add_sample(x, y, l * fs.weight, local_nonfinite);
        }
    rays += counters.rays;
    nonfinite += local_nonfinite;
    cpu_ns += uint64_t((thread_cpu_seconds() - t0) * 1e9);
  };
  if (parallel) {
    tbb::parallel_for(tbb::blocked_range<int>(rect.y0, rect.y1(), 1), [&](const auto& r) {
      for (int y = r.begin(); y < r.end(); ++y) render_rows(y, y + 1);
    });
  } else {
    render_rows(rect.y0, rect.y1());
  }
  buf.rays = rays;
  buf.nonfinite_samples = nonfinite;
  buf.header.core_seconds = double(cpu_ns.load()) * 1e-9;
  buf.finish_pass();
  return buf;
}

// One pass of light tracing: spp_per_pass light paths per pixel of the frame, so a pass costs
// about what a camera-path pass costs. Light path i of pass p is keyed by (seed, frame, p, i).
// Paths are traced in fixed chunks; each chunk records its splats, and the chunks' splats are
// added in chunk order: bit-identical whatever the thread count (atomics would not be).
SampleBuffer Renderer::render_light_paths(uint32_t pass, bool parallel) const {
  const int w = scene_.film.width, h = scene_.film.height;
  SampleBuffer buf(header(PassSet::range(pass, pass + 1)), Rect{0, 0, w, h}, true);
  const RenderSettings& rs = scene_.render;
  PerspectiveCamera camera(scene_.camera, w, h);
  RenderContext ctx = context();
  const uint64_t paths = rs.spp_per_pass() * uint64_t(w) * uint64_t(h);
  constexpr uint64_t kChunk = 4096;
  const uint64_t chunks = (paths + kChunk - 1) / kChunk;
  const size_t wave = parallel ? size_t(8 * tbb::this_task_arena::max_concurrency()) : 1;
  std::vector<std::vector<Splat>> lists(std::min<uint64_t>(wave, chunks));
  std::atomic<uint64_t> rays{0}, cpu_ns{0};

  auto trace_chunk = [&](uint64_t chunk, std::vector<Splat>& out) {
    double t0 = thread_cpu_seconds();
    out.clear();
    TraceCounters counters;
    Sampler sampler(Sampler::Kind::Independent);  // light paths: independent (sampler.h)
    SplatTarget target{&out, w, h, &scene_.film.filter};
    for (uint64_t i = chunk * kChunk; i < std::min(paths, (chunk + 1) * kChunk); ++i) {
      sampler.start_light_path(rs.seed, frame_, pass, i);
      trace_light_path(ctx, camera, sampler, target, counters);
    }
    rays += counters.rays;
    cpu_ns += uint64_t((thread_cpu_seconds() - t0) * 1e9);
  };
  for (uint64_t first = 0; first < chunks; first += lists.size()) {
    size_t n = size_t(std::min<uint64_t>(lists.size(), chunks - first));
    if (parallel)
      tbb::parallel_for(size_t(0), n, [&](size_t k) { trace_chunk(first + k, lists[k]); });
    else
      for (size_t k = 0; k < n; ++k) trace_chunk(first + k, lists[k]);
    for (size_t k = 0; k < n; ++k)
      for (const Splat& sp : lists[k]) buf.add_splat(int(sp.pixel % uint32_t(w)), int(sp.pixel / uint32_t(w)), sp.value);
  }
  buf.light_paths = paths;
  buf.rays = rays;
  buf.header.core_seconds = double(cpu_ns.load()) * 1e-9;
  buf.finish_pass();
  return buf;
}

// One pass of BDPT: camera samples as for the path tracer, each with its own light subpath, so
// the splat plane is normalised by the camera sample count. Rows are traced in fixed chunks whose
// splat lists are added in chunk order (bit-identical for any thread count), while each row's
// pixels take their own samples directly (rows are disjoint).
SampleBuffer Renderer::render_bdpt(uint32_t pass, bool parallel) const {
  const int w = scene_.film.width, h = scene_.film.height;
  SampleBuffer buf(header(PassSet::range(pass, pass + 1)), Rect{0, 0, w, h}, true);
  const RenderSettings& rs = scene_.render;
  PerspectiveCamera camera(scene_.camera, w, h);
  RenderContext ctx = context();
  const uint64_t spp = rs.spp_per_pass();
  constexpr int kRowsPerChunk = 4;
  const int chunks = (h + kRowsPerChunk - 1) / kRowsPerChunk;
  const int wave = parallel ? 8 * tbb::this_task_arena::max_concurrency() : 1;
  std::vector<std::vector<Splat>> lists(size_t(std::min(wave, chunks)));
  std::atomic<uint64_t> rays{0}, cpu_ns{0}, nonfinite{0};

  auto trace_chunk = [&](int chunk, std::vector<Splat>& out) {
    double t0 = thread_cpu_seconds();
    out.clear();
    TraceCounters counters;
    uint64_t local_nonfinite = 0;
    Sampler sampler(kind_from_name(rs.sampler));
    SplatTarget target{&out, w, h, &scene_.film.filter};
    for (int y = chunk * kRowsPerChunk; y < std::min(h, (chunk + 1) * kRowsPerChunk); ++y)
      for (int x = 0; x < w; ++x)
        for (uint64_t s = 0; s < spp; ++s) {
          sampler.start_camera_sample(rs.seed, frame_, pass, x, y, s);
          FilterSample fs = sample_filter(scene_.film.filter, sampler.get_2d());
          Vec2 u_lens = sampler.get_2d();
          Ray ray = camera.generate_ray(float(x) + 0.5f + fs.offset.x,
                                        float(y) + 0.5f + fs.offset.y, u_lens);
          RGB l = bdpt_sample(ctx, camera, ray, sampler, target, counters);
          buf.add_sample(x, y, l * fs.weight, local_nonfinite);
        }
    rays += counters.rays;
    nonfinite += local_nonfinite;
    cpu_ns += uint64_t((thread_cpu_seconds() - t0) * 1e9);
  };
  for (int first = 0; first < chunks; first += int(lists.size())) {
    int n = std::min(int(lists.size()), chunks - first);
    if (parallel)
      tbb::parallel_for(0, n, [&](int k) { trace_chunk(first + k, lists[size_t(k)]); });
    else
      for (int k = 0; k < n; ++k) trace_chunk(first + k, lists[size_t(k)]);
    for (int k = 0; k < n; ++k)
      for (const Splat& sp : lists[size_t(k)])
        buf.add_splat(int(sp.pixel % uint32_t(w)), int(sp.pixel / uint32_t(w)), sp.value);
  }
  buf.light_paths = spp * uint64_t(w) * uint64_t(h);
  buf.rays = rays;
  buf.nonfinite_samples += nonfinite;
  buf.header.core_seconds = double(cpu_ns.load()) * 1e-9;
  buf.finish_pass();
  return buf;
}

// Per-pass state, built by the first task of a pass that needs it and kept for the few passes
// in flight (a local render works on a window of passes; a worker on one task at a time).
template <class T, class Build>
std::shared_ptr<const T> cached_pass_state(std::mutex& mu,
                                           std::map<uint64_t, std::shared_ptr<const void>>& cache,
                                           uint64_t pass, Build build) {
  constexpr size_t kKeep = 8;
  {
    std::lock_guard<std::mutex> lock(mu);
    auto it = cache.find(pass);
    if (it != cache.end()) return std::static_pointer_cast<const T>(it->second);
  }
  std::shared_ptr<const T> state = build();  // outside the lock: tiles of other passes go on
  std::lock_guard<std::mutex> lock(mu);
  auto [it, inserted] = cache.emplace(pass, state);
  while (cache.size() > kKeep) cache.erase(cache.begin() == it ? std::next(cache.begin()) : cache.begin());
  return std::static_pointer_cast<const T>(it->second);
}

std::shared_ptr<const VplSet> Renderer::pass_vpls(uint32_t pass, std::atomic<uint64_t>& rays) const {
  return cached_pass_state<VplSet>(cache_mutex_, pass_cache_, pass_key(pass), [&] {
    TraceCounters counters;
    auto v = build_vpls(context(), pass, counters);
    rays += counters.rays;
    return v;
  });
}

std::shared_ptr<const PhotonMap> Renderer::pass_photons(uint32_t pass,
                                                        std::atomic<uint64_t>& rays) const {
  return cached_pass_state<PhotonMap>(cache_mutex_, pass_cache_, pass_key(pass), [&] {
    TraceCounters counters;
    auto p = build_photon_map(context(), pass, counters);
    rays += counters.rays;
    return p;
  });
}

}  // namespace rf
