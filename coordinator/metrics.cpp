#include "coordinator/metrics.h"

#include <prometheus/collectable.h>
#include <prometheus/exposer.h>
#include <prometheus/metric_family.h>

#include <cctype>
#include <cmath>
#include <iterator>
#include <limits>
#include <stdexcept>

namespace rf {

namespace {

using prometheus::ClientMetric;
using prometheus::MetricFamily;
using prometheus::MetricType;

MetricFamily family(const char* name, const char* help, MetricType type) {
  MetricFamily f;
  f.name = name;
  f.help = help;
  f.type = type;
  return f;
}

ClientMetric value(MetricType type, double v, std::vector<ClientMetric::Label> labels = {}) {
  ClientMetric m;
  m.label = std::move(labels);
  (type == MetricType::Counter ? m.counter.value : m.gauge.value) = v;
  return m;
}

MetricFamily single(const char* name, const char* help, MetricType type, double v) {
  MetricFamily f = family(name, help, type);
  f.metric.push_back(value(type, v));
  return f;
}

// "queued", "running", ...: job_state_name() without its JOB_ prefix, in lower case.
std::string state_label(JobState s) {
  std::string name = std::string(job_state_name(s)).substr(4);
  for (char& c : name) c = char(std::tolower(static_cast<unsigned char>(c)));
  return name;
}

}  // namespace

std::vector<MetricFamily> metric_families(const CoordinatorMetrics& m) {
  const auto C = MetricType::Counter, G = MetricType::Gauge;
  const CoordinatorMetrics::Counters& c = m.counters;
  std::vector<MetricFamily> out;
  out.push_back(single("rayfarm_tasks_queued",
                       "Tasks waiting for a worker, over all jobs but paused ones", G,
                       double(m.tasks_queued)));
  out.push_back(
      single("rayfarm_tasks_paused", "Tasks waiting in paused jobs", G, double(m.tasks_paused)));
  out.push_back(single("rayfarm_tasks_in_flight", "Tasks leased to a worker now, over all jobs", G,
                       double(m.tasks_leased)));
  out.push_back(
      single("rayfarm_tasks_leased_total", "Tasks handed to workers", C, double(c.tasks_leased)));
  out.push_back(
      single("rayfarm_tasks_completed_total", "Task results merged", C, double(c.tasks_completed)));
  out.push_back(single("rayfarm_tasks_failed_total", "Task failures reported by workers", C,
                       double(c.tasks_failed)));
  out.push_back(single("rayfarm_tasks_handed_back_total",
                       "Tasks returned unfinished by workers shutting down", C,
                       double(c.tasks_handed_back)));
  out.push_back(single("rayfarm_leases_expired_total",
                       "Leases not renewed in time (a crashed, stalled or cut-off worker)", C,
                       double(c.leases_expired)));
  out.push_back(single("rayfarm_results_refused_total",
                       "Task results refused by the checks (counted against their worker)", C,
                       double(c.results_refused)));
  out.push_back(single("rayfarm_calls_refused_total",
                       "Calls refused for their token or role (UNAUTHENTICATED, PERMISSION_DENIED)",
                       C, double(c.calls_refused)));
  out.push_back(single("rayfarm_refusal_log_lines_suppressed_total",
                       "Refused calls left out of the log by its rate limit", C,
                       double(c.refusal_lines_suppressed)));
  out.push_back(single("rayfarm_samples_merged_total", "Camera samples in merged task results", C,
                       double(c.samples_merged)));
  out.push_back(single("rayfarm_merged_bytes_total", "Encoded sample-buffer bytes merged", C,
                       double(c.bytes_merged)));
  out.push_back(single("rayfarm_core_seconds_total",
                       "Worker CPU seconds spent on the merged results", C, c.core_seconds));
  out.push_back(single("rayfarm_result_flushes_total",
                       "Flushes (syncfs) that made task results durable, each covering every "
                       "result written before it",
                       C, double(c.result_flushes)));
  out.push_back(single("rayfarm_store_commits_total",
                       "Job store transactions, each one flush for the ledger rows queued", C,
                       double(c.store_commits)));
  out.push_back(single("rayfarm_workers_registered", "Workers registered and not refused", G,
                       double(m.workers_registered)));
  out.push_back(single("rayfarm_workers_connected", "Workers heard from within one lease time", G,
                       double(m.workers_connected)));
  out.push_back(single("rayfarm_jobs_expired_total",
                       "Finished jobs removed by retention (--keep-finished)", C,
                       double(c.jobs_expired)));
  out.push_back(single("rayfarm_blobs_collected_total",
                       "Scene blobs no job referenced, removed after --blob-grace", C,
                       double(c.blobs_collected)));
  out.push_back(single("rayfarm_blob_collected_bytes_total", "Bytes of the blobs collected", C,
                       double(c.blob_bytes_collected)));
  out.push_back(single("rayfarm_blob_store_bytes",
                       "Bytes of scene blobs stored, as of the last retention pass", G,
                       double(m.blob_store_bytes)));
  out.push_back(single("rayfarm_storage_ok",
                       "1 while the coordinator can store results, 0 while it cannot (disk full)",
                       G, m.storage_ok ? 1 : 0));

  MetricFamily lease = family("rayfarm_lease_duration_seconds",
                              "Time the coordinator takes to answer a lease request (lock wait, "
                              "scheduling, the lease's database row)",
                              MetricType::Histogram);
  ClientMetric h;
  h.histogram.sample_count = c.lease_calls;
  h.histogram.sample_sum = c.lease_seconds;
  uint64_t cumulative = 0;
  for (size_t i = 0; i < std::size(CoordinatorMetrics::kLeaseBuckets); ++i) {
    cumulative += i < c.lease_buckets.size() ? c.lease_buckets[i] : 0;
    h.histogram.bucket.push_back({cumulative, CoordinatorMetrics::kLeaseBuckets[i]});
  }
  h.histogram.bucket.push_back({c.lease_calls, std::numeric_limits<double>::infinity()});
  lease.metric.push_back(h);
  out.push_back(std::move(lease));

  MetricFamily jobs = family("rayfarm_jobs", "Jobs known to the coordinator, by state", G);
  for (JobState s : {JobState::Queued, JobState::Running, JobState::Completed, JobState::Failed,
                     JobState::Cancelled})
    jobs.metric.push_back(
        value(G, double(m.jobs_by_state[size_t(s)]), {{"state", state_label(s)}}));
  out.push_back(std::move(jobs));

  // Per pool (the `pool=NAME` a job requires; "any" for none): each pool's autoscaler's input.
  MetricFamily pool_queued =
      family("rayfarm_pool_tasks_queued",
             "Tasks waiting for a worker, by the pool their job requires (\"any\": none), paused "
             "jobs left out",
             G);
  MetricFamily pool_leased =
      family("rayfarm_pool_tasks_in_flight", "Tasks leased now, by the pool their job requires", G);
  for (const auto& [name, p] : m.pools) {
    pool_queued.metric.push_back(value(G, double(p.tasks_queued), {{"pool", name}}));
    pool_leased.metric.push_back(value(G, double(p.tasks_leased), {{"pool", name}}));
  }
  out.push_back(std::move(pool_queued));
  out.push_back(std::move(pool_leased));

  MetricFamily queued = family("rayfarm_job_tasks_queued",
                               "Tasks of a queued or running job waiting for a worker", G);
  MetricFamily leased =
      family("rayfarm_job_tasks_in_flight", "Tasks of a running job leased to a worker now", G);
  MetricFamily rel_mse = family("rayfarm_frame_relmse",
                                "Estimated relative MSE of a rendering frame's merged image", G);
  MetricFamily eta =
      family("rayfarm_frame_eta_seconds", "Estimated seconds until a rendering frame is done", G);
  MetricFamily progress =
      family("rayfarm_frame_progress_ratio", "Passes merged over passes of a rendering frame", G);
  for (const CoordinatorMetrics::Job& j : m.jobs) {
    queued.metric.push_back(value(G, double(j.tasks_queued), {{"job", j.job_id}}));
    leased.metric.push_back(value(G, double(j.tasks_leased), {{"job", j.job_id}}));
    for (const FrameStatus& f : j.frames) {
      std::vector<ClientMetric::Label> labels = {{"frame", std::to_string(f.frame)},
                                                 {"job", j.job_id}};
      const FrameProgress& p = f.progress;
      if (p.passes_merged >= 2 && std::isfinite(p.rel_mse))  // known from two passes on
        rel_mse.metric.push_back(value(G, p.rel_mse, labels));
      if (std::isfinite(p.eta_seconds) && p.eta_seconds >= 0)
        eta.metric.push_back(value(G, p.eta_seconds, labels));
      if (p.passes_total > 0)
        progress.metric.push_back(value(G, double(p.passes_merged) / p.passes_total, labels));
    }
  }
  for (MetricFamily* f : {&queued, &leased, &rel_mse, &eta, &progress})
    out.push_back(std::move(*f));
  return out;
}

class MetricsServer::Collector : public prometheus::Collectable {
 public:
  explicit Collector(const Coordinator& core) : core_(core) {}
  std::vector<MetricFamily> Collect() const override { return metric_families(core_.metrics()); }

 private:
  const Coordinator& core_;
};

MetricsServer::MetricsServer(const std::string& listen, const Coordinator& core)
    : collector_(std::make_shared<Collector>(core)) {
  try {
    // civetweb serves a connection per thread: 16 threads, and a connection that sends no
    // request within 500 ms is closed, so idle connections cannot hold the scrape off for long
    // (docs/security.md, "Metrics").
    exposer_ = std::make_unique<prometheus::Exposer>(
        std::vector<std::string>{"listening_ports", listen, "num_threads", "16",
                                 "request_timeout_ms", "500", "enable_keep_alive", "no"});
  } catch (const std::exception& e) {
    throw std::runtime_error("coordinator: cannot listen on --metrics-listen " + listen + " (" +
                             std::string(e.what()) + ")");
  }
  exposer_->RegisterCollectable(collector_, "/metrics");
}

MetricsServer::~MetricsServer() {
  if (exposer_) exposer_->RemoveCollectable(collector_, "/metrics");
}

int MetricsServer::port() const {
  std::vector<int> ports = exposer_->GetListeningPorts();
  return ports.empty() ? 0 : ports.front();
}

}  // namespace rf
