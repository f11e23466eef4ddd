// The coordinator's refusals in plain C++ (service.cpp maps each code to one gRPC status).
#pragma once

#include <stdexcept>
#include <string>

namespace rf {

enum class ErrorCode {
  InvalidArgument,     // malformed request, frame range, bundle, scene or sample buffer
  NotFound,            // unknown job, frame, task, lease or blob
  FailedPrecondition,  // a lease that has ended; a frame with no pass yet; a job that has ended
  PermissionDenied,    // another tenant's job; another worker's lease or registration; a role
  Unauthenticated,     // (the service's) a missing, unknown or expired token
  ResourceExhausted,   // over a configured limit
  DataLoss,            // a payload's checksum does not match
  Unavailable,         // shutting down
  Internal,            // the coordinator could not do what it should (e.g. a disk write failed)
};

struct CoordinatorError : std::runtime_error {
  CoordinatorError(ErrorCode code, const std::string& message)
      : std::runtime_error(message), code(code) {}
  ErrorCode code;
};

}  // namespace rf
