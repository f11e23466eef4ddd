// The coordinator's job logic (DESIGN.md "Coordinator") in plain C++ types, knowing no gRPC:
// jobs and their frames, submission checks, leasing, completion, failure counting, restart and
// recovery, and the progress report. service.cpp puts it behind the gRPC services; the tests
// drive it directly (tests/coordinator_core_test.cpp).
//
// State: jobs and task events in SQLite (job_store.h), per-frame results in atomic checkpoint
// files (checkpoint.h), scene bundles in a content-addressed blob store (farm/blob_store.h); the
// task queue and leases in memory (scheduler.h), rebuilt from those on start. The frame merge is
// the engine's FrameAccumulator: passes merged in order, the stop taken on the completed prefix.
//
// Every method may be called from any thread. A refused request throws CoordinatorError with
// its code; anything else thrown is an internal error.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "coordinator/errors.h"
#include "coordinator/group_sync.h"
#include "coordinator/job_store.h"
#include "coordinator/scene_check.h"
#include "coordinator/scheduler.h"
#include "coordinator/state_dir.h"
#include "coordinator/versions.h"
#include "engine/frame.h"
#include "engine/frame_accumulator.h"
#include "engine/progress.h"
#include "engine/sample_buffer.h"
#include "farm/blob_store.h"
#include "farm/job.h"

