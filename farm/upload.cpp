#include "farm/upload.h"

#include "farm/channel.h"
#include "farm/chunking.h"

namespace rf {

UploadAnswer upload_result(rayfarm::v1::WorkerService::Stub& stub, const std::string& worker_id,
                           const rayfarm::v1::Task& task, std::string_view buffer,
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

BatchAnswer upload_results(rayfarm::v1::WorkerService::Stub& stub, const std::string& worker_id,
                           const std::vector<UploadItem>& items, double seconds,
                           bool wait_for_ready) {
  BatchAnswer out;
  if (items.size() == 1) {
    const UploadItem& i = items[0];
    UploadAnswer a = upload_result(stub, worker_id, *i.task, i.buffer, i.core_seconds, seconds,
                                   wait_for_ready, i.log);
    if (a.status.ok()) out.results.push_back(a);
    out.status = a.status;
    return out;
  }
  grpc::ClientContext ctx;
  set_deadline(ctx, seconds, wait_for_ready);
  rayfarm::v1::CompleteResponse resp;
  auto w = stub.CompleteTask(&ctx, &resp);
  bool ok = true;
  for (size_t n = 0; n < items.size() && ok; ++n) {
    const UploadItem& i = items[n];
    rayfarm::v1::CompleteHeader h;
    h.set_worker_id(worker_id);
    h.set_lease_id(i.task->lease_id());
    h.set_task_id(i.task->task_id());
    h.set_core_seconds(i.core_seconds);
    if (n == 0) h.set_results(uint32_t(items.size()));
    for (const std::string& l : i.log) h.add_log(l);
    ok = write_result(*w, h, i.buffer, n + 1 == items.size());
  }
  out.status = w->Finish();
  if (!out.status.ok()) return out;
  if (size_t(resp.results_size()) != items.size()) {
    out.status = grpc::Status(grpc::StatusCode::INTERNAL,
                              "the coordinator answered " + std::to_string(resp.results_size()) +
                                  " of " + std::to_string(items.size()) + " results");
    return out;
  }
  for (const rayfarm::v1::ResultOutcome& r : resp.results())
    out.results.push_back({grpc::Status(grpc::StatusCode(r.code()), r.message()), r.accepted()});
  return out;
}

}  // namespace rf
