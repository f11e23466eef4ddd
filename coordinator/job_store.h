// The coordinator's durable job state (DESIGN.md "Coordinator": state survives a restart): an
// embedded SQLite database in WAL mode with one writer connection, on local disk. It records each
// job's spec (the serialized JobSpec), its state and error, and every task completion and
// failure. Which task results an image contains is recorded by the frame checkpoints
// (checkpoint.h), not here: on restart a task the database calls done but the checkpoint lacks
// is rendered again.
#pragma once

#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

struct sqlite3;

namespace rf {

struct StoreError : std::runtime_error {
  using std::runtime_error::runtime_error;
};
// The database as a whole is damaged (not a database, fails SQLite's integrity check): the
// coordinator exits with kStoreDamagedExit and this message, which says how to recover.
struct StoreDamaged : StoreError {
  using StoreError::StoreError;
};
constexpr int kStoreDamagedExit = 4;

struct StoredJob {
  std::string id;
  uint64_t seq = 0;  // submission order
  std::string spec;  // serialized rayfarm.v1.JobSpec
  int state = 0;     // rayfarm.v1.JobState
  std::string error;
  int64_t submitted_unix = 0;
  double core_seconds = 0;
  std::string tenant;    // whose job it is ('' before tenants existed)
  std::string build_id;  // the build of its first merged result ('' until then)
};

// A lease as handed out, kept so that its holder's late result is accepted after a restart.
struct StoredLease {
  std::string lease_id, job_id;
  uint32_t frame = 0, pass = 0, tile = 0;
  std::string worker_id;
};

// One coordinator per state directory: an exclusive lock (flock) on STATE_DIR/lock, held for
// the object's life, with the holder's pid written in the file. A second holder is refused
// with a StoreError naming the first one's pid.
class StateDirLock {
 public:
  explicit StateDirLock(const std::string& state_dir);  // creates the directory if needed
  ~StateDirLock();
  StateDirLock(const StateDirLock&) = delete;
  StateDirLock& operator=(const StateDirLock&) = delete;

 private:
  int fd_ = -1;
};

class JobStore {
 public:
  explicit JobStore(const std::string& path);  // creates the schema if needed
  ~JobStore();
  JobStore(const JobStore&) = delete;
  JobStore& operator=(const JobStore&) = delete;

  uint64_t next_seq();  // one past the largest job sequence number stored
  void insert_job(const StoredJob& job);
  void set_state(const std::string& job_id, int state, const std::string& error);
  void add_core_seconds(const std::string& job_id, double seconds);
  void task_done(const std::string& job_id, uint32_t frame, uint32_t pass, uint32_t tile,
                 const std::string& worker_id);
  void task_failed(const std::string& job_id, uint32_t frame, uint32_t pass, uint32_t tile,
                   const std::string& worker_id, const std::string& message);
  std::vector<StoredJob> jobs() const;  // in submission order

  // Worker registrations (id -> the principal that registered it) and leases. Lease rows are
  // written with synchronous=NORMAL (no fsync): losing the last ones in a power cut only makes
  // those late results be rendered again.
  struct StoredWorker {
    std::string id, principal, build_id;
    std::string refused;  // why it is refused for good (outvoted), or empty
  };
  void insert_worker(const StoredWorker& worker);
  void refuse_worker(const std::string& worker_id, const std::string& why);
  void delete_worker(const std::string& worker_id);
  std::vector<StoredWorker> workers() const;
  void set_build(const std::string& job_id, const std::string& build_id);

  // Which tenants uploaded a blob: a client sees a blob as present only once its tenant did.
  void add_blob_tenant(const std::string& tenant, const std::string& sha256);
  bool blob_tenant(const std::string& tenant, const std::string& sha256) const;
  void insert_lease(const StoredLease& lease);
  // The job's lease rows in the order written, one at a time (a large job may have many).
  void for_each_lease(const std::string& job_id,
                      const std::function<void(const StoredLease&)>& f) const;
  std::vector<StoredLease> leases(const std::string& job_id) const;
  void delete_leases(const std::string& job_id);                  // the job ended
  void delete_leases(const std::string& job_id, uint32_t frame);  // the frame is done

  struct TaskFailure {
    uint32_t frame, pass, tile;
    std::string worker_id, message;
  };
  std::vector<TaskFailure> failures(const std::string& job_id) const;  // in the order recorded
  // A worker's result refused (it did not match its task): counted against the worker in the
  // job, never against the task.
  void result_refused(const std::string& job_id, uint32_t frame, uint32_t pass, uint32_t tile,
                      const std::string& worker_id, const std::string& why);
  std::vector<std::string> refused_workers(const std::string& job_id) const;  // one per refusal
  uint64_t tasks_done(const std::string& job_id) const;

 private:
  void exec(const std::string& sql);
  void open_schema();  // WAL, tables, columns added since
  void insert_event(const std::string& job_id, uint32_t frame, uint32_t pass, uint32_t tile,
                    const std::string& worker_id, int kind, const std::string& message);
  std::string damage_advice() const;
  sqlite3* db_ = nullptr;
  std::string path_;
};

}  // namespace rf
