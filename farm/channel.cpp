#include "farm/channel.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace rf {

std::shared_ptr<grpc::Channel> coordinator_channel(const std::string& address,
                                                   int keepalive_seconds) {
  grpc::ChannelArguments args;
  if (keepalive_seconds > 0) {
    args.SetInt(GRPC_ARG_KEEPALIVE_TIME_MS, keepalive_seconds * 1000);
    args.SetInt(GRPC_ARG_KEEPALIVE_TIMEOUT_MS, std::max(1, keepalive_seconds / 2) * 1000);
    args.SetInt(GRPC_ARG_KEEPALIVE_PERMIT_WITHOUT_CALLS, 1);
  }
  args.SetInt(GRPC_ARG_INITIAL_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MIN_RECONNECT_BACKOFF_MS, 100);
  args.SetInt(GRPC_ARG_MAX_RECONNECT_BACKOFF_MS, 2000);
  return grpc::CreateCustomChannel(address, grpc::InsecureChannelCredentials(), args);
}

void set_deadline(grpc::ClientContext& ctx, double seconds, bool wait_for_ready) {
  ctx.set_deadline(std::chrono::system_clock::now() +
                   std::chrono::milliseconds(int64_t(seconds * 1000)));
  if (wait_for_ready) ctx.set_wait_for_ready(true);
}

bool transient(const grpc::Status& s) {
  return s.error_code() == grpc::StatusCode::UNAVAILABLE ||
         s.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED;
}

double backoff_seconds(int attempt, double first, double cap, std::mt19937& rng) {
  double base = first * std::ldexp(1.0, std::clamp(attempt, 0, 30));
  return std::min(cap, base) * std::uniform_real_distribution<double>(0.5, 1.0)(rng);
}

}  // namespace rf
