#include "farm/upload.h"

#include "farm/channel.h"
#include "farm/chunking.h"

namespace rf {

UploadAnswer upload_result(rayfarm::v1::WorkerService::Stub& stub, const std::string& worker_id,
                           const rayfarm::v1::Task& task, const std::string& buffer,
                           double core_seconds, double seconds, bool wait_for_ready,
                           const std::vector<std::string>& log) {
  grpc::ClientContext ctx;
  set_deadline(ctx, seconds, wait_for_ready);
  rayfarm::v1::CompleteResponse resp;
  auto w = stub.CompleteTask(&ctx, &resp);
  rayfarm::v1::CompleteHeader h;
  h.set_worker_id(worker_id);
  h.set_lease_id(task.lease_id());
  h.set_task_id(task.task_id());
  h.set_core_seconds(core_seconds);
  for (const std::string& l : log) h.add_log(l);
  write_result(*w, h, buffer);
  UploadAnswer out;
  out.status = w->Finish();
  out.accepted = out.status.ok() && resp.accepted();
  return out;
}

}  // namespace rf