namespace rf {

// The numbers are rayfarm.v1.JobState's and are stored in jobs.sqlite: state directories
// written by earlier versions read the same.
enum class JobState : int { Queued = 1, Running = 2, Completed = 3, Failed = 4, Cancelled = 5 };
bool terminal(JobState state);
const char* job_state_name(JobState state);  // "JOB_QUEUED", ..., as logs and errors spell it

// Who makes a call, as the service authenticated it (farm/auth.h); the core sees no tokens.
// `principal` binds a worker's registration to the identity that made it; a caller with
// all_tenants (admin, or the open loopback mode) sees every tenant's jobs.
struct Caller {
  std::string principal = "local";
  std::string tenant;
  bool all_tenants = true;
};

struct FrameStatus {
  FrameNumber frame = 0;
  FrameProgress progress;  // engine/progress.h: passes, spp, relMSE, ETA
  uint32_t scene_version = 0;  // the job's scene version it renders (0: the submitted one)
  uint32_t run = 0;            // how many times it was requeued
};

// One point of a frame's history (Coordinator::frame_history).
struct ProgressPoint {
  double unix_time = 0;
  uint32_t passes = 0;  // the merged prefix
  float rel_mse = 0;    // of that prefix; 0 before two passes
};
inline constexpr size_t kHistoryPoints = 128;

// One frame of a job, without the job's other frames (the monitor's preview and plot).
struct FrameHistory {
  FrameStatus status;
  double noise_target = 0;  // the job's (0: none)
  std::vector<ProgressPoint> points;
};

struct JobStatus {
  std::string job_id, name;
  std::string tenant;    // whose job it is
  std::string build_id;  // the build whose results it merges, once known
  std::string cpu_kind;  // the CPU kind (Embree ISA and configuration) of those results
  JobState state = JobState::Queued;
  std::string error;  // why it failed (the workers' messages) or was cancelled
  double core_seconds = 0;
  double noise_target = 0;  // the relMSE its frames stop at (0: none), from its settings or scene
  int64_t submitted_unix = 0;
  bool paused = false;
  int priority = 0;
  std::vector<FrameNumber> held;  // unfinished frames a `retry --frames` left out
  // Why no registered worker can take its tasks (its required tags, or its build and CPU kind
  // pin, met by none), or "" (also for an ended or paused job).
  std::string waiting_for;
  std::vector<FrameStatus> frames;
  // As submitted: the settings over the scene file's, the scene's path in the bundle, the
  // tile size (0: the default) and the worker tags required; when it last ended (0: never).
  SceneOverrides settings;
  std::string scene_path;
  uint32_t tile_size = 0;
  std::vector<std::string> required_tags;
  int64_t ended_unix = 0;
};

// The current image of a frame: its merged prefix as an encoded sample buffer
// (engine/buffer_file.h).
// A frame's merged prefix as fetched: its encoded bytes, or for a checkpoint larger than
// CoreOptions::frame_memory, its file opened (read by the caller in pieces, so a frame kept in
// tiles is never whole in memory; the open file is the prefix of the moment, whatever is saved
// after).
struct FrameImage {
  struct File {
    int fd = -1;
    uint64_t size = 0;
    ~File();
  };
  FrameStatus status;
  std::string buffer;
  std::shared_ptr<const File> file;
};

struct WorkerInfo {
  std::string hostname;
  uint32_t cores = 0;
  std::string build_id, isa;
  std::vector<std::string> tags;  // farm/tags.h: what jobs may require of it
};

// A registered worker as `workers` lists it.
struct WorkerStatus {
  std::string worker_id;
  std::string principal;  // who registered it (empty for a caller who may not see it)
  WorkerInfo info;        // as registered (after a restart: its build and CPU kind only)
  std::vector<std::string> tasks;  // its live leases' task ids ("another tenant's task" hidden)
  int failures = 0;                // failed tasks and refused results, in jobs not ended
  double seconds_since_contact = 0;
  std::string refused;  // why it is refused for good (outvoted), or empty
};

struct Registration {
  std::string worker_id;
  uint32_t lease_seconds = 0;      // renew well within this
  uint32_t keepalive_seconds = 0;  // a third of the lease
};

// What a worker needs to render a task, with the lease it holds it under.
struct TaskAssignment {
  TaskRef task;
  std::string lease_id;
  Rect rect;
  std::string scene_path;          // in the bundle
  std::vector<BundleEntry> files;  // the bundle
  SceneOverrides overrides;        // the job's settings
  std::string scene_digest;        // what the worker's parse must reproduce
};

struct LeaseResult {
  std::optional<TaskAssignment> task;  // nothing to do now when absent
  bool no_more_work = false;           // nothing queued or leased that this worker could get
  std::vector<TaskAssignment> more;    // further tasks of task's job (batched leases)
};

// A task's result as uploaded: the encoded sample buffer, its transfer checksum already checked.
struct TaskResult {
  std::string worker_id;  // must hold the lease
  std::string lease_id;
  TaskRef task;
  std::string buffer;
  std::vector<std::string> log;  // the attempt's log lines, bounded (farm/job.h bounded_log)
};

struct TaskFailureReport {
  std::string worker_id, lease_id, message;
  bool handed_back = false;  // the worker is shutting down: not a failure
  std::vector<std::string> log;  // the attempt's log lines (bounded here)
};

// A task's attempt as `rayfarm logs` shows it (outcome Running: a live lease).
using TaskAttempt = StoredAttempt;
struct TaskLog {
  std::vector<TaskAttempt> attempts;  // in the order they began... ended; live ones last
  bool more = false;                  // earlier attempts were left out
};

// What one job may ask for, checked at submit: a job over a limit is refused naming it
// (RESOURCE_EXHAUSTED for sizes, INVALID_ARGUMENT for strings). The coordinator keeps a tile
// rectangle per tile, a record per task in flight only (scheduler.h) and, per open frame
// (CoreOptions::window_frames of them), an accumulator of about 104 bytes per pixel (more with
// AOVs): the defaults bound one job to 10 million tasks (a bit each while their frame is open, a
// row each once done) and 1.7 GB per open frame. `rayfarm coordinator --limit NAME=VALUE` sets
// them.
struct JobLimits {
  uint64_t pixels_per_frame = 4096ull * 4096;
  uint64_t tiles_per_frame = 4096;
  uint64_t tasks_per_job = 10000000;
  uint64_t frames_per_job = 10000;
  uint64_t spp = uint64_t(1) << 20;
  uint64_t name_bytes = 256;   // the job's name
  uint64_t path_bytes = 1024;  // the scene path and each bundle path
  uint64_t bundle_files = 10000;
  // The scene check's budget (scene_check.h), by the names parse_memory_mb, parse_cpu_seconds,
  // parse_wall_seconds, parse_children, import_files, import_bytes, import_elements.
  SceneCheckLimits scene_check;
  // Sets the limit called `name` (the field's name); false if there is no such limit. Throws
  // std::invalid_argument for a value the limit cannot take (0 for a scene check's budget).
  bool set(const std::string& name, uint64_t value);
  static std::vector<std::string> names();
};

// What the coordinator shows an operator (coordinator/metrics.h serves it to Prometheus, taken
// afresh at each scrape): counters since this process started, and figures of now. Per-job
// figures are for jobs still queued or running, so a job's series end with it; they are keyed by
// the coordinator's own job ids, never by a client's strings.
struct CoordinatorMetrics {
  struct Counters {
    uint64_t tasks_leased = 0;
    uint64_t tasks_completed = 0;         // results merged
    uint64_t tasks_failed = 0;            // failures workers reported
    uint64_t tasks_handed_back = 0;       // returned unfinished by a worker shutting down
    uint64_t leases_expired = 0;          // not renewed in time (a crashed or cut-off worker)
    uint64_t results_refused = 0;         // results that failed the checks (counted on the worker)
    uint64_t samples_merged = 0;          // camera samples in those results
    uint64_t bytes_merged = 0;            // their encoded sample buffers
    double core_seconds = 0;              // the CPU time the workers spent on them
    uint64_t lease_calls = 0;             // lease() calls answered, with or without a task
    double lease_seconds = 0;             // their time in the core: lock wait, scheduling, the row
    std::vector<uint64_t> lease_buckets;  // per bound of kLeaseBuckets (not cumulative)
    uint64_t calls_refused = 0;           // calls the service's gate refused (tokens, roles)
    uint64_t refusal_lines_suppressed = 0;  // of those, not logged (the log's rate limit)
    uint64_t jobs_expired = 0;              // finished jobs retention removed (--keep-finished)
    uint64_t blobs_collected = 0;           // blobs no job referenced, removed
    uint64_t blob_bytes_collected = 0;
    uint64_t result_flushes = 0;  // syncfs calls that made results durable (group commit)
    uint64_t store_commits = 0;   // job store transactions (the journal's batches)
  };
  static constexpr double kLeaseBuckets[] = {0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025,
                                             0.05,   0.1,   0.25,   0.5,   1,    2.5};
  struct Pool {
    uint64_t tasks_queued = 0;  // waiting, in jobs not paused that require this pool
    uint64_t tasks_leased = 0;
  };
  // By the pool jobs require (their `pool=NAME` requirement; kAnyPool, "any", for none): what
  // the autoscaler of each pool's workers scales on.
  std::map<std::string, Pool> pools;
  struct Job {
    std::string job_id;
    uint64_t tasks_queued = 0;        // waiting for a worker, in every frame (not only the window)
    uint64_t tasks_leased = 0;        // leased now
    std::vector<FrameStatus> frames;  // frames with a merged pass and not done
  };
  Counters counters;
  uint64_t tasks_queued = 0;  // over all jobs but paused ones (the autoscalers scale on it)
  uint64_t tasks_paused = 0;  // waiting in paused jobs (no worker would get them)
  uint64_t tasks_leased = 0;
  size_t workers_registered = 0;
  size_t workers_connected = 0;  // heard from within one lease time
  size_t jobs_by_state[6] = {};  // indexed by JobState
  std::vector<Job> jobs;         // queued and running
  bool storage_ok = true;
  uint64_t blob_store_bytes = 0;  // the scene blobs stored, as of the last retention pass
};

struct CoreOptions {
  std::string state_dir;
  double lease_seconds = 30;
  uint32_t window_frames = 4;
  int max_failures = 3;  // workers a task may fail on, and tasks a worker may fail, per job
  FairShare share = FairShare::Tenants;  // between jobs of equal priority (scheduler.h)
  JobLimits limits;
  // The fraction of tasks rendered twice, on different workers, and merged only when the two
  // results are bit-identical (the determinism contract); a third worker settles a disagreement
  // and the outvoted worker is refused from then on. 0: none.
  double verify_fraction = 0;
  // Distinguishes this run's lease and worker ids from an earlier run's; empty: made up from
  // the time and process id.
  std::string instance;
  // Seconds on a monotonic clock (leases and ETAs use differences only); empty: steady_clock.
  std::function<double()> clock;
  // Parses and summarises a submitted job's scenes (scene_check.h). Required: the server runs
  // them in bounded child processes (child_scene_checker); tests may parse in-process.
  SceneChecker scene_checker;
  // Retention (Coordinator::collect): finished jobs are kept this long after they end (<= 0:
  // for ever), and a blob no job references this long after it was last stored or asked for.
  double keep_finished_seconds = 7 * 86400.0;
  double blob_grace_seconds = 3600;
  // Bytes a frame's accumulator holds in memory (its merged prefix and the results waiting for
  // their pass); a larger frame is kept in tiles in unlinked files in its checkpoint folder
  // (ProgressiveOptions::memory_budget; 0: every frame whole).
  uint64_t frame_memory = uint64_t(1) << 30;
  // The job store (job_store.h); empty: SQLite at STATE/jobs.sqlite. The core's tests and the
  // fuzzer give a memory store, kept across their restarts.
  std::shared_ptr<JobStore> store;
};

struct JobRecord;
struct FrameRecord;
class Journal;
class Ledger;

class Coordinator {
 public:
  // Opens (or creates) the state directory and restores every job in it.
  explicit Coordinator(CoreOptions options);
  ~Coordinator();
  Coordinator(const Coordinator&) = delete;
  Coordinator& operator=(const Coordinator&) = delete;

