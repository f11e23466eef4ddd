#include "coordinator/job_store.h"

namespace rf {

bool lease_write(const StoreWrite& w) {
  return std::holds_alternative<store::InsertLease>(w) ||
         std::holds_alternative<store::DeleteLeases>(w) ||
         std::holds_alternative<store::Attempt>(w);
}

const char* attempt_outcome_name(AttemptOutcome o) {
  switch (o) {
    case AttemptOutcome::Done:
      return "done";
    case AttemptOutcome::Failed:
      return "failed";
    case AttemptOutcome::Refused:
      return "refused";
    case AttemptOutcome::HandedBack:
      return "handed back";
    case AttemptOutcome::Expired:
      return "expired";
    case AttemptOutcome::NotNeeded:
      return "not needed";
    case AttemptOutcome::Held:
      return "held";
    case AttemptOutcome::Running:
      return "running";
  }
  return "unknown";
}

std::vector<StoredLease> JobStore::leases(const std::string& job_id) const {
  std::vector<StoredLease> out;
  for_each_lease(job_id, [&](const StoredLease& l) { out.push_back(l); });
  return out;
}

}  // namespace rf
