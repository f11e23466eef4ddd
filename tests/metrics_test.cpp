// The coordinator's Prometheus metrics (coordinator/metrics.h): the families a core snapshot
// becomes, and a real coordinator scraped over HTTP while a real job runs: the counters move
// with the job and end where the job's own figures say, the job's series vanish when it ends,
// and every query of the shipped Grafana dashboard and Kubernetes autoscalers names a metric
// the coordinator serves.
#include <gtest/gtest.h>
#include <prometheus/metric_family.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>
#include <string>

#include "coordinator/metrics.h"
#include "farm/tags.h"
#include "tests/support/farm.h"
#include "tests/support/net.h"
#include "tests/support/test_support.h"

namespace rf {
namespace {

using test::http_get;

// A text exposition: each sample "name{labels}" -> value, and the families' names and types.
struct Scrape {
  std::map<std::string, double> samples;
  std::map<std::string, std::string> types;
  std::string text;
  double at(const std::string& key) const {
    auto it = samples.find(key);
    return it == samples.end() ? NAN : it->second;
  }
  bool has_prefix(const std::string& prefix) const {
    auto it = samples.lower_bound(prefix);
    return it != samples.end() && it->first.rfind(prefix, 0) == 0;
  }
};

Scrape parse(const std::string& text) {
  Scrape s;
  s.text = text;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("# TYPE ", 0) == 0) {
      std::istringstream t(line.substr(7));
      std::string name, type;
      t >> name >> type;
      s.types[name] = type;
    } else if (!line.empty() && line[0] != '#') {
      size_t space = line.rfind(' ');
      s.samples[line.substr(0, space)] = std::stod(line.substr(space + 1));
    }
  }
  return s;
}

Scrape scrape(int port) {
  std::string error;
  std::string body = http_get(port, "/metrics", error);
  EXPECT_EQ(error, "");
  return parse(body);
}

// The metric names a text mentions (rayfarm_...), a histogram's _bucket/_sum/_count series
// named by their family.
std::set<std::string> metric_names_in(const std::string& text, const Scrape& served) {
  std::set<std::string> out;
  std::regex name("rayfarm_[a-z_]+[a-z]");
  for (auto it = std::sregex_iterator(text.begin(), text.end(), name); it != std::sregex_iterator();
       ++it) {
    std::string n = it->str();
    for (const char* suffix : {"_bucket", "_sum", "_count"}) {
      std::string s = suffix;
      if (n.size() > s.size() && n.compare(n.size() - s.size(), s.size(), s) == 0 &&
          served.types.count(n.substr(0, n.size() - s.size())))
        n = n.substr(0, n.size() - s.size());
    }
    out.insert(n);
  }
  return out;
}

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(Metrics, ASnapshotBecomesFamiliesWithJobSeriesOnlyForLiveJobs) {
  CoordinatorMetrics m;
  m.counters.tasks_leased = 7;
  m.counters.lease_calls = 3;
  m.counters.lease_seconds = 0.003;
  m.counters.lease_buckets.assign(std::size(CoordinatorMetrics::kLeaseBuckets), 0);
  m.counters.lease_buckets[0] = 2;  // <= 0.5 ms
  m.counters.lease_buckets[4] = 1;  // <= 10 ms
  m.tasks_queued = 5;
  m.tasks_paused = 3;
  m.counters.jobs_expired = 4;
  m.blob_store_bytes = 1234;
  m.jobs_by_state[size_t(JobState::Running)] = 1;
  CoordinatorMetrics::Job j;
  j.job_id = "j000004";
  j.tasks_queued = 5;
  j.tasks_leased = 1;
  FrameStatus one{1, {}}, two{2, {}};
  one.progress.passes_merged = 1;  // relMSE unknown before two passes
  one.progress.passes_total = 4;
  two.progress.passes_merged = 3;
  two.progress.passes_total = 4;
  two.progress.rel_mse = 0.01;
  two.progress.eta_seconds = 12;
  j.frames = {one, two};
  m.jobs.push_back(j);
  m.pools[kAnyPool] = {2, 1};
  m.pools["gpu"] = {3, 0};
  std::map<std::string, const prometheus::MetricFamily*> by_name;
  std::vector<prometheus::MetricFamily> families = metric_families(m);
  for (const auto& f : families) by_name[f.name] = &f;
  ASSERT_TRUE(by_name.count("rayfarm_tasks_leased_total"));
  EXPECT_EQ(by_name["rayfarm_tasks_leased_total"]->type, prometheus::MetricType::Counter);
  EXPECT_EQ(by_name["rayfarm_tasks_leased_total"]->metric.at(0).counter.value, 7);
  EXPECT_EQ(by_name["rayfarm_tasks_queued"]->metric.at(0).gauge.value, 5);
  EXPECT_EQ(by_name["rayfarm_tasks_paused"]->metric.at(0).gauge.value, 3);
  EXPECT_EQ(by_name["rayfarm_jobs_expired_total"]->metric.at(0).counter.value, 4);
  EXPECT_EQ(by_name["rayfarm_blob_store_bytes"]->metric.at(0).gauge.value, 1234);
  const auto& pools = by_name["rayfarm_pool_tasks_queued"]->metric;  // by pool name
  ASSERT_EQ(pools.size(), 2u);
  EXPECT_EQ(pools[0].label.at(0).value, "any");
  EXPECT_EQ(pools[0].gauge.value, 2);
  EXPECT_EQ(pools[1].label.at(0).value, "gpu");
  EXPECT_EQ(pools[1].gauge.value, 3);
  EXPECT_EQ(by_name["rayfarm_pool_tasks_in_flight"]->metric.at(0).gauge.value, 1);
  const auto& h = by_name["rayfarm_lease_duration_seconds"]->metric.at(0).histogram;
  EXPECT_EQ(h.sample_count, 3u);
  ASSERT_EQ(h.bucket.size(), std::size(CoordinatorMetrics::kLeaseBuckets) + 1);
  EXPECT_EQ(h.bucket[0].cumulative_count, 2u);
  EXPECT_EQ(h.bucket[3].cumulative_count, 2u);
  EXPECT_EQ(h.bucket[4].cumulative_count, 3u);
  EXPECT_TRUE(std::isinf(h.bucket.back().upper_bound));
  EXPECT_EQ(h.bucket.back().cumulative_count, 3u);
  const auto& rel = by_name["rayfarm_frame_relmse"]->metric;
  ASSERT_EQ(rel.size(), 1u) << "frame 1 has one pass: no relMSE yet";
  EXPECT_EQ(rel[0].gauge.value, 0.01);
  EXPECT_EQ(rel[0].label.at(0).value, "2");
  EXPECT_EQ(rel[0].label.at(1).value, "j000004");
  EXPECT_EQ(by_name["rayfarm_frame_progress_ratio"]->metric.size(), 2u);
  EXPECT_EQ(by_name["rayfarm_job_tasks_queued"]->metric.at(0).label.at(0).value, "j000004");

  m.jobs.clear();  // the job ended: its series go, the families stay
  by_name.clear();
  families = metric_families(m);
  for (const auto& f : families) by_name[f.name] = &f;
  EXPECT_TRUE(by_name["rayfarm_job_tasks_queued"]->metric.empty());
  EXPECT_TRUE(by_name["rayfarm_frame_relmse"]->metric.empty());
}

