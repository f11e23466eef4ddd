#include "coordinator/job_store.h"

namespace rf {

bool lease_write(const StoreWrite& w) {
  return std::holds_alternative<store::InsertLease>(w) ||
         std::holds_alternative<store::DeleteLeases>(w);
}

std::vector<StoredLease> JobStore::leases(const std::string& job_id) const {
  std::vector<StoredLease> out;
  for_each_lease(job_id, [&](const StoredLease& l) { out.push_back(l); });
  return out;
}

}  // namespace rf
