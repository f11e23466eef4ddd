#include "bench/bench.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <random>
#include <vector>

#include "engine/buffer_file.h"
#include "engine/camera.h"
#include "engine/frame_accumulator.h"
#include "engine/integrators/drivers.h"
#include "engine/integrators/path/path_tracer.h"
#include "engine/render.h"
#include "engine/sampler.h"
#include "engine/sampling.h"
#include "engine/scene.h"

namespace rf {

namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) {
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// A sphere of lat-long triangles, radius r at c, with a ripple so the BVH is not trivial.
Mesh make_sphere(Vec3 c, float r, int n_theta, int n_phi, uint32_t material) {
  Mesh m;
  m.name = "generated-sphere";
  m.material = material;
  for (int i = 0; i <= n_theta; ++i) {
    float th = kPi * float(i) / float(n_theta);
    for (int j = 0; j < n_phi; ++j) {
      float ph = 2 * kPi * float(j) / float(n_phi);
      float rr = r * (1.0f + 0.03f * std::sin(9 * th) * std::sin(11 * ph));
      m.positions.push_back(
          c + rr * Vec3(std::sin(th) * std::cos(ph), std::cos(th), std::sin(th) * std::sin(ph)));
    }
  }
  for (int i = 0; i < n_theta; ++i)
    for (int j = 0; j < n_phi; ++j) {
      uint32_t a = uint32_t(i * n_phi + j), b = uint32_t(i * n_phi + (j + 1) % n_phi);
      uint32_t c2 = a + uint32_t(n_phi), d = b + uint32_t(n_phi);
      if (i != 0) m.indices.insert(m.indices.end(), {a, b, c2});
      if (i != n_theta - 1) m.indices.insert(m.indices.end(), {b, d, c2});
    }
  return m;
}

// Bare Embree loop: per pixel sample a camera ray and, where it hits, one cosine-distributed
// bounce ray from the hit point; closest-hit queries only, no shading.
double bare_embree_rays_per_second(const Renderer& r, int spp, uint64_t& rays_out) {
  const Scene& s = r.scene();
  PerspectiveCamera cam(s.camera, s.film.width, s.film.height);
  std::atomic<uint64_t> rays{0};
  auto t0 = Clock::now();
  tbb::parallel_for(tbb::blocked_range<int>(0, s.film.height), [&](const auto& range) {
    IndependentSampler sampler;
    uint64_t local = 0;
    for (int y = range.begin(); y < range.end(); ++y)
      for (int x = 0; x < s.film.width; ++x)
        for (int k = 0; k < spp; ++k) {
          sampler.start_camera_sample(1, 0, 0, x, y, uint64_t(k));
          Vec2 u = sampler.get_2d();
          Ray ray = cam.generate_ray(float(x) + u.x, float(y) + u.y, sampler.get_2d());
          SurfaceHit hit;
          ++local;
          if (!r.accel().intersect(ray, hit)) continue;
          Frame f = Frame::from_normal(dot(hit.ng, ray.d) < 0 ? hit.ng : -hit.ng);
          Ray bounce = r.accel().spawn(hit, f.to_world(sample_cosine_hemisphere(sampler.get_2d())));
          ++local;
          r.accel().intersect(bounce, hit);
        }
    rays += local;
  });
  double secs = seconds_since(t0);
  rays_out = rays;
  return double(rays) / secs;
}

// Embree's single-ray query against its 8-wide packets on the same rays: camera rays of 8
// neighbouring pixels per packet (coherent), and their hits' cosine-distributed bounce rays in the
// same order (incoherent, as a wavefront path tracer would batch them). Closest hit only; rays/s of
// each, all cores. Whether packet queries pay is what a wavefront path tracer would bet on.
void packet_comparison(const Renderer& r, int spp) {
  const Scene& s = r.scene();
  PerspectiveCamera cam(s.camera, s.film.width, s.film.height);
  std::vector<Ray> camera_rays, bounce_rays;
  IndependentSampler sampler;
  for (int y = 0; y < s.film.height; ++y)
    for (int k = 0; k < spp; ++k)
      for (int x = 0; x < s.film.width; ++x) {
        sampler.start_camera_sample(1, 0, 0, x, y, uint64_t(k));
        Vec2 u = sampler.get_2d();
        Ray ray = cam.generate_ray(float(x) + u.x, float(y) + u.y, Vec2{0.5f, 0.5f});
        camera_rays.push_back(ray);
        SurfaceHit hit;
        if (!r.accel().intersect(ray, hit)) continue;
        Frame f = Frame::from_normal(dot(hit.ng, ray.d) < 0 ? hit.ng : -hit.ng);
        bounce_rays.push_back(
            r.accel().spawn(hit, f.to_world(sample_cosine_hemisphere(sampler.get_2d()))));
      }
  // Rays/s of one way of casting all rays, in chunks of 4096 over all cores.
  auto rate = [&](const std::vector<Ray>& rays, bool packets) {
    auto t0 = Clock::now();
    const size_t chunk = 4096;
    tbb::parallel_for(size_t(0), (rays.size() + chunk - 1) / chunk, [&](size_t c) {
      size_t b = c * chunk, e = std::min(rays.size(), b + chunk);
      float t[8];
      if (packets)
        for (size_t i = b; i < e; i += 8)
          r.accel().cast8(&rays[i], int(std::min<size_t>(8, e - i)), t);
      else
        for (size_t i = b; i < e; ++i) r.accel().cast(rays[i].o, rays[i].d);
    });
    return double(rays.size()) / seconds_since(t0);
  };
  double cam1 = rate(camera_rays, false), cam8 = rate(camera_rays, true);
  double b1 = rate(bounce_rays, false), b8 = rate(bounce_rays, true);
  std::printf(
      "  Embree 1-ray vs 8-ray packets: camera rays %.2f / %.2f Mrays/s (x%.2f), bounce rays "
      "%.2f / %.2f Mrays/s (x%.2f)\n",
      cam1 / 1e6, cam8 / 1e6, cam8 / cam1, b1 / 1e6, b8 / 1e6, b8 / b1);
}

// The path tracer's two ways of casting (PathTracer::radiance): each pixel's samples one at a time
// with single-ray queries, and 16 at a time in lockstep with packet queries; one pass of the frame
// through the render driver on all cores each, three rounds alternating the two (the best of
// each: a shared VM's speed drifts over seconds; docs/performance.md, "Machines and how to read
// the figures"). Samples/s of both, and how many pixel sums differ in any bit (0 is the path
// tracer's contract, except where a ray meets two triangles at one distance and Embree's two
// kernels report different ones: see integrators/path/packets.h).
void path_packet_comparison(const Renderer& r) {
  const RenderContext& ctx = r.context();
  const PathTracer tracer(ctx);
  const TaskKey task{0, Rect{0, 0, r.scene().film.width, r.scene().film.height}, 0};
  SampleBuffer out[2];
  double rate[2] = {0, 0};
  for (int round = 0; round < 6; ++round) {
    const bool packets = round % 2 == 1;
    auto t0 = Clock::now();
    out[packets] = render_camera_paths<false>(
        ctx, task, true,
        [&](const Ray* rays, Sampler* samplers, int n, RGB* radiance, TraceCounters& counters) {
          tracer.radiance(rays, samplers, n, radiance, counters, packets);
        });
    rate[packets] =
        std::max(rate[packets], double(out[packets].total_samples()) / seconds_since(t0));
  }
  size_t differ = 0;
  for (size_t i = 0; i < out[0].sum.size(); i += 3)
    differ += std::memcmp(&out[0].sum[i], &out[1].sum[i], 3 * sizeof(out[0].sum[i])) != 0;
  std::printf(
      "  path, single-ray queries vs 16-sample packets: %.3f / %.3f Msamples/s (x%.2f), %zu of %zu "
      "pixels differ\n",
      rate[0] / 1e6, rate[1] / 1e6, rate[1] / rate[0], differ, out[0].sum.size() / 3);
}

void bench_scene(const std::string& label, const Scene& scene, int spp) {
  auto tb = Clock::now();
  Renderer r(scene);
  double build_s = seconds_since(tb);
  size_t tris = 0;
  for (const Mesh& m : scene.meshes) tris += m.triangle_count();

  uint64_t bare_rays = 0;
  double bare = bare_embree_rays_per_second(r, spp, bare_rays);

  auto t0 = Clock::now();
  Rect full{0, 0, scene.film.width, scene.film.height};
  SampleBuffer b = r.render(TaskKey{0, full, 0}, /*parallel=*/true);
  double secs = seconds_since(t0);
  double samples = double(b.total_samples());
  double path_rays = double(b.rays) / secs;
  std::printf(
      "%-22s %9zu tris  BVH %.2f s | path: %8.3f Msamples/s %8.2f Mrays/s | bare Embree: "
      "%8.2f Mrays/s | ratio %.3f\n",
      label.c_str(), tris, build_s, samples / secs / 1e6, path_rays / 1e6, bare / 1e6,
      path_rays / bare);
  packet_comparison(r, spp);
  path_packet_comparison(r);
}

// The Cornell box plus about `triangles` triangles of rippled spheres: one diffuse sphere, or four
// of diffuse, rough plastic, rough gold and glass (the materials issue's benchmark).
Scene with_generated_spheres(Scene s, int triangles, bool materials) {
  int count = materials ? 4 : 1;
  // Each sphere has n_theta * n_phi * 2 - 2 * n_phi triangles with n_phi = 2 n_theta.
  int n_theta = std::max(4, int(std::sqrt(double(triangles) / count / 4.0)));
  std::vector<uint32_t> mats(4, s.meshes[0].material);
  if (materials) {
    auto add = [&](Material m) {
      s.materials.push_back(m);
      return uint32_t(s.materials.size() - 1);
    };
    Material plastic{"bench-plastic", MaterialType::Plastic, {RGB(0.2f, 0.3f, 0.8f)}};
    plastic.roughness.value = 0.2f;
    Material gold{"bench-gold", MaterialType::RoughConductor};
    gold.roughness.value = 0.15f;
    Material glass{"bench-glass", MaterialType::Dielectric};
    mats = {s.meshes[0].material, add(plastic), add(gold), add(glass)};
  }
  for (int i = 0; i < count; ++i) {
    float r = materials ? 0.22f : 0.45f;
    Vec3 c = materials ? Vec3(-0.55f + 0.37f * float(i), 1.45f - 0.12f * float(i % 2), 0.45f)
                       : Vec3(0.0f, 0.8f, 0.3f);
    s.meshes.push_back(make_sphere(c, r, n_theta, 2 * n_theta, mats[size_t(i)]));
  }
  s.digest = "generated";
  return s;
}

// Every integrator on the Cornell box: one pass of the whole frame on all cores. Light tracing
// counts light paths (as many per pass as camera samples: spp per pixel).
void bench_integrators(const std::string& cornell, SceneOverrides ov) {
  std::printf("\nintegrators on cornell-box (one pass, all cores):\n");
  for (const std::string& name : known_integrators()) {
    ov.integrator = name;
    Scene s = load_scene(cornell, ov);
    Renderer r(s);
    auto t0 = Clock::now();
    SampleBuffer b = r.render(TaskKey{0, Rect{0, 0, s.film.width, s.film.height}, 0}, true);
    double secs = seconds_since(t0);
    double work = double(b.total_samples() ? b.total_samples() : b.light_paths);
    std::printf("  %-8s %8.3f M%s/s %8.2f Mrays/s\n", name.c_str(), work / secs / 1e6,
                b.light_paths ? "light paths" : "samples", double(b.rays) / secs / 1e6);
  }
}

// Splat accumulation, the light tracer's choice: each chunk of paths records its splats in a list
// and the lists are added in chunk order (deterministic), against every thread adding into one
// shared plane with atomic fetch_add on doubles (non-deterministic: float addition order varies).
void bench_splat_accumulation(bool quick) {
  const int w = 256, h = 256;
  const uint64_t splats = quick ? (1u << 18) : (1u << 24), chunk = 4096 * 5;
  std::vector<double> plane(size_t(w) * h * 3, 0.0);
  auto key = [](uint64_t i) { return mix64(i * 0x9e3779b97f4a7c15ULL); };
  auto t0 = Clock::now();
  tbb::parallel_for(uint64_t(0), splats, [&](uint64_t i) {
    uint64_t k = key(i);
    size_t px = size_t(k % uint64_t(w * h));
    for (int c = 0; c < 3; ++c)
      std::atomic_ref<double>(plane[3 * px + size_t(c)]).fetch_add(double(k >> 40) * 0x1p-24);
  });
  double atomic_s = seconds_since(t0);
  std::fill(plane.begin(), plane.end(), 0.0);
  uint64_t chunks = (splats + chunk - 1) / chunk;
  size_t wave = size_t(8 * tbb::this_task_arena::max_concurrency());
  std::vector<std::vector<std::pair<uint32_t, float>>> lists(wave);
  t0 = Clock::now();
  for (uint64_t first = 0; first < chunks; first += wave) {
    size_t n = size_t(std::min<uint64_t>(wave, chunks - first));
    tbb::parallel_for(size_t(0), n, [&](size_t j) {
      lists[j].clear();
      for (uint64_t i = (first + j) * chunk; i < std::min(splats, (first + j + 1) * chunk); ++i) {
        uint64_t k = key(i);
        lists[j].push_back({uint32_t(k % uint64_t(w * h)), float(k >> 40) * 0x1p-24f});
      }
    });
    for (size_t j = 0; j < n; ++j)
      for (auto [px, v] : lists[j])
        for (int c = 0; c < 3; ++c) plane[3 * size_t(px) + size_t(c)] += double(v);
  }
  double list_s = seconds_since(t0);
  std::printf(
      "\nsplat accumulation, %llu splats into %dx%d: atomic fetch_add %.1f Msplats/s, "
      "chunk lists merged in order %.1f Msplats/s\n",
      (unsigned long long)splats, w, h, double(splats) / atomic_s / 1e6,
      double(splats) / list_s / 1e6);
}

}  // namespace