  // ---- Jobs. A caller without all_tenants sees only its tenant's jobs: another tenant's job is
  // refused with PermissionDenied, and list() leaves them out.
  // Blobs are scoped per tenant: for a caller without all_tenants, a blob its tenant never
  // uploaded is missing (and a bundle may not name it), so a digest query reveals nothing of
  // other tenants' uploads.
  std::vector<std::string> missing_blobs(const std::vector<std::string>& sha256,
                                         const Caller& caller = {}) const;
  // One uploaded bundle file, recorded for the caller's tenant; returns its digest.
  std::string put_blob(std::string_view bytes, const Caller& caller = {});
  // Checks the spec against the stored blobs (every frame's scene parsed with the job's
  // overrides, so a bad scene is refused now, not by a worker later) and queues the job under
  // the caller's tenant.
  std::string submit(const JobSpec& spec, const Caller& caller = {});  // the new job's id
  // In submission order; a page of at most `limit` jobs after job `after` (empty: the first).
  // `more` is set when jobs follow the page.
  std::vector<JobStatus> list(const Caller& caller = {}, size_t limit = SIZE_MAX,
                              const std::string& after = "", bool* more = nullptr) const;
  JobStatus status(const std::string& job_id, const Caller& caller = {}) const;
  // For watching a job: its status if it changed since version `seen` (0: never seen), waiting
  // up to timeout_seconds for a change; `seen` becomes the version returned.
  std::optional<JobStatus> next_status(const std::string& job_id, uint64_t& seen,
                                       double timeout_seconds, const Caller& caller = {}) const;
  void cancel(const std::string& job_id, const Caller& caller = {});
  // No new leases for a paused job; its leases in flight finish and their results merge.
  // Idempotent; FailedPrecondition for an ended job.
  void set_paused(const std::string& job_id, bool paused, const Caller& caller = {});
  // The job's priority among jobs from now on (higher first). FailedPrecondition once it ended.
  void set_priority(const std::string& job_id, int priority, const Caller& caller = {});
  // Failed or cancelled work runs again: the job's unfinished frames in `frames` (a frame range,
  // farm/frame_range.h; empty: all) are queued again with the failure counts afresh (the store
  // keeps the old failures as history) and the job is Running; its other unfinished frames are
  // held, and once the rest is done the job fails again naming them. On a Queued or Running job
  // it releases held frames; a retry of frames that run already changes nothing (idempotent).
  // FailedPrecondition for a completed job or one that cannot run (its bundle is gone) and when
  // every frame named is done; InvalidArgument for a bad range or a frame the job lacks.
  void retry(const std::string& job_id, const std::string& frames, const Caller& caller = {});
  // Removes an ended job: its folder (checkpoints, its record), its store rows and its state;
  // from then on it is NotFound, and its id is never given to another job. A queued or running
  // job is refused (FailedPrecondition) unless `force`, which deletes it as it is (its leases
  // end; their results are answered NotFound). Its scene blobs stay (other jobs may share them).
  // A delete interrupted by a crash is finished at the next start.
  void delete_job(const std::string& job_id, bool force, const Caller& caller = {});

