// The coordinator's durable job state (DESIGN.md "Coordinator": state survives a restart) behind
// one interface with two implementations: SQLite on the state directory (WAL, one writer
// connection; the server's) and memory (the core's unit tests and the coordinator fuzzer). It
// records each job's spec (spec_codec.h), its state and error, whether it is paused and its
// priority when changed after submit, every task completion, failure and
// refused result, worker registrations, which tenants uploaded which blobs, and the leases of
// running jobs. Which task results an image contains is recorded by the frame checkpoints
// (checkpoint.h), not here: on restart a task the store calls done but the checkpoint lacks is
// rendered again.
//
// Writes come in batches applied in order, all or none (one SQLite transaction): the journal
// (journal.h) groups the writes of many calls into one. Every implementation is safe to call from
// any thread.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "engine/frame.h"
#include "farm/job.h"

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
  uint64_t seq = 0;             // submission order
  std::optional<JobSpec> spec;  // nothing when the stored spec does not decode
  int state = 0;                // rayfarm.v1.JobState
  std::string error;
  int64_t submitted_unix = 0;
  double core_seconds = 0;
  std::string tenant;    // whose job it is ('' before tenants existed)
  std::string build_id;  // the build of its first merged result ('' until then)
  bool paused = false;
  std::optional<int> priority;  // set after submit (`priority JOB N`); the spec's when absent
  std::vector<FrameNumber> held;  // unfinished frames a `retry --frames` left out, sorted
  std::string cpu_kind;  // the CPU kind (BufferHeader::isa) of its first merged result, or ''
  // Its scene versions and requeued frames (`requeue`), as the coordinator encodes them
  // (coordinator/versions.h); '' for a job never requeued.
  std::string versions;
  int64_t ended_unix = 0;  // when it last ended (Completed, Failed, Cancelled); 0 while not
};

// What is left of a job that retention expired (`--keep-finished`): its id answers "expired".
struct Tombstone {
  int64_t expired_unix = 0;
  std::string tenant;
};

// A lease as handed out, kept so that its holder's late result is accepted after a restart.
struct StoredLease {
  std::string lease_id, job_id;
  FrameNumber frame = 0;
  uint32_t pass = 0, tile = 0;
  std::string worker_id;
};

// A worker registration: the id the coordinator issued and the principal that registered it.
struct StoredWorker {
  std::string id, principal, build_id;
  std::string refused;  // why it is refused for good (outvoted), or empty
  std::string isa;      // its CPU kind as it registered ('' in rows of earlier builds)
  std::vector<std::string> tags;  // as registered (none in rows of earlier builds)
};

struct TaskFailure {
  FrameNumber frame;
  uint32_t pass, tile;
  std::string worker_id, message;
  bool counted = true;  // false once a retry of its job forgot it (failure_history only)
};

enum class TaskEventKind : int { Failed = 0, Done = 1, ResultRefused = 2 };

// How a task's attempt (one lease) ended, for `rayfarm logs`; stored as the number.
enum class AttemptOutcome : int {
  Done = 0,
  Failed = 1,
  Refused = 2,     // its result did not pass the checks
  HandedBack = 3,  // the worker shut down, or its result was of another build or CPU kind
  Expired = 4,     // not renewed in time
  NotNeeded = 5,   // another result came first, or its frame or job stopped
  Held = 6,        // kept until another worker's result agrees (verification)
  Running = 7,     // not ended (never stored: a live lease)
};
const char* attempt_outcome_name(AttemptOutcome outcome);  // "done", "handed back", ...

struct StoredAttempt {
  std::string job_id;
  FrameNumber frame = 0;
  uint32_t pass = 0, tile = 0;
  std::string lease_id, worker_id;
  double started_unix = 0, ended_unix = 0;
  AttemptOutcome outcome = AttemptOutcome::Done;
  std::string message;           // a failure's or refusal's reason
  std::vector<std::string> log;  // the worker's lines (farm/job.h bounds them)
};