void add_bench_options(CLI::App& app, BenchOptions& o) {
  app.add_option("--scene", o.scenes, "scene files to benchmark (default: scenes/cornell-box)");
  app.add_option("--spp", o.spp, "samples per pixel per measurement")->check(CLI::Range(1.0, 1e6));
  app.add_option("--res", o.res, "square resolution")->check(CLI::Range(1.0, 16384.0));
  app.add_option("--triangles", o.triangles, "triangles of the generated scene")
      ->check(CLI::Range(1.0, 1e9));
  app.add_flag("!--no-generated", o.generated, "skip the generated scene");
  app.add_flag("--quick", o.quick, "a tiny run that only checks the benchmark works");
}

// Merge throughput, the coordinator's work per completed task, on one core: reassemble the
// task's bytes from 1 MiB chunks (ChunkAssembler's one copy), decode them where they lie
// (EncodedBuffer: the XXH3 checksum and the header), and hand them to the frame accumulator,
// which adds each complete pass's tiles into the frame. Reported in GB/s of encoded task buffers,
// against a memcpy of the same bytes in the same run, and best of `rounds`.
void bench_merge(bool quick) {
  keep_heap_for_sample_buffers();  // as the coordinator does
  const int size = quick ? 64 : 512, tile = quick ? 32 : 64;
  const uint32_t passes = quick ? 2 : 8;
  const int rounds = quick ? 1 : 5;
  BufferHeader h;
  h.scene_digest = "bench";
  h.integrator = "path";
  h.width = h.height = size;
  TileGrid tiles(size, size, tile);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<std::string> wire;
  for (uint32_t p = 0; p < passes; ++p)
    for (const Rect& r : tiles) {
      BufferHeader th = h;
      th.passes = PassSet::range(p, p + 1);
      SampleBuffer b(th, r, false);
      for (int y = r.y0; y < r.y1(); ++y)
        for (int x = r.x0; x < r.x1(); ++x)
          for (int s = 0; s < 4; ++s)
            b.add_sample(x, y, RGB(float(u(rng)), float(u(rng)), float(u(rng))));
      b.finish_pass();
      wire.push_back(encode_buffer(b));
    }
  double bytes = 0;
  for (const std::string& w : wire) bytes += double(w.size());
  const ProgressiveOptions po{0, passes, 0};
  using Clock = std::chrono::steady_clock;
  auto secs = [](Clock::time_point a) {
    return std::chrono::duration<double>(Clock::now() - a).count();
  };
  // What ChunkAssembler does: one string, reserved, appended chunk by chunk.
  auto reassemble = [](const std::string& w) {
    std::string out;
    out.reserve(w.size());
    for (size_t at = 0; at < w.size(); at += size_t(1) << 20)
      out.append(w, at, std::min(w.size() - at, size_t(1) << 20));
    return out;
  };
  double best_memcpy = 1e30, best_all = 1e30, best_dm = 1e30, best_decode = 1e30, best_merge = 1e30,
         best_copying = 1e30;
  std::string sink(wire.front().size(), '\0');
  for (int round = 0; round < rounds; ++round) {
    auto t = Clock::now();  // the baseline: each task's bytes copied once
    for (const std::string& w : wire) {
      if (sink.size() < w.size()) sink.resize(w.size());
      std::memcpy(sink.data(), w.data(), w.size());
    }
    best_memcpy = std::min(best_memcpy, secs(t));
    {  // the coordinator's path, task after task: reassemble, decode in place, merge
      FrameAccumulator acc(h, tiles, false, po);
      t = Clock::now();
      for (const std::string& w : wire) acc.add(EncodedBuffer(reassemble(w), "bench"));
      best_all = std::min(best_all, secs(t));
      if (!acc.done()) throw std::runtime_error("bench: the frame did not complete");
    }
    {  // decode + merge task after task, the bytes received already
      std::vector<std::string> copies = wire;
      FrameAccumulator acc(h, tiles, false, po);
      t = Clock::now();
      for (std::string& w : copies) acc.add(EncodedBuffer(std::move(w), "bench"));
      best_dm = std::min(best_dm, secs(t));
    }
    {  // the parts alone
      std::vector<std::string> copies = wire;
      std::vector<EncodedBuffer> decoded;
      decoded.reserve(copies.size());
      t = Clock::now();
      for (std::string& w : copies) decoded.emplace_back(std::move(w), "bench");
      best_decode = std::min(best_decode, secs(t));
      FrameAccumulator acc(h, tiles, false, po);
      t = Clock::now();
      for (EncodedBuffer& b : decoded) acc.add(std::move(b));
      best_merge = std::min(best_merge, secs(t));
    }
    {  // decoding into owned planes (a second copy), as the coordinator did before
      FrameAccumulator acc(h, tiles, false, po);
      t = Clock::now();
      for (const std::string& w : wire) acc.add(decode_buffer(reassemble(w), "bench"));
      best_copying = std::min(best_copying, secs(t));
    }
  }
  std::printf(
      "\nmerge (one core, best of %d): %zu task buffers of %dx%d px, %.1f MB encoded, frame "
      "%dx%d, %u passes\n",
      rounds, wire.size(), tile, tile, bytes / 1e6, size, size, passes);
  auto gbs = [&](double s) { return bytes / s / 1e9; };
  std::printf(
      "  decode + merge %.2f GB/s (memcpy %.2f GB/s, ratio %.2f) | with the receive copy %.2f GB/s "
      "(ratio %.2f)\n  decode alone %.2f GB/s | merge alone %.2f GB/s | with the receive copy and "
      "decoding into copied planes: %.2f GB/s\n",
      gbs(best_dm), gbs(best_memcpy), best_memcpy / best_dm, gbs(best_all), best_memcpy / best_all,
      gbs(best_decode), gbs(best_merge), gbs(best_copying));
}