  // ---- Retention (run every so often; `unix_now` is the time it takes as now). Finished jobs
  // (Completed, Failed, Cancelled) whose end is keep_finished_seconds past expire: removed as a
  // delete removes them, their id answering "expired at T" from then on (to their tenant). Ended
  // jobs release their frame accumulators. Blobs that no job references and that were not
  // stored or asked for (missing_blobs, put_blob) within blob_grace_seconds are removed.
  struct Collected {
    size_t jobs_expired = 0, blobs_removed = 0, accumulators_released = 0;
    uint64_t blob_bytes_removed = 0;
  };
  Collected collect(double unix_now);
  // `requeue`: the job's frames in `frames` (a frame range; required) render again from scratch,
  // with the seed and settings they had: their merged passes go, leases of theirs in flight end
  // (their results are answered not needed and counted against no one), and the job's failure
  // counts start afresh. With `scene` (its bundle uploaded as a submit's, checked as a submit's
  // is, with the job's resolution and passes), they render it as the job's next scene version;
  // without, each its own. A completed, failed or cancelled job runs again (Running), its other
  // unfinished frames held as a retry holds them. The build and CPU kind pin stays unless no
  // merged result is left and the spec named no build. A repeat of the job's latest
  // `request_id` changes nothing. InvalidArgument for a bad range, a frame the job lacks or a
  // scene that does not fit; FailedPrecondition for a job that cannot run (its bundle is gone).
  void requeue(const std::string& job_id, const std::string& frames,
               const std::optional<SceneVersion>& scene, const std::string& request_id = "",
               const Caller& caller = {});
  FrameImage fetch(const std::string& job_id, FrameNumber frame, const Caller& caller = {}) const;
  // A frame's status and its noise over time in this run of the coordinator: a point each time
  // its merged prefix grew (at most kHistoryPoints, thinned evenly as it grows), for the
  // monitor's plot. NotFound for a frame the job lacks.
  FrameHistory frame_history(const std::string& job_id, FrameNumber frame,
                             const Caller& caller = {}) const;

