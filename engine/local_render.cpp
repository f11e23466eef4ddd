#include "engine/local_render.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>

#include "engine/frame_accumulator.h"

namespace rf {

LocalRenderResult render_local(const Renderer& renderer, const LocalRenderOptions& opt) {
  using clock = std::chrono::steady_clock;
  const Scene& scene = renderer.scene();
  uint32_t total_passes = scene.render.passes;
  uint32_t count = opt.pass_count ? opt.pass_count : total_passes - opt.first_pass;
  TileGrid tiles = renderer.tiles(opt.tile_size);
  ProgressiveOptions popt{opt.first_pass, count, opt.noise_target};
  popt.memory_budget = opt.memory_budget;
  popt.spill_dir = opt.spill_dir;
  auto acc_owner = std::make_unique<FrameAccumulator>(renderer.header(opt.frame, PassSet{}), tiles,
                                                      renderer.splats(), popt);
  FrameAccumulator& acc = *acc_owner;

  // Passes are rendered in windows of passes whose tasks run in parallel (each task also spreads
  // its rows over threads: TBB balances the nesting); each result goes to the accumulator as it
  // is made, which merges in (pass, tile) order, so no window's results are ever held together
  // beyond the accumulator's memory budget. The stop tests run after every pass. A window of one
  // pass when a pass has enough tiles keeps the stop decisions (noise target, time budget)
  // fine-grained.
  int threads = tbb::this_task_arena::max_concurrency();
  uint32_t window = tiles.size() >= size_t(threads) ? 1u : 2u;
  auto start = clock::now();
  std::atomic<uint64_t> tasks_done{0};
  LocalProgress prog;
  prog.tasks_total = uint64_t(count) * tiles.size();
  prog.passes_total = count;
  std::mutex mu;
  std::condition_variable cv;
  bool finished = false;
  auto report = [&](bool last) {
    LocalProgress p;
    {
      std::lock_guard<std::mutex> lock(mu);
      p = prog;
    }
    p.tasks_done = tasks_done.load();
    p.finished = last;
    p.seconds = std::chrono::duration<double>(clock::now() - start).count();
    if (opt.progress) opt.progress(p);
  };
  // The merged prefix's figures, for the reports that follow.
  auto note_merged = [&] {
    std::lock_guard<std::mutex> lock(mu);
    prog.passes_merged = acc.passes_merged();
    prog.rel_mse = acc.rel_mse_history().empty() ? 0 : acc.rel_mse_history().back();
  };
  // Over the time budget, the tasks in flight are stopped where they are (a pass may be long),
  // and the passes they belong to are dropped: the image is the prefix completed before.
  auto over_budget = [&] {
    return opt.time_budget_s > 0 &&
           std::chrono::duration<double>(clock::now() - start).count() >= opt.time_budget_s;
  };
  std::thread monitor([&] {
    std::unique_lock<std::mutex> lock(mu);
    while (!finished) {
      cv.wait_for(lock, std::chrono::milliseconds(200));
      if (finished) break;
      lock.unlock();
      if (over_budget()) renderer.request_stop();
      report(false);
      lock.lock();
    }
  });

  bool stopped_on_time = false;
  try {
    for (uint32_t p0 = opt.first_pass; p0 < opt.first_pass + count && !acc.done(); p0 += window) {
      if (over_budget()) {
        stopped_on_time = true;
        break;
      }
      uint32_t p1 = std::min(opt.first_pass + count, p0 + window);
      size_t n = size_t(p1 - p0) * tiles.size();
      std::mutex acc_mu;
      try {
        tbb::parallel_for(size_t(0), n, [&](size_t i) {
          TaskKey task{opt.frame, tiles[i % tiles.size()], p0 + uint32_t(i / tiles.size())};
          SampleBuffer r = renderer.render(task, /*parallel=*/true);  // nested: TBB balances
          ++tasks_done;
          std::lock_guard<std::mutex> lock(acc_mu);
          acc.add(std::move(r));
        });
      } catch (const RenderStopped&) {
        renderer.resume();
        stopped_on_time = true;
        break;
      }
      note_merged();
    }
  } catch (...) {
    {
      std::lock_guard<std::mutex> lock(mu);
      finished = true;
    }
    cv.notify_all();
    monitor.join();
    throw;
  }
  {
    std::lock_guard<std::mutex> lock(mu);
    finished = true;
  }
  cv.notify_all();
  monitor.join();
  note_merged();  // the last pass's merge, and a stop's early end
  report(true);

  LocalRenderResult res;
  if (acc.tiled()) {
    res.frame = acc.info();  // header and counters; the pixels stay in the tiles
    res.tiles = std::move(acc_owner);
  } else {
    res.frame = acc.frame();
  }
  res.passes_merged = acc.passes_merged();
  res.stopped_on_target = acc.stopped_on_target();
  res.stopped_on_time = stopped_on_time;
  res.seconds = std::chrono::duration<double>(clock::now() - start).count();
  res.rays = acc.info().rays;  // of the merged tasks
  return res;
}

}  // namespace rf
