// The one upload client: a task's result sent to the coordinator (CompleteTask), used by the
// worker and by the soak benchmark's simulated workers, so the soak exercises the worker's code.
#pragma once

#include <grpcpp/grpcpp.h>

#include <string>
#include <vector>

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
                           const rayfarm::v1::Task& task, std::string_view buffer,
                           double core_seconds, double seconds, bool wait_for_ready,
                           const std::vector<std::string>& log = {});

// A batched upload (RegisterResponse.max_results_per_upload > 1): several results in one
// CompleteTask, made durable by one flush. `status` is the call's; when it is OK, each result's
// answer is in `results` (its own status: a refusal of that result alone). One item is sent as
// upload_result sends it.
struct UploadItem {
  const rayfarm::v1::Task* task = nullptr;
  std::string_view buffer;
  double core_seconds = 0;
  std::vector<std::string> log;
};
struct BatchAnswer {
  grpc::Status status;
  std::vector<UploadAnswer> results;  // one per item, in order, when status is OK
};
BatchAnswer upload_results(rayfarm::v1::WorkerService::Stub& stub, const std::string& worker_id,
                           const std::vector<UploadItem>& items, double seconds,
                           bool wait_for_ready);

}  // namespace rf