  // ---- Workers. A worker id is issued by register_worker and bound to the caller's principal
  // (stored, so it outlives a restart); every later call naming it must come from the same
  // principal, and a lease is renewed, failed or completed only by the worker holding it.
  // Its tags are checked (InvalidArgument naming a bad one; at most kMaxTags) and stored.
  Registration register_worker(const WorkerInfo& worker, const Caller& caller = {});
  // Up to max_tasks tasks (batched leases), each under its own lease: more than one only of a
  // job whose results so far took the worker under kLeaseBatchSeconds all together (its mean
  // CPU seconds a task over the worker's cores, at least kTasksBeforeBatching results merged),
  // so that a batch never holds back work that other workers could share.
  LeaseResult lease(const std::string& worker_id, const Caller& caller = {},
                    uint32_t max_tasks = 1);
  static constexpr uint32_t kMaxTasksPerLease = 64;
  static constexpr double kLeaseBatchSeconds = 0.25;
  static constexpr uint64_t kTasksBeforeBatching = 4;
  // The lease's length from now, in seconds.
  uint32_t renew(const std::string& worker_id, const std::string& lease_id,
                 const Caller& caller = {});
  // A scene blob, for a worker: a caller without all_tenants gets only blobs of the bundles of
  // jobs that one of its principal's workers holds a live lease in (NotFound otherwise, the same
  // answer as for a blob the store lacks).
  std::string blob(const std::string& sha256, const Caller& caller = {}) const;
  // Whether an upload may start: the job and task exist and the caller's worker holds the
  // task's lease (current, or expired with the task not yet done). Called on an upload's header,
  // before any of its bytes are buffered; complete() checks again.
  // False when the task is settled (done, stopped, its job ended): the upload is not needed,
  // and is answered accepted = false without reading it.
  bool check_upload(const std::string& worker_id, const std::string& lease_id, const TaskRef& task,
                    const Caller& caller = {}) const;
  // True when the result was merged; false when another result for the task came first, or the
  // task is no longer needed (stopped frame, ended job). The result is durable before this
  // returns true. A result that does not match its task (tile, pass, header, sample counts) or
  // holds a non-finite sum is refused with InvalidArgument and logged against its worker.
  bool complete(TaskResult result, const Caller& caller = {});
  // A batched upload's results (at most kMaxResultsPerUpload): each checked and its record
  // written as complete() does, then one flush for them all, each merged, and one wait for the
  // ledger's rows. Each has its own outcome: merged, not needed, or the error complete() would
  // have thrown for it alone.
  struct ResultOutcome {
    bool accepted = false;
    std::optional<CoordinatorError> error;
  };
  std::vector<ResultOutcome> complete_batch(std::vector<TaskResult> results,
                                            const Caller& caller = {});
  static constexpr uint32_t kMaxResultsPerUpload = 64;
  void fail(const TaskFailureReport& report, const Caller& caller = {});
  // An upload that check_upload let start was refused before it became a result (its chunks
  // out of order, over the size limit, or failing their checksum): as a refused result, its lease
  // ends, the task is queued again, and the refusal counts against the worker in the job.
  void refuse_upload(const std::string& worker_id, const std::string& lease_id, const TaskRef& task,
                     const std::string& why, const std::vector<std::string>& log = {});

