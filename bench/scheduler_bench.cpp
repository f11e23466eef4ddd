// The coordinator's scheduler alone (coordinator/scheduler.h): the cost of one lease and its
// completion while a job of N tasks drains, one worker, no I/O. The coordinator does this under
// its mutex, so it bounds how many leases per second one coordinator can hand out.
//
//   build/bin/scheduler_bench
#include <chrono>
#include <cstdio>
#include <vector>

#include "coordinator/scheduler.h"

int main() {
  for (uint32_t frames : {10u, 100u}) {
    const uint32_t tiles = 100, passes = 10;
    rf::Scheduler s(rf::SchedulerOptions{30, 3, 4, "L"});
    std::vector<rf::FrameNumber> numbers;
    for (uint32_t i = 0; i < frames; ++i) numbers.push_back(rf::FrameNumber(i));
    s.add_job("j1", numbers, tiles, passes, 0);
    auto t0 = std::chrono::steady_clock::now();
    size_t n = 0;
    double now = 0;
    while (std::optional<rf::Lease> l = s.lease("w", now)) {
      s.complete(l->lease_id, now);
      ++n;
      now += 1e-3;
    }
    double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    std::printf("%u frames x %u passes x %u tiles = %zu tasks: %.1f us per lease + complete\n",
                frames, passes, tiles, n, 1e6 * seconds / double(n));
  }
}