int run_bench(const BenchOptions& in) {
  BenchOptions o = in;
  if (o.quick) o.spp = 1, o.res = 32, o.triangles = 20000;
  std::vector<std::string> scenes = o.scenes;
  std::string cornell = std::string(RAYFARM_SOURCE_DIR) + "/scenes/cornell-box/scene.json";
  if (scenes.empty()) scenes.push_back(cornell);
  std::printf("rayfarm bench: %d threads, %dx%d, %d spp, max depth from each scene\n",
              tbb::this_task_arena::max_concurrency(), o.res, o.res, o.spp);
  std::printf(
      "(rays/s: path counts closest-hit and shadow rays; bare Embree casts a camera ray "
      "and one diffuse bounce per sample, closest-hit only)\n");
  SceneOverrides ov;
  ov.width = ov.height = o.res;
  ov.spp = uint64_t(o.spp);
  ov.passes = 1;
  for (const std::string& path : scenes) {
    Scene s = load_scene(path, ov);
    bench_scene(std::filesystem::path(path).parent_path().filename().string(), s, o.spp);
  }
  bench_integrators(cornell, ov);
  bench_splat_accumulation(o.quick);
  bench_merge(o.quick);
  if (o.generated) {
    Scene s = load_scene(cornell, ov);
    bench_scene("generated (cornell+sphere)", with_generated_spheres(s, o.triangles, false), o.spp);
    bench_scene("generated, 4 materials", with_generated_spheres(s, o.triangles, true), o.spp);
  }
  return 0;
}

}  // namespace rf