  // `logs`: the job's task attempts (of one frame, or one task by its id, when given), the most
  // recent `limit` (0: 100; at most 10000) ended ones in the order they were stored, then the
  // live ones. InvalidArgument for a task id that is not one of the job's.
  TaskLog task_log(const std::string& job_id, std::optional<FrameNumber> frame,
                   const std::string& task_id, uint32_t limit, const Caller& caller = {}) const;

  // The registered workers, by id. A caller without all_tenants sees other tenants' tasks as
  // "(another tenant's task)" and no principals.
  // In worker id order; a page of at most `limit` after worker `after` (empty: the first), `more`
  // set when workers follow it.
  std::vector<WorkerStatus> workers(const Caller& caller = {}, size_t limit = SIZE_MAX,
                                    const std::string& after = "", bool* more = nullptr) const;

  // Refuses leases and ends watches from now on.
  void shut_down();

  // The coordinator's own storage (disk full, unwritable state directory): why it cannot store
  // results now, or "" when it can. A result it cannot store is refused UNAVAILABLE (the worker
  // retries; nothing counts against it), running jobs show the problem, and `listener` hears
  // each change (the server turns it into the health status of "rayfarm.storage").
  std::string storage_problem() const;
  void set_storage_listener(std::function<void(const std::string& problem)> listener);

  CoordinatorMetrics metrics() const;
  // A call the service refused before it reached the core; `logged` false when the refusal
  // log's rate limit left it out. Lock-free: a flood of refused calls never waits on mu_.
  void note_refused_call(bool logged) {
    ++refused_calls_;
    if (!logged) ++suppressed_refusal_lines_;
  }

