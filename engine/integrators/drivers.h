// The two render drivers: the loops that turn an integrator's estimator into one task's sample
// buffer (DESIGN.md "Work units", "Pixels, filters and splats").
//
//   render_camera_paths  camera samples of every pixel of the task's rect; the estimator returns
//                        the radiance of one camera ray (and, for BDPT, splats light-path
//                        connections: then the rect is the whole frame);
//   render_light_paths   light paths of the whole frame, each splatting where it reaches the film.
//
// When the scene asks for AOVs (engine/aov.h), the camera-path driver traces each camera sample's
// ray once more for them (aov_sample.h), and the light-path driver casts spp-per-pass camera rays
// per pixel for them, started like camera samples; neither draws from the samplers the image uses.
//
// Both are bit-identical whatever the thread count: pixels are filled by one thread each, and
// splats are recorded per fixed chunk of work and added in chunk order (for_chunks_in_order).
// Every random number comes from a Sampler started for (seed, frame, pass, pixel, sample) or
// (seed, frame, pass, light path): the determinism contract.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <time.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <type_traits>
#include <vector>

#include "engine/filter.h"
#include "engine/frame.h"
#include "engine/integrators/aov_sample.h"
#include "engine/integrators/common.h"
#include "engine/integrators/sample_layout.h"
#include "engine/sample_buffer.h"
#include "engine/work_units.h"

