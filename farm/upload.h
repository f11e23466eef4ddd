// The one upload client: a task's result sent to the coordinator (CompleteTask), used by the
// worker and by the soak benchmark's simulated workers, so the soak exercises the worker's code.
#pragma once

#include <grpcpp/grpcpp.h>

#include <string>

#include "proto/rayfarm.grpc.pb.h"

namespace rf {

struct UploadAnswer {
  grpc::Status status;
  bool accepted = false;  // merged; false: not needed (another result came first, or it settled)
};

// One CompleteTask call: the header naming the worker, the task and its lease (with the CPU
// seconds the result took), then the encoded sample buffer in checksummed chunks. The call's
// deadline is `seconds`; with wait_for_ready it waits for a coordinator that is away.
UploadAnswer upload_result(rayfarm::v1::WorkerService::Stub& stub, const std::string& worker_id,
                           const rayfarm::v1::Task& task, const std::string& buffer,
                           double core_seconds, double seconds, bool wait_for_ready,
                           const std::vector<std::string>& log = {});

}  // namespace rf