 private:
  double now() const { return options_.clock(); }
  std::shared_ptr<JobRecord> build_job(const std::string& id, uint64_t seq, const JobSpec& spec,
                                       const Caller& caller = {}, bool restoring = false);
  std::map<std::string, SceneSummary> scene_summaries(const JobRecord& job, const JobSpec& spec,
                                                      const std::string& bundle_dir,
                                                      const std::string& cache,
                                                      const std::string& bundle_problem,
                                                      bool restoring) const;
  // A requeue's scene version of the job: its bundle laid out (jobs/ID/bundle-vK) and checked as
  // a submit's is, each of its frames split as the job's are (InvalidArgument when they differ
  // in resolution, passes or the like).
  struct FrameScene {
    std::string scene_path;
    BufferHeader base;
  };
  std::map<FrameNumber, FrameScene> version_scenes(const JobRecord& job, uint32_t version,
                                                   const SceneVersion& scene, const Caller& caller,
                                                   bool restoring) const;
  // The job's requeued frames as the store or its folder records them: their scene versions
  // and checkpoint folders (restoring).
  void apply_versions(JobRecord& job, JobVersions versions);
  bool blob_visible(const std::string& sha256, const Caller& caller) const;
  // The spec's bundle checked (paths, digests uploaded by the caller's tenant) and laid out as
  // files in `bundle_dir`.
  void lay_out_bundle(const JobSpec& spec, const std::string& bundle_dir, const Caller& caller,
                      bool restoring) const;
  void add_frames(JobRecord& job, const std::string& bundle_dir, bool restoring);
  void restore(const StoredJob& stored);
  // A stored job that cannot be restored: kept, failed with the reason, with no frames.
  void restore_failed(const StoredJob& stored, const std::string& why);
  // Each job's folder holds its own record (job.spec, job.json, and state.json once it ended)
  // beside its checkpoints, so a job the database lost is recovered from its folder.
  void write_folder_record(const StoredJob& job) const;
  void write_folder_state(const JobRecord& job) const;
  void write_folder_versions(const JobRecord& job) const;  // versions.json, once requeued
  // Folders of runs and scene versions the job no longer names (a requeue replaced them, or one
  // a crash interrupted before the store recorded it).
  void remove_stale_folders(const JobRecord& job) const;
  // Jobs with a folder but no row (the database lost them): recovered; folders of submits that
  // never finished: removed. Job ids are never reused: next_seq_ passes every folder's.
  void recover_folders();
  // Deletes whose folder was renamed to jobs/.deleted-ID (the point of no return) but that a
  // crash interrupted: their rows are deleted and the folders removed. Before any job is restored.
  void finish_deletes();
  // The job's removal (delete, expiry) under its frame locks: `check` (under mu_) may refuse it;
  // expired_unix > 0 marks an expiry (its id then answers so). Logs "job J (STATE) " + why.
  void remove_job(const std::shared_ptr<JobRecord>& job,
                  const std::function<void(const JobRecord&)>& check, int64_t expired_unix,
                  const std::string& why);
  // For an id that retention expired and the caller may see: what to answer; else "".
  std::string expired_message(const std::string& id, const Caller& caller) const;
  void check_limits(const JobSpec& spec) const;
  bool verified(const TaskRef& task) const;
  // A verified task's result: true when it agrees with another worker's (merge it now); false
  // when it is held (the task goes to another worker) or the job failed.          // under mu_
  bool verify(JobRecord& job, const TaskResult& r, const EncodedBuffer& buffer);
  // Whether the job merges results of this build and CPU kind (its pin, or any while none is
  // known; a worker whose kind is unknown, '', may lease any).
  bool pin_ok(const JobRecord& job, const std::string& build_id,
              const std::string& cpu_kind) const;  // under mu_
  // Why a result of this build and kind is not the job's, or "".
  std::string pin_problem(const JobRecord& job, const BufferHeader& header) const;  // under mu_
  // A frame's checkpoint read back: its accumulator and the tasks it holds (no accumulator when
  // it holds none). Reads and writes files: called without mu_, under the frame's lock or before
  // any merge can reach it.
  struct LoadedFrame {
    std::unique_ptr<FrameAccumulator> acc;
    std::vector<TaskRef> done;
  };
  LoadedFrame load_frame(const JobRecord& job, FrameRecord& f) const;
  // A frame's accumulator: the job's merge options, held whole up to options_.frame_memory, else
  // in tiles in the frame's checkpoint folder.
  std::unique_ptr<FrameAccumulator> make_accumulator(const JobRecord& job,
                                                     const FrameRecord& f) const;
  // The loaded state made the frame's: the scheduler learns its done tasks, its figures are
  // published. Under mu_ (and the frame's lock, or no merge can reach it).
  void adopt_frame(JobRecord& job, FrameRecord& f, LoadedFrame loaded);
  void resume_frame(JobRecord& job, FrameRecord& f) { adopt_frame(job, f, load_frame(job, f)); }
  // The result decoded where it lies (its bytes move out of r) and checked against its task and
  // the frame's header `base`.
  EncodedBuffer checked_buffer(const JobRecord& job, const BufferHeader& base, TaskResult& r) const;
  // complete()'s halves. stage_result: the answer when the result needs no flush (not needed,
  // or held for verification); else nullopt, with its record written unflushed and `staged` set.
  // commit_result, once a flush covered the record (`flush_error` when it failed): the ledger's
  // verdict, the merge, the prefix checkpoint; `ticket` is the journal's ticket to wait for.
  struct StagedResult;
  std::optional<bool> stage_result(TaskResult r, const Caller& caller,
                                   std::unique_ptr<StagedResult>& staged);
  bool commit_result(StagedResult& s, const std::string& flush_error, uint64_t& ticket);
  bool record_result(JobRecord& job, const TaskResult& r,  // under mu_
                     const BufferHeader& header);
  void publish_frame(JobRecord& job, FrameRecord& f);                          // under mu_
  // The ledger's transition, and what the coordinator keeps beside the state: the folder's copy,
  // held verification results, watchers. Returns the journal ticket to wait for.   // under mu_
  uint64_t set_state(JobRecord& job, JobState s, const std::string& error);
  // Waits (without mu_) until the journal has stored everything up to `ticket`; after
  // kStoreWaitSeconds refuses UNAVAILABLE naming `what` and the store's problem.
  void wait_stored(uint64_t ticket, const std::string& what) const;
  // A setting of a Queued or Running job that a client changes (pause, resume, priority):
  // refused with FailedPrecondition ("... has already completed; " + refused_because) once the
  // job ended, nothing when `unchanged`, else `change` (the ledger's), the folder's copy, a log
  // line "job J <action> by P" and the watchers told; returns once the change is stored.
  void change_setting(const std::string& id, const Caller& caller, const std::string& action,
                      const std::string& refused_because,
                      const std::function<bool(const JobRecord&)>& unchanged,
                      const std::function<uint64_t(JobRecord&)>& change);
  static constexpr double kStoreWaitSeconds = 10;
  JobStatus status_of(const JobRecord& job) const;                             // under mu_
  // JobStatus::waiting_for of a job not ended.                                  // under mu_
  std::string waiting_for(const JobRecord& job) const;
  FrameStatus frame_status(const JobRecord& job, const FrameRecord& f) const;  // under mu_
  std::shared_ptr<JobRecord> find(const std::string& id) const;                // under mu_
  std::shared_ptr<JobRecord> find_or_throw(const std::string& id) const;       // under mu_
  // find_or_throw, refusing another tenant's job.                                 // under mu_
  std::shared_ptr<JobRecord> find_for(const std::string& id, const Caller& caller) const;
  // The worker's registration checked against the caller; throws if unknown or not theirs.
  // A worker that passes is noted as heard from now (last_seen_: workers connected).
  void check_worker(const std::string& worker_id, const Caller& caller) const;  // under mu_
  // The lease is known and held by worker_id (and for `task` when given): true; false when it  //
  // under mu_ is retired (ended with its task settled); throws otherwise.
  bool check_lease(const std::string& worker_id, const std::string& lease_id,
                   const TaskRef* task) const;