namespace rf {

// The ray of pixel (x, y) through the filter offset u_filter picks and the lens point u_lens
// picks, and the sample's filter weight.
// In a scene where something moves, the sample's time (its position in the frame's shutter, the
// ray's time) comes from its own hashed stream (kTimeStream), which moves no other number of the
// sample, and a moving camera is placed where it is at that time.
inline Ray camera_ray(const RenderContext& ctx, Sampler& sampler, FrameNumber frame, int x, int y,
                      Vec2 u_filter, Vec2 u_lens, float& filter_weight) {
  const FilterSample fs = sample_filter(ctx.scene.film.filter, u_filter);
  filter_weight = fs.weight;
  const float rx = float(x) + 0.5f + fs.offset.x, ry = float(y) + 0.5f + fs.offset.y;
  if (!ctx.moves) return ctx.camera.generate_ray(rx, ry, u_lens);
  const float u = sampler.get_1d_stream(kTimeStream);  // the shutter position: the ray's time
  Ray ray = ctx.scene.camera.moves()
                ? ctx.camera.generate_ray(rx, ry, u_lens,
                                          ctx.scene.camera.motion.at(ctx.scene.time.at(frame, u)))
                : ctx.camera.generate_ray(rx, ry, u_lens);
  ray.time = u;
  return ray;
}

// The camera at shutter position u of frame `frame` (a light path's time): the context's own
// when the camera does not move, else placed where camera_ray places it at that time, so that a
// light path's camera connections and the camera rays of that time see one camera.
inline PerspectiveCamera camera_at(const RenderContext& ctx, FrameNumber frame, float u) {
  if (!ctx.scene.camera.moves()) return ctx.camera;
  return ctx.camera.placed(ctx.scene.camera.motion.at(ctx.scene.time.at(frame, u)));
}

// Camera sample `index` of pixel (x, y): starts the sampler for it, draws the filter offset
// (filter importance sampling: the sample stays in its pixel) and the lens point, and returns
// the camera ray; `filter_weight` is the sample's weight.
inline Ray start_camera_sample(const RenderContext& ctx, Sampler& sampler, const TaskKey& task,
                               int x, int y, uint64_t index, float& filter_weight) {
  sampler.start_camera_sample(ctx.scene.render.seed, task.frame, task.pass, x, y, index);
  const Vec2 u_filter = sampler.get_2d();
  const Vec2 u_lens = sampler.get_2d_if(ctx.camera.lens_radius() > 0);  // a pinhole reads none
  return camera_ray(ctx, sampler, task.frame, x, y, u_filter, u_lens, filter_weight);
}

// start_camera_sample() for samples first_index + i of pixel (x, y), i < n <= Sampler::kMaxLanes,
// each with its own sampler s[i]: the same rays, weights and sampler states, the samplers started
// together (Sampler::start_camera_samples) and, for the Sobol kinds, the filter and lens numbers
// drawn in lockstep (Sampler::get_lanes).
inline void start_camera_samples(const RenderContext& ctx, Sampler* s, int n, const TaskKey& task,
                                 int x, int y, uint64_t first_index, Ray* rays,
                                 float* filter_weight) {
  Sampler::start_camera_samples(s, n, ctx.scene.render.seed, task.frame, task.pass, x, y,
                                first_index);
  const bool lens = ctx.camera.lens_radius() > 0;
  if (n <= 1 || s[0].kind() == Sampler::Kind::Independent) {
    for (int i = 0; i < n; ++i) {
      const Vec2 u_filter = s[i].get_2d(), u_lens = s[i].get_2d_if(lens);
      rays[i] = camera_ray(ctx, s[i], task.frame, x, y, u_filter, u_lens, filter_weight[i]);
    }
    return;
  }
  int lane[Sampler::kMaxLanes];
  for (int i = 0; i < n; ++i) lane[i] = i;
  const uint8_t draws[2] = {2, uint8_t(lens ? 2 : 0)};  // a Sobol skip is one dimension either way
  Sampler::LaneDraws u[2];
  Sampler::get_lanes(s, lane, n, draws, 2, u);
  for (int i = 0; i < n; ++i) {
    const Vec2 u_lens = lens ? Vec2{u[1][0][i], u[1][1][i]} : Vec2{0.0f, 0.0f};
    rays[i] =
        camera_ray(ctx, s[i], task.frame, x, y, {u[0][0][i], u[0][1][i]}, u_lens, filter_weight[i]);
  }
}

// Runs produce(chunk, out) for every chunk in [0, chunks), in parallel waves when `parallel`,
// and consume(out) on each chunk's output in chunk order: whatever the thread count, consume sees
// the same sequence. A wave holds a few chunks per thread, so memory stays bounded (splat lists);
// a caller that keeps every output anyway asks for one wave of all chunks (no barriers).
template <class T, class Produce, class Consume>
void for_chunks_in_order(uint64_t chunks, bool parallel, Produce&& produce, Consume&& consume,
                         bool one_wave = false) {
  const uint64_t wave = !parallel  ? 1
                        : one_wave ? std::max<uint64_t>(chunks, 1)
                                   : uint64_t(8 * tbb::this_task_arena::max_concurrency());
  std::vector<T> outs(size_t(std::min(wave, chunks)));
  for (uint64_t first = 0; first < chunks; first += outs.size()) {
    const size_t n = size_t(std::min<uint64_t>(outs.size(), chunks - first));
    if (parallel)
      tbb::parallel_for(size_t(0), n, [&](size_t k) { produce(first + k, outs[k]); });
    else
      for (size_t k = 0; k < n; ++k) produce(first + k, outs[k]);
    for (size_t k = 0; k < n; ++k) consume(outs[k]);
  }
}

namespace driver_detail {

inline double thread_cpu_seconds() {
  timespec ts;
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

// What a task's threads add up: rays, CPU time, non-finite camera samples.
struct Tally {
  std::atomic<uint64_t> rays{0}, cpu_ns{0}, nonfinite{0};
  void add(const TraceCounters& c, double cpu_start, uint64_t nonfinite_samples = 0) {
    rays += c.rays;
    nonfinite += nonfinite_samples;
    cpu_ns += uint64_t((thread_cpu_seconds() - cpu_start) * 1e9);
  }
  // Writes the totals into the task's one-pass buffer and sets its batch plane.
  void finish(SampleBuffer& buf) const {
    buf.rays += rays;
    buf.nonfinite_samples += nonfinite;
    buf.header.core_seconds = double(cpu_ns.load()) * 1e-9;
    buf.finish_pass();
  }
};

// The AOVs of a light-path render: spp-per-pass camera rays per pixel, cast for them alone.
inline void light_path_aovs(const RenderContext& ctx, const TaskKey& task, bool parallel,
                            SampleBuffer& buf, Tally& tally) {
  const uint64_t spp = ctx.scene.render.spp_per_pass();
  const Sampler::Kind kind = kind_from_name(ctx.scene.render.sampler);
  auto rows = [&](int y_begin, int y_end) {
    double t0 = thread_cpu_seconds();
    TraceCounters counters;
    Sampler sampler(kind, ctx.scene.render.spp_per_pass());
    for (int y = y_begin; y < y_end; ++y)
      for (int x = buf.rect.x0; x < buf.rect.x1(); ++x)
        for (uint64_t s = 0; s < spp; ++s) {
          float filter_weight;
          Ray ray = start_camera_sample(ctx, sampler, task, x, y, s, filter_weight);
          buf.add_aov_sample(x, y, aov_sample(ctx, ray, counters));
        }
    tally.add(counters, t0);
  };
  if (parallel)
    tbb::parallel_for(tbb::blocked_range<int>(buf.rect.y0, buf.rect.y1(), 1),
                      [&](const auto& r) { rows(r.begin(), r.end()); });
  else
    rows(buf.rect.y0, buf.rect.y1());
}

// What light paths cannot reach, as camera samples: the environment seen directly (a light path
// never hits the camera's lens). spp-per-pass camera samples per pixel, started like camera
// samples: the environment's radiance when the camera ray leaves the scene, 0 when it hits a
// surface. The buffer's estimate is then their mean plus the splats per light path.
inline void environment_camera_samples(const RenderContext& ctx, const TaskKey& task, bool parallel,
                                       SampleBuffer& buf, Tally& tally) {
  const uint64_t spp = ctx.scene.render.spp_per_pass();
  const Sampler::Kind kind = kind_from_name(ctx.scene.render.sampler);
  auto rows = [&](int y_begin, int y_end) {
    double t0 = thread_cpu_seconds();
    TraceCounters counters;
    uint64_t nonfinite = 0;
    Sampler sampler(kind, spp);
    for (int y = y_begin; y < y_end; ++y)
      for (int x = buf.rect.x0; x < buf.rect.x1(); ++x)
        for (uint64_t s = 0; s < spp; ++s) {
          float filter_weight;
          Ray ray = start_camera_sample(ctx, sampler, task, x, y, s, filter_weight);
          ++counters.rays;
          RGB le = ctx.accel.cast(ray.o, ray.d) == kInf ? ctx.lights.environment_radiance(ray.d)
                                                        : RGB(0.0f);
          buf.add_sample(x, y, le * filter_weight, nonfinite);
        }
    tally.add(counters, t0, nonfinite);
  };
  if (parallel)
    tbb::parallel_for(tbb::blocked_range<int>(buf.rect.y0, buf.rect.y1(), 1),
                      [&](const auto& r) { rows(r.begin(), r.end()); });
  else
    rows(buf.rect.y0, buf.rect.y1());
}

}  // namespace driver_detail

// An estimator that traces the camera samples of one pixel together (render_camera_paths):
// estimate(rays, samplers, n, radiance, counters) for n <= Accel::kPacket samples.
template <class Estimate>
constexpr bool kPacketEstimator =
    std::is_invocable_v<Estimate&, const Ray*, Sampler*, int, RGB*, TraceCounters&>;

// One pass of camera paths over task.rect: spp_per_pass samples per pixel, each
// estimate(ray, sampler, counters) -> RGB radiance along the camera ray. With kSplats the rect
// must be the whole frame and the estimator is estimate(ray, sampler, splats, counters): rows are
// traced in chunks whose splat lists are added in chunk order, and the buffer's light-path count
// is its camera sample count (every camera sample carries one light subpath).
// A packet estimator (kPacketEstimator, no splats) gets the pixel's samples in groups of
// Accel::kPacket in sample order, each with its own sampler, and returns their radiances: the
// groups depend on the pixel and the pass only, never on the tile, so tiles stay bit-identical
// to the whole frame.
template <bool kSplats, class Estimate>
SampleBuffer render_camera_paths(const RenderContext& ctx, const TaskKey& task, bool parallel,
                                 Estimate&& estimate) {
  const Rect rect = task.rect;
  SampleBuffer buf(frame_header(ctx.scene, task.frame, PassSet::range(task.pass, task.pass + 1)),
                   rect, kSplats);
  const uint64_t spp = ctx.scene.render.spp_per_pass();
  const Sampler::Kind kind = kind_from_name(ctx.scene.render.sampler);
  const int w = ctx.scene.film.width, h = ctx.scene.film.height;
  const bool aovs = ctx.scene.render.aovs.any();
  driver_detail::Tally tally;

  // Rows are disjoint: no two threads share a pixel.
  auto render_rows = [&](int y_begin, int y_end, std::vector<Splat>* splats) {
    double t0 = driver_detail::thread_cpu_seconds();
    TraceCounters counters;
    uint64_t nonfinite = 0;
    if constexpr (!kSplats && kPacketEstimator<Estimate>) {
      constexpr int K = Accel::kPacket;
      static_assert(K <= Sampler::kMaxLanes);
      std::array<Sampler, K> samplers;
      samplers.fill(Sampler(kind, spp));
      Ray rays[K];
      float filter_weight[K];
      RGB l[K];
      for (int y = y_begin; y < y_end; ++y)
        for (int x = rect.x0; x < rect.x1(); ++x)
          for (uint64_t s0 = 0; s0 < spp; s0 += K) {
            ctx.throw_if_stopped();
            const int n = int(std::min<uint64_t>(K, spp - s0));
            start_camera_samples(ctx, samplers.data(), n, task, x, y, s0, rays, filter_weight);
            if (aovs)
              for (int i = 0; i < n; ++i)
                buf.add_aov_sample(x, y, aov_sample(ctx, rays[i], counters));
            estimate(static_cast<const Ray*>(rays), samplers.data(), n, l, counters);
            for (int i = 0; i < n; ++i) buf.add_sample(x, y, l[i] * filter_weight[i], nonfinite);
          }
    } else {
      Sampler sampler(kind, spp);
      SplatTarget target{splats, w, h, &ctx.scene.film.filter};
      for (int y = y_begin; y < y_end; ++y)
        for (int x = rect.x0; x < rect.x1(); ++x)
          for (uint64_t s = 0; s < spp; ++s) {
            ctx.throw_if_stopped();
            float filter_weight;
            Ray ray = start_camera_sample(ctx, sampler, task, x, y, s, filter_weight);
            if (aovs) buf.add_aov_sample(x, y, aov_sample(ctx, ray, counters));
            RGB l;
            if constexpr (kSplats)
              l = estimate(ray, sampler, target, counters);
            else
              l = estimate(ray, sampler, counters);
            buf.add_sample(x, y, l * filter_weight, nonfinite);
          }
    }
    tally.add(counters, t0, nonfinite);
  };

  if constexpr (kSplats) {
    constexpr int kRowsPerChunk = 4;
    const uint64_t chunks = uint64_t((rect.h + kRowsPerChunk - 1) / kRowsPerChunk);
    for_chunks_in_order<std::vector<Splat>>(
        chunks, parallel,
        [&](uint64_t chunk, std::vector<Splat>& out) {
          out.clear();
          int y0 = rect.y0 + int(chunk) * kRowsPerChunk;
          render_rows(y0, std::min(rect.y1(), y0 + kRowsPerChunk), &out);
        },
        [&](const std::vector<Splat>& out) { buf.add_splats(out); });
    buf.light_paths = spp * uint64_t(rect.area());
  } else if (parallel) {
    tbb::parallel_for(tbb::blocked_range<int>(rect.y0, rect.y1(), 1), [&](const auto& r) {
      for (int y = r.begin(); y < r.end(); ++y) render_rows(y, y + 1, nullptr);
    });
  } else {
    render_rows(rect.y0, rect.y1(), nullptr);
  }
  tally.finish(buf);
  return buf;
}

// render_camera_paths<false> for an estimator that reads per-pass state (instant radiosity's VPLs,
// photon mapping's photons): build(counters) -> shared_ptr<const State> runs once per (frame,
// pass) through the pass cache (the task that runs it counts its rays), then every camera ray is
// estimate(state, ray, sampler, counters).
template <class State, class Build, class Estimate>
SampleBuffer render_camera_paths_with_pass_state(const RenderContext& ctx, const TaskKey& task,
                                                 bool parallel, Build&& build,
                                                 Estimate&& estimate) {
  TraceCounters built;
  std::shared_ptr<const State> state =
      ctx.pass_cache.get<State>(task.frame, task.pass, [&] { return build(built); });
  SampleBuffer buf = render_camera_paths<false>(
      ctx, task, parallel, [&](Ray ray, Sampler& sampler, TraceCounters& counters) {
        return estimate(*state, ray, sampler, counters);
      });
  buf.rays += built.rays;
  return buf;
}

// One pass of light paths over the whole frame: `paths` paths, path i traced by
// trace(sampler, splats, counters) with the sampler started for (seed, frame, pass, i) (light
// paths always use the independent sampler, sampler.h), in fixed chunks of paths whose splats are
// added in chunk order. A scene with an environment also gets camera samples of the environment
// seen directly (driver_detail::environment_camera_samples).
template <class Trace>
SampleBuffer render_light_paths(const RenderContext& ctx, const TaskKey& task, bool parallel,
                                uint64_t paths, Trace&& trace) {
  const int w = ctx.scene.film.width, h = ctx.scene.film.height;
  SampleBuffer buf(frame_header(ctx.scene, task.frame, PassSet::range(task.pass, task.pass + 1)),
                   Rect{0, 0, w, h}, true);
  constexpr uint64_t kChunk = 4096;
  driver_detail::Tally tally;
  for_chunks_in_order<std::vector<Splat>>(
      (paths + kChunk - 1) / kChunk, parallel,
      [&](uint64_t chunk, std::vector<Splat>& out) {
        double t0 = driver_detail::thread_cpu_seconds();
        out.clear();
        TraceCounters counters;
        Sampler sampler(Sampler::Kind::Independent);
        SplatTarget target{&out, w, h, &ctx.scene.film.filter};
        for (uint64_t i = chunk * kChunk; i < std::min(paths, (chunk + 1) * kChunk); ++i) {
          ctx.throw_if_stopped();
          sampler.start_light_path(ctx.scene.render.seed, task.frame, task.pass, i);
          trace(sampler, target, counters);
        }
        tally.add(counters, t0);
      },
      [&](const std::vector<Splat>& out) { buf.add_splats(out); });
  buf.light_paths = paths;
  if (ctx.lights.has_environment())
    driver_detail::environment_camera_samples(ctx, task, parallel, buf, tally);
  if (ctx.scene.render.aovs.any()) driver_detail::light_path_aovs(ctx, task, parallel, buf, tally);
  tally.finish(buf);
  return buf;
}

}  // namespace rf
