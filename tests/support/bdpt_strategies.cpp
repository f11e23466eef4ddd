#include "tests/support/bdpt_strategies.h"

#include <algorithm>

#include "engine/integrators/bdpt.h"
#include "engine/integrators/drivers.h"
#include "engine/render.h"

namespace rf {

namespace {

// Collects one pass's strategy images (render_bdpt_strategies).
struct ImageRecorder final : BdptStrategyRecorder {
  ImageRecorder(StrategyImages& o, const FilterSettings& f) : out(o), filter(f) {}
  StrategyImages& out;
  const FilterSettings& filter;
  std::vector<int> index;  // strategy slot by depth-major (s, t) key, -1 when not shown
  // Per camera sample: its t >= 2 records, committed once its total is known to be finite.
  struct Pending {
    int slot;
    RGB weighted, unweighted;
  };
  std::vector<Pending> pending;
  std::vector<Splat> scratch;

  int slot(int s, int t) const {
    int d = s + t - 2;
    if (d > out.max_shown_depth) return -1;
    return index[size_t(d) * size_t(out.max_shown_depth + 3) + size_t(s)];
  }
  void camera(int s, int t, RGB weighted, RGB unweighted) override {
    pending.push_back({slot(s, t), weighted, unweighted});
  }
  void splat(int s, int t, Vec2 raster, RGB weighted, RGB unweighted) override {
    int k = slot(s, t);
    add_splat(raster, weighted, k >= 0 ? out.images[size_t(k)].weighted : out.rest);
    if (k >= 0) add_splat(raster, unweighted, out.images[size_t(k)].unweighted);
  }
  void add_splat(Vec2 raster, RGB value, std::vector<double>& img) {
    scratch.clear();
    SplatTarget target{&scratch, out.width, out.height, &filter};
    splat_to_film(target, raster, value);
    for (const Splat& sp : scratch)
      for (int c = 0; c < 3; ++c) img[3 * size_t(sp.pixel) + size_t(c)] += double(sp.value[c]);
  }
};

}  // namespace

StrategyImages render_bdpt_strategies(const Scene& scene, uint32_t pass, int max_shown_depth,
                                      FrameNumber frame) {
  Renderer renderer(scene);
  const RenderContext& ctx = renderer.context();
  const int w = scene.film.width, h = scene.film.height;
  const size_t pixels = size_t(w) * size_t(h);
  const RenderSettings& rs = scene.render;

  StrategyImages out;
  out.width = w;
  out.height = h;
  out.max_shown_depth = std::max(0, max_shown_depth);
  out.rest.assign(3 * pixels, 0.0);
  ImageRecorder rec(out, scene.film.filter);
  const size_t stride = size_t(out.max_shown_depth + 3);
  rec.index.assign(size_t(out.max_shown_depth + 1) * stride, -1);
  for (int d = 0; d <= out.max_shown_depth; ++d)
    for (int s = 0; s <= d + 1; ++s) {
      if (s == 1 && d == 0) continue;
      rec.index[size_t(d) * stride + size_t(s)] = int(out.images.size());
      out.images.push_back({s, d + 2 - s, std::vector<double>(3 * pixels, 0.0),
                            std::vector<double>(3 * pixels, 0.0)});
    }
  // Camera strategies are summed per pixel first and divided by the pixel's sample count at the
  // end; splats are divided by the light path count (camera samples of the frame).
  const uint64_t spp = rs.spp_per_pass();
  std::vector<double> rest_camera(3 * pixels, 0.0);
  std::vector<std::vector<double>> cam_w(out.images.size(), std::vector<double>(3 * pixels, 0.0));
  std::vector<std::vector<double>> cam_u = cam_w;

  TraceCounters counters;
  Sampler sampler(kind_from_name(rs.sampler));
  const TaskKey task{frame, Rect{0, 0, w, h}, pass};
  std::vector<Splat> ignored;
  SplatTarget target{&ignored, w, h, &scene.film.filter};
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (uint64_t k = 0; k < spp; ++k) {
        float filter_weight;
        Ray ray = start_camera_sample(ctx, sampler, task, x, y, k, filter_weight);
        rec.pending.clear();
        RGB l = bdpt_camera_sample(ctx, ray, sampler, target, counters, task.frame, &rec);
        ignored.clear();
        if (!is_finite(l * filter_weight)) continue;  // SampleBuffer drops the whole sample
        size_t p = 3 * (size_t(y) * size_t(w) + size_t(x));
        for (const ImageRecorder::Pending& r : rec.pending)
          for (int c = 0; c < 3; ++c) {
            double wv = double(r.weighted[c] * filter_weight),
                   uv = double(r.unweighted[c] * filter_weight);
            if (r.slot < 0) {
              rest_camera[p + size_t(c)] += wv;
            } else {
              cam_w[size_t(r.slot)][p + size_t(c)] += wv;
              cam_u[size_t(r.slot)][p + size_t(c)] += uv;
            }
          }
      }
  const double inv_spp = spp > 0 ? 1.0 / double(spp) : 0.0;
  const double inv_paths = spp > 0 ? 1.0 / double(spp * pixels) : 0.0;
  for (size_t i = 0; i < 3 * pixels; ++i) {
    out.rest[i] = out.rest[i] * inv_paths + rest_camera[i] * inv_spp;
    for (size_t k = 0; k < out.images.size(); ++k) {
      StrategyImage& img = out.images[k];
      img.weighted[i] = img.weighted[i] * inv_paths + cam_w[k][i] * inv_spp;
      img.unweighted[i] = img.unweighted[i] * inv_paths + cam_u[k][i] * inv_spp;
    }
  }
  return out;
}

}  // namespace rf