TEST(Metrics, AScrapeDuringARealJobMovesWithItAndEndsAtTheJobsFigures) {
  test::Farm farm("farm-metrics", /*lease_seconds=*/30, "", {"--metrics-listen", "127.0.0.1:0"});
  std::smatch m;
  std::string log = farm.coordinator().log();
  ASSERT_TRUE(std::regex_search(log, m, std::regex("metrics port ([0-9]+)"))) << log;
  int port = std::stoi(m[1]);
  ASSERT_GT(port, 0);

  Scrape idle = scrape(port);
  for (const char* name :
       {"rayfarm_tasks_queued", "rayfarm_tasks_leased_total", "rayfarm_tasks_completed_total",
        "rayfarm_tasks_failed_total", "rayfarm_leases_expired_total",
        "rayfarm_results_refused_total", "rayfarm_samples_merged_total",
        "rayfarm_merged_bytes_total", "rayfarm_workers_connected", "rayfarm_lease_duration_seconds",
        "rayfarm_job_tasks_queued", "rayfarm_frame_relmse", "rayfarm_frame_eta_seconds",
        "rayfarm_pool_tasks_queued", "rayfarm_pool_tasks_in_flight"})
    EXPECT_TRUE(idle.types.count(name)) << name << " is not served:\n" << idle.text;
  EXPECT_EQ(idle.at("rayfarm_pool_tasks_queued{pool=\"any\"}"), 0) << idle.text;
  EXPECT_EQ(idle.types["rayfarm_tasks_leased_total"], "counter");
  EXPECT_EQ(idle.types["rayfarm_lease_duration_seconds"], "histogram");
  EXPECT_EQ(idle.at("rayfarm_tasks_queued"), 0);
  std::string error;
  EXPECT_EQ(http_get(port, "/other", error), "");
  EXPECT_NE(error, "") << "only /metrics is served";

  // 8 passes of one tile: 8 tasks.
  const std::string args =
      "scenes/cornell-box/scene.json --spp 64 --passes 8 --res 32x32 --tile-size 32";
  std::string job = farm.submit(args);
  const std::string jl = "{job=\"" + job + "\"}";
  Scrape queued = scrape(port);
  EXPECT_EQ(queued.at("rayfarm_tasks_queued"), 8);
  EXPECT_EQ(queued.at("rayfarm_pool_tasks_queued{pool=\"any\"}"), 8) << queued.text;
  EXPECT_EQ(queued.at("rayfarm_job_tasks_queued" + jl), 8) << queued.text;
  EXPECT_EQ(queued.at("rayfarm_jobs{state=\"queued\"}"), 1);

  // A worker that leaves after 3 tasks: the job is part done.
  test::Process& first = farm.worker({"--max-tasks", "3"});
  ASSERT_EQ(first.wait(120), 0) << first.log();
  Scrape mid = scrape(port);
  EXPECT_EQ(mid.at("rayfarm_tasks_completed_total"), 3) << mid.text;
  EXPECT_EQ(mid.at("rayfarm_samples_merged_total"), 3 * 8 * 32 * 32);
  EXPECT_EQ(mid.at("rayfarm_job_tasks_queued" + jl), 5);
  EXPECT_EQ(mid.at("rayfarm_tasks_queued"), 5);
  EXPECT_EQ(mid.at("rayfarm_pool_tasks_queued{pool=\"any\"}"), 5);
  EXPECT_EQ(mid.at("rayfarm_jobs{state=\"running\"}"), 1);
  EXPECT_EQ(mid.at("rayfarm_workers_connected"), 1) << "heard from within a lease time";
  const std::string fl = "{frame=\"0\",job=\"" + job + "\"}";
  EXPECT_DOUBLE_EQ(mid.at("rayfarm_frame_progress_ratio" + fl), 3.0 / 8) << mid.text;
  EXPECT_GT(mid.at("rayfarm_frame_relmse" + fl), 0) << mid.text;
  EXPECT_GE(mid.at("rayfarm_frame_eta_seconds" + fl), 0) << mid.text;
  EXPECT_GT(mid.at("rayfarm_merged_bytes_total"), 0);
  EXPECT_GE(mid.at("rayfarm_lease_duration_seconds_count"), 3);

  test::Process& second = farm.worker();  // --exit-when-idle
  ASSERT_EQ(second.wait(120), 0) << second.log();
  nlohmann::json done = farm.status(job);
  ASSERT_EQ(done["state"], "completed") << done.dump();
  Scrape end = scrape(port);
  EXPECT_EQ(end.at("rayfarm_tasks_completed_total"), 8);
  EXPECT_EQ(end.at("rayfarm_tasks_leased_total"), 8);
  EXPECT_EQ(end.at("rayfarm_tasks_failed_total"), 0);
  EXPECT_EQ(end.at("rayfarm_leases_expired_total"), 0);
  EXPECT_EQ(end.at("rayfarm_samples_merged_total"),
            done["frames"][0]["spp"].get<double>() * 32 * 32);
  EXPECT_NEAR(end.at("rayfarm_core_seconds_total"), done["core_seconds"].get<double>(),
              1e-6 * done["core_seconds"].get<double>() + 1e-3);
  EXPECT_GT(end.at("rayfarm_merged_bytes_total"), mid.at("rayfarm_merged_bytes_total"));
  EXPECT_EQ(end.at("rayfarm_tasks_queued"), 0);
  EXPECT_EQ(end.at("rayfarm_jobs{state=\"completed\"}"), 1);
  EXPECT_EQ(end.at("rayfarm_workers_registered"), 2);
  // Every lease call is in the histogram: the buckets are cumulative and end at the count.
  double count = end.at("rayfarm_lease_duration_seconds_count");
  // The first worker's 3 single leases, the second's first, then (the job's tasks timed) one
  // batch or single leases for the last 4, and an empty answer.
  EXPECT_GE(count, 6);
  EXPECT_GE(end.at("rayfarm_result_flushes_total"), 1);
  EXPECT_GE(end.at("rayfarm_store_commits_total"), 1);
  EXPECT_EQ(end.at("rayfarm_lease_duration_seconds_bucket{le=\"+Inf\"}"), count) << end.text;
  EXPECT_FALSE(end.has_prefix("rayfarm_job_tasks_queued{")) << "the job's series end with it";
  EXPECT_FALSE(end.has_prefix("rayfarm_frame_relmse{")) << end.text;

  // The dashboard and the autoscalers ask only for what is served.
  std::set<std::string> asked;
  std::string dashboard = test::source_dir() + "/deploy/grafana/rayfarm.json";
  ASSERT_TRUE(std::filesystem::exists(dashboard));
  asked = metric_names_in(read_text(dashboard), end);
  EXPECT_GE(asked.size(), 8u) << "the dashboard shows the main figures";
  for (const auto& e :
       std::filesystem::recursive_directory_iterator(test::source_dir() + "/deploy/k8s"))
    if (e.path().extension() == ".yaml")
      for (const std::string& n : metric_names_in(read_text(e.path()), end)) asked.insert(n);
  for (const std::string& n : asked)
    EXPECT_TRUE(end.types.count(n)) << n << " is queried but not served";
}

}  // namespace
}  // namespace rf
