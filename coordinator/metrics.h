// Prometheus metrics of the coordinator (`rayfarm coordinator --metrics-listen HOST:PORT`,
// served at /metrics over plain HTTP by prometheus-cpp's exposer; docs/deploy.md lists them).
// Each scrape takes the core's snapshot (Coordinator::metrics()) and writes it out, so a job's
// series exist exactly while the job is queued or running and vanish when it ends; label values
// are the coordinator's own job ids and frame numbers, never a client's strings.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "coordinator/core.h"

namespace prometheus {
struct MetricFamily;
class Exposer;
}  // namespace prometheus

namespace rf {

// The families a snapshot becomes (every family is present, with no samples when there is
// nothing to report, so a dashboard's queries always name something served).
std::vector<prometheus::MetricFamily> metric_families(const CoordinatorMetrics& m);

class MetricsServer {
 public:
  // Starts serving `core`'s metrics on `listen` (HOST:PORT; port 0 picks one); throws, naming
  // the address, if it cannot listen. `core` must outlive this.
  MetricsServer(const std::string& listen, const Coordinator& core);
  ~MetricsServer();
  MetricsServer(const MetricsServer&) = delete;
  MetricsServer& operator=(const MetricsServer&) = delete;
  int port() const;

 private:
  class Collector;
  std::shared_ptr<Collector> collector_;
  std::unique_ptr<prometheus::Exposer> exposer_;
};

}  // namespace rf