  CoreOptions options_;
  StateDirLock lock_;  // before anything in the state directory is opened
  BlobStore blobs_;
  std::shared_ptr<JobStore> store_;
  std::unique_ptr<Journal> journal_;  // the store's writes, in order, off mu_ (journal.h)
  // Task files written unflushed are made durable together (group_sync.h), off every lock.
  std::unique_ptr<GroupSync> results_sync_;
  std::unique_ptr<Ledger> ledger_;    // the only code that changes task and job state
  mutable std::mutex mu_;
  std::mutex requeue_mu_;  // before any frame's lock and mu_: one requeue at a time
  mutable std::condition_variable changed_;
  uint64_t version_ = 1;  // bumped at every change a watcher may want to see
  bool closing_ = false;
  std::map<std::string, std::shared_ptr<JobRecord>> jobs_;
  // (tenant, request id) -> the job that submit made: a retried submit gets it again.
  std::map<std::pair<std::string, std::string>, std::string> requests_;
  // The job a (tenant, request id) already made, checked against this spec; "" if none. Under mu_
  // (`lock`): while the first submit of the request is storing its job, waits for it.
  std::string submitted_before(const JobSpec& spec, const Caller& caller,
                               std::unique_lock<std::mutex>& lock) const;
  struct WorkerRecord {
    std::string principal;      // the identity that registered it
    std::string build_id;       // the build it said it runs
    std::string isa;            // and its CPU kind ('' when registered by an earlier build)
    WorkerInfo info;            // as registered (restored: its build and kind only)
    double registered_at = 0;   // now() at its registration, or at this coordinator's start
    mutable bool used = false;  // a call other than Register named it (check_worker)
  };
  static constexpr double kUnusedWorkerSeconds = 600;
  double last_worker_sweep_ = -1e300;
  void forget_unused_workers();  // under mu_
  std::map<std::string, WorkerRecord> workers_;
  // Verification (CoreOptions::verify_fraction): each selected task's results so far, one per
  // worker, until two agree; and the workers outvoted, with why.
  std::map<TaskRef, std::vector<std::pair<std::string, EncodedBuffer>>> verifying_;
  std::map<std::string, std::string> outvoted_;
  std::string storage_problem_;  // under mu_
  std::function<void(const std::string&)> storage_listener_;
  void storage_failed(const std::string& why);  // under mu_
  void storage_ok();                            // under mu_
  uint64_t next_seq_ = 1, next_worker_ = 1, next_staging_ = 1;
  CoordinatorMetrics::Counters counters_;            // under mu_
  std::atomic<uint64_t> refused_calls_{0}, suppressed_refusal_lines_{0};
  uint64_t blob_store_bytes_ = 0;                    // under mu_: as of the last retention pass
  // Blob digest -> the scene versions of jobs held that name it (retention collects a blob only
  // once this is 0 and its grace period passed). Under mu_; rebuilt from the jobs at a start.
  std::unordered_map<std::string, int64_t> blob_refs_;
  // Counts the blobs of the job's scene versions from `from_version` on: +1 (held), -1 (gone).
  void reference_blobs(const JobRecord& job, uint32_t from_version, int delta);  // under mu_
  mutable std::map<std::string, double> last_seen_;  // worker id -> now() of its last call
};

}  // namespace rf
