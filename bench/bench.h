// `rayfarm bench`: the path tracer's throughput next to a bare Embree ray-cast loop on the same
// scene in the same run, and their ratio (CONVENTIONS.md: benchmarks report ratios).
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

namespace rf {

struct BenchOptions {
  std::vector<std::string> scenes;  // default: the shipped Cornell box
  bool generated = true;            // also the generated ~1M-triangle scene
  int spp = 16;
  int res = 256;
  int triangles = 1000000;
  bool quick = false;               // tiny run (for the test suite: it runs, not how fast)
};

void add_bench_options(CLI::App& app, BenchOptions& o);
int run_bench(const BenchOptions& o);

}  // namespace rf