// The writes, one struct each.
namespace store {
struct InsertJob {
  StoredJob job;
};
struct SetState {
  std::string job_id;
  int state = 0;
  std::string error;
  int64_t ended_unix = 0;  // when an ended state began (0 for Queued and Running)
};
struct AddCoreSeconds {
  std::string job_id;
  double seconds = 0;
};
// The job's pin: results of this build and CPU kind only (its first merged result's).
struct SetBuild {
  std::string job_id, build_id, cpu_kind;
};
struct SetPaused {
  std::string job_id;
  bool paused = false;
};
struct SetPriority {
  std::string job_id;
  int priority = 0;
};
// The job runs again (`retry`): `held` are its unfinished frames left out (not queued until a
// later retry names them); with forget_failures, its failures and refused results so far stop
// counting (they stay in the history).
struct Retry {
  std::string job_id;
  std::vector<FrameNumber> held;
  bool forget_failures = false;
};
// The job's frames were requeued (`requeue`): its scene versions and which version and run each
// requeued frame has now (coordinator/versions.h's text).
struct SetVersions {
  std::string job_id, versions;
};
// The job is deleted: its events and leases go, and its row is reduced to its id and sequence
// number (so that no later job gets its id); jobs() no longer lists it.
struct DeleteJob {
  std::string job_id;
  int64_t expired_unix = 0;  // retention expired it then (0: a client's delete)
};
// A blob retention collected: no tenant has it any more.
struct ForgetBlob {
  std::string sha256;
};
struct TaskEvent {
  std::string job_id;
  FrameNumber frame = 0;
  uint32_t pass = 0, tile = 0;
  std::string worker_id;
  TaskEventKind kind = TaskEventKind::Done;
  std::string message;
};
struct Attempt {  // an attempt ended (lost in a power cut: only its log line goes)
  StoredAttempt attempt;
};
struct InsertWorker {
  StoredWorker worker;
};
struct RefuseWorker {
  std::string worker_id, why;
};
struct DeleteWorker {
  std::string worker_id;
};
struct AddBlobTenant {
  std::string tenant, sha256;
};
struct InsertLease {
  StoredLease lease;
};
struct DeleteLeases {
  std::string job_id;
  std::optional<FrameNumber> frame;  // all of the job's when absent
};
}  // namespace store

using StoreWrite =
    std::variant<store::InsertJob, store::SetState, store::AddCoreSeconds, store::SetBuild,
                 store::SetPaused, store::SetPriority, store::Retry, store::SetVersions,
                 store::DeleteJob, store::TaskEvent, store::Attempt, store::InsertWorker,
                 store::RefuseWorker, store::DeleteWorker, store::AddBlobTenant, store::ForgetBlob,
                 store::InsertLease, store::DeleteLeases>;

// Whether losing the write in a power cut costs nothing but work or a log record: a lease's row
// (its holder's late result is then rendered again), an attempt's record. Batches of such writes
// only are not flushed to disk.
bool lease_write(const StoreWrite& w);

class JobStore {
 public:
  virtual ~JobStore() = default;

  // Applies the writes in order, all or none, durable on return (batches of lease writes only:
  // written, not flushed). Throws StoreError naming the store.
  virtual void write(const std::vector<StoreWrite>& batch) = 0;
  void write(StoreWrite w) { write(std::vector<StoreWrite>{std::move(w)}); }

  // One past the largest job sequence number, deleted jobs' included.
  virtual uint64_t next_seq() const = 0;
  virtual std::vector<StoredJob> jobs() const = 0;  // in submission order, deleted ones left out
  virtual std::vector<StoredWorker> workers() const = 0;
  // Which tenants uploaded a blob: a client sees a blob as present only once its tenant did.
  virtual bool blob_tenant(const std::string& tenant, const std::string& sha256) const = 0;
  // A job retention expired: when, and whose it was; nothing for any other id.
  virtual std::optional<Tombstone> tombstone(const std::string& job_id) const = 0;
  // The job's lease rows in the order written, one at a time (a large job may have many).
  virtual void for_each_lease(const std::string& job_id,
                              const std::function<void(const StoredLease&)>& f) const = 0;
  // The failures and refused results that count (none from before a retry that forgot them).
  virtual std::vector<TaskFailure> failures(const std::string& job_id) const = 0;  // in order
  virtual std::vector<std::string> refused_workers(const std::string& job_id) const = 0;
  // Every failure of the job, those a retry forgot included (counted = false), in order.
  virtual std::vector<TaskFailure> failure_history(const std::string& job_id) const = 0;
  virtual uint64_t tasks_done(const std::string& job_id) const = 0;
  // The job's ended attempts, of one frame or one task when given: the most recent `limit`, in
  // the order they were stored; `more` says earlier ones were left out.
  virtual std::vector<StoredAttempt> attempts(const std::string& job_id,
                                              std::optional<FrameNumber> frame,
                                              const std::optional<TaskRef>& task, size_t limit,
                                              bool* more) const = 0;

  std::vector<StoredLease> leases(const std::string& job_id) const;
};

// SQLite at `path` (creates the schema, or upgrades one of an earlier build). Throws StoreDamaged
// for a damaged database, StoreError (saying why) for a full or unwritable disk.
std::unique_ptr<JobStore> open_sqlite_store(const std::string& path);
std::unique_ptr<JobStore> memory_store();

}  // namespace rf
