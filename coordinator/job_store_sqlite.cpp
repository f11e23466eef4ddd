// The job store in SQLite (job_store.h): WAL with synchronous=FULL, one connection behind a mutex.
#include <sqlite3.h>

#include <algorithm>
#include <map>
#include <mutex>
#include <set>
#include <string>
#include <utility>

#include "coordinator/job_store.h"
#include "coordinator/spec_codec.h"
#include "farm/frame_range.h"

namespace rf {

namespace {

// Prepared statements kept per connection by their SQL text, so that a statement the journal runs
// for every task is parsed once (SQLite's parser was 1% of the coordinator's CPU per task, perf).
// Every use is under the store's mutex; a statement in use is out of the cache (a nested use of
// the same text prepares its own). close_db finalizes them before the connection closes.
std::mutex g_statements_mu;
std::map<std::pair<sqlite3*, std::string>, sqlite3_stmt*> g_statements;

void close_db(sqlite3* db) {
  if (!db) return;
  {
    std::lock_guard lock(g_statements_mu);
    for (auto it = g_statements.begin(); it != g_statements.end();)
      if (it->first.first == db) {
        sqlite3_finalize(it->second);
        it = g_statements.erase(it);
      } else {
        ++it;
      }
  }
  sqlite3_close(db);
}

// A prepared statement (from the cache, or prepared now) that goes back to the cache, reset and
// unbound, when done; bind() takes values in order.
class Stmt {
 public:
  Stmt(sqlite3* db, const char* sql, const std::string& path) : db_(db), sql_(sql), path_(path) {
    {
      std::lock_guard lock(g_statements_mu);
      auto it = g_statements.find({db, sql_});
      if (it != g_statements.end()) {
        s_ = it->second;
        g_statements.erase(it);
        return;
      }
    }
    if (sqlite3_prepare_v2(db, sql, -1, &s_, nullptr) != SQLITE_OK) fail("prepare");
  }
  ~Stmt() {
    sqlite3_reset(s_);
    sqlite3_clear_bindings(s_);
    std::lock_guard lock(g_statements_mu);
    if (!g_statements.emplace(std::pair{db_, std::move(sql_)}, s_).second) sqlite3_finalize(s_);
  }
  Stmt& bind(const std::string& v) {
    sqlite3_bind_text(s_, ++n_, v.data(), int(v.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Stmt& bind_blob(const std::string& v) {
    sqlite3_bind_blob(s_, ++n_, v.data(), int(v.size()), SQLITE_TRANSIENT);
    return *this;
  }
  Stmt& bind(int64_t v) {
    sqlite3_bind_int64(s_, ++n_, v);
    return *this;
  }
  Stmt& bind(double v) {
    sqlite3_bind_double(s_, ++n_, v);
    return *this;
  }
  bool step() {  // true while a row is available
    int rc = sqlite3_step(s_);
    if (rc == SQLITE_ROW) return true;
    if (rc != SQLITE_DONE) fail("step");
    return false;
  }
  std::string text(int col) const {
    const void* p = sqlite3_column_blob(s_, col);
    return p ? std::string(static_cast<const char*>(p), size_t(sqlite3_column_bytes(s_, col)))
             : std::string();
  }
  int64_t integer(int col) const { return sqlite3_column_int64(s_, col); }
  double real(int col) const { return sqlite3_column_double(s_, col); }
  bool null(int col) const { return sqlite3_column_type(s_, col) == SQLITE_NULL; }

 private:
  [[noreturn]] void fail(const char* what) {
    throw StoreError(path_ + ": SQLite " + what + ": " + sqlite3_errmsg(db_));
  }
  sqlite3* db_;
  std::string sql_;
  sqlite3_stmt* s_ = nullptr;
  int n_ = 0;
  const std::string& path_;
};

// Lists of lines (tags, log lines: none holds a newline) in one TEXT column.
std::string join_lines(const std::vector<std::string>& lines) {
  std::string out;
  for (const std::string& l : lines) out += (out.empty() ? "" : "\n") + l;
  return out;
}

std::vector<std::string> split_lines(const std::string& text) {
  std::vector<std::string> out;
  for (size_t at = 0; at < text.size();) {
    size_t end = std::min(text.find('\n', at), text.size());
    out.push_back(text.substr(at, end - at));
    at = end + 1;
  }
  return out;
}

}  // namespace

namespace {

class SqliteJobStore final : public JobStore {
 public:
  explicit SqliteJobStore(const std::string& path);
  ~SqliteJobStore() override { close_db(db_); }

  void write(const std::vector<StoreWrite>& batch) override;
  uint64_t next_seq() const override;
  std::vector<StoredJob> jobs() const override;
  std::vector<StoredWorker> workers() const override;
  bool blob_tenant(const std::string& tenant, const std::string& sha256) const override;
  std::optional<Tombstone> tombstone(const std::string& job_id) const override;
  void for_each_lease(const std::string& job_id,
                      const std::function<void(const StoredLease&)>& f) const override;
  std::vector<TaskFailure> failures(const std::string& job_id) const override;
  std::vector<std::string> refused_workers(const std::string& job_id) const override;
  std::vector<TaskFailure> failure_history(const std::string& job_id) const override;
  std::vector<StoredAttempt> attempts(const std::string& job_id, std::optional<FrameNumber> frame,
                                      const std::optional<TaskRef>& task, size_t limit,
                                      bool* more) const override;
  uint64_t tasks_done(const std::string& job_id) const override;

 private:
  void exec(const std::string& sql) const;
  void open_schema();  // WAL, tables, columns added since
  std::string damage_advice() const;
  void apply(const StoreWrite& w);  // under mu_, inside a transaction

  mutable std::mutex mu_;
  sqlite3* db_ = nullptr;
  std::string path_;
};

SqliteJobStore::SqliteJobStore(const std::string& path) : path_(path) {
  if (sqlite3_open(path.c_str(), &db_) != SQLITE_OK) {
    std::string why = db_ ? sqlite3_errmsg(db_) : "out of memory";
    close_db(db_);
    throw StoreError(path + ": cannot open the job database: " + why);
  }
  try {
    open_schema();
    std::string check;
    {
      Stmt s(db_, "PRAGMA quick_check", path_);
      while (s.step()) check += (check.empty() ? "" : "; ") + s.text(0);
    }
    if (check != "ok")
      throw StoreDamaged(path + ": the job database is damaged (SQLite quick_check: " +
                         check.substr(0, 500) + ")" + damage_advice());
  } catch (const StoreDamaged&) {
    close_db(db_);
    db_ = nullptr;
    throw;
  } catch (const StoreError& e) {
    int code = db_ ? sqlite3_errcode(db_) : 0;
    close_db(db_);
    db_ = nullptr;
    // Not damage: a full disk or a file that cannot be written. Moving the database aside, the
    // advice for damage, would not help and would lose nothing but time.
    if (code == SQLITE_FULL)
      throw StoreError(std::string(e.what()) +
                       ". The state directory's disk is full: free space there and start again "
                       "(the job database is not damaged)");
    if (code == SQLITE_READONLY || code == SQLITE_CANTOPEN || code == SQLITE_PERM)
      throw StoreError(std::string(e.what()) +
                       ". The job database cannot be written: give the coordinator a writable "
                       "--state-dir");
    throw StoreDamaged(std::string(e.what()) + damage_advice());
  }
}

std::string SqliteJobStore::damage_advice() const {
  return ". To recover: stop, move " + path_ +
         " and its -wal and -shm files aside (keep them for "
         "a post-mortem), and start again: each job is recovered from its folder under jobs/ "
         "(its spec, state and checkpoints), with its merged passes; task failure counts and "
         "worker registrations start afresh";
}

void SqliteJobStore::open_schema() {
  sqlite3_busy_timeout(db_, 5000);
  // WAL with synchronous=FULL: a committed transaction survives a power loss.
  exec("PRAGMA journal_mode=WAL");
  exec("PRAGMA synchronous=FULL");
  exec(
      "CREATE TABLE IF NOT EXISTS jobs (id TEXT PRIMARY KEY, seq INTEGER NOT NULL, spec BLOB NOT "
      "NULL, state INTEGER NOT NULL, error TEXT NOT NULL DEFAULT '', submitted INTEGER NOT NULL, "
      "core_seconds REAL NOT NULL DEFAULT 0)");
  exec(
      "CREATE TABLE IF NOT EXISTS task_events (job_id TEXT NOT NULL, frame INTEGER NOT NULL, "
      "pass INTEGER NOT NULL, tile INTEGER NOT NULL, worker TEXT NOT NULL, done INTEGER NOT NULL, "
      "message TEXT NOT NULL DEFAULT '', at INTEGER NOT NULL DEFAULT (strftime('%s','now')))");
  exec("CREATE INDEX IF NOT EXISTS task_events_job ON task_events (job_id, done)");
  // Columns added since: a store written before gains them, empty.
  std::set<std::string> columns;
  {
    Stmt s(db_, "SELECT name FROM pragma_table_info('jobs')", path_);
    while (s.step()) columns.insert(s.text(0));
  }
  if (!columns.count("tenant")) exec("ALTER TABLE jobs ADD COLUMN tenant TEXT NOT NULL DEFAULT ''");
  if (!columns.count("build")) exec("ALTER TABLE jobs ADD COLUMN build TEXT NOT NULL DEFAULT ''");
  if (!columns.count("paused"))
    exec("ALTER TABLE jobs ADD COLUMN paused INTEGER NOT NULL DEFAULT 0");
  if (!columns.count("priority")) exec("ALTER TABLE jobs ADD COLUMN priority INTEGER");
  // The CPU kind its results come from (BufferHeader::isa), pinned with the build.
  if (!columns.count("cpu_kind"))
    exec("ALTER TABLE jobs ADD COLUMN cpu_kind TEXT NOT NULL DEFAULT ''");
  // 1: deleted (the row keeps the id and sequence number only).
  if (!columns.count("deleted"))
    exec("ALTER TABLE jobs ADD COLUMN deleted INTEGER NOT NULL DEFAULT 0");
  // Frames a retry left out, in the range syntax (farm/frame_range.h).
  if (!columns.count("held")) exec("ALTER TABLE jobs ADD COLUMN held TEXT NOT NULL DEFAULT ''");
  // Its scene versions and requeued frames (coordinator/versions.h), '' until a requeue.
  if (!columns.count("versions"))
    exec("ALTER TABLE jobs ADD COLUMN versions TEXT NOT NULL DEFAULT ''");
  // When it last ended (Unix seconds; 0 while queued or running, and in rows of earlier builds),
  // and when retention expired it (0: not expired; a deleted row with 0 was a client's delete).
  if (!columns.count("ended")) exec("ALTER TABLE jobs ADD COLUMN ended INTEGER NOT NULL DEFAULT 0");
  if (!columns.count("expired"))
    exec("ALTER TABLE jobs ADD COLUMN expired INTEGER NOT NULL DEFAULT 0");
  columns.clear();
  {
    Stmt s(db_, "SELECT name FROM pragma_table_info('task_events')", path_);
    while (s.step()) columns.insert(s.text(0));
  }
  // 0 for a failure or refused result a retry forgot: history, no longer counted.
  if (!columns.count("counted"))
    exec("ALTER TABLE task_events ADD COLUMN counted INTEGER NOT NULL DEFAULT 1");
  exec(
      "CREATE TABLE IF NOT EXISTS workers (id TEXT PRIMARY KEY, principal TEXT NOT NULL, build "
      "TEXT NOT NULL DEFAULT '', registered INTEGER NOT NULL DEFAULT (strftime('%s','now')))");
  columns.clear();
  {
    Stmt s(db_, "SELECT name FROM pragma_table_info('workers')", path_);
    while (s.step()) columns.insert(s.text(0));
  }
  if (!columns.count("refused"))
    exec("ALTER TABLE workers ADD COLUMN refused TEXT NOT NULL DEFAULT ''");
  if (!columns.count("isa")) exec("ALTER TABLE workers ADD COLUMN isa TEXT NOT NULL DEFAULT ''");
  // Its tags, one per line (a tag holds no newline: farm/tags.h).
  if (!columns.count("tags")) exec("ALTER TABLE workers ADD COLUMN tags TEXT NOT NULL DEFAULT ''");
  exec(
      "CREATE TABLE IF NOT EXISTS leases (id TEXT PRIMARY KEY, job_id TEXT NOT NULL, frame "
      "INTEGER NOT NULL, pass INTEGER NOT NULL, tile INTEGER NOT NULL, worker TEXT NOT NULL)");
  exec("DROP INDEX IF EXISTS leases_job");
  exec("CREATE INDEX IF NOT EXISTS leases_job_frame ON leases (job_id, frame)");
  // Each ended attempt of a task (`rayfarm logs`); log: its lines joined by newlines.
  exec(
      "CREATE TABLE IF NOT EXISTS attempts (job_id TEXT NOT NULL, frame INTEGER NOT NULL, pass "
      "INTEGER NOT NULL, tile INTEGER NOT NULL, lease_id TEXT NOT NULL, worker TEXT NOT NULL, "
      "started REAL NOT NULL, ended REAL NOT NULL, outcome INTEGER NOT NULL, message TEXT NOT "
      "NULL, log TEXT NOT NULL)");
  exec("CREATE INDEX IF NOT EXISTS attempts_task ON attempts (job_id, frame, pass, tile)");
  exec(
      "CREATE TABLE IF NOT EXISTS blob_tenants (tenant TEXT NOT NULL, sha256 TEXT NOT NULL, "
      "PRIMARY KEY (tenant, sha256)) WITHOUT ROWID");
}

void SqliteJobStore::exec(const std::string& sql) const {
  char* err = nullptr;
  if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
    std::string why = err ? err : "unknown error";
    sqlite3_free(err);
    throw StoreError(path_ + ": SQLite: " + why + " (in: " + sql.substr(0, 60) + ")");
  }
}

void SqliteJobStore::write(const std::vector<StoreWrite>& batch) {
  if (batch.empty()) return;
  bool leases_only = true;
  for (const StoreWrite& w : batch) leases_only &= lease_write(w);
  std::lock_guard lock(mu_);
  // Lease rows are not flushed: losing the last ones in a power cut only makes their holders'
  // late results be rendered again.
  if (leases_only) exec("PRAGMA synchronous=NORMAL");
  try {
    exec("BEGIN IMMEDIATE");
    try {
      for (const StoreWrite& w : batch) apply(w);
      exec("COMMIT");
    } catch (...) {
      char* err = nullptr;
      sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, &err);
      sqlite3_free(err);
      throw;
    }
  } catch (...) {
    if (leases_only) exec("PRAGMA synchronous=FULL");
    throw;
  }
  if (leases_only) exec("PRAGMA synchronous=FULL");
}

void SqliteJobStore::apply(const StoreWrite& write) {
  std::visit(
      [&](const auto& w) {
        using W = std::decay_t<decltype(w)>;
        if constexpr (std::is_same_v<W, store::InsertJob>) {
          const StoredJob& j = w.job;
          Stmt s(db_,
                 "INSERT INTO jobs (id, seq, spec, state, error, submitted, tenant) VALUES "
                 "(?,?,?,?,?,?,?)",
                 path_);
          s.bind(j.id)
              .bind(int64_t(j.seq))
              .bind_blob(j.spec ? encode_spec(*j.spec) : std::string())
              .bind(int64_t(j.state))
              .bind(j.error)
              .bind(j.submitted_unix)
              .bind(j.tenant)
              .step();
        } else if constexpr (std::is_same_v<W, store::SetState>) {
          Stmt s(db_, "UPDATE jobs SET state = ?, error = ?, ended = ? WHERE id = ?", path_);
          s.bind(int64_t(w.state)).bind(w.error).bind(w.ended_unix).bind(w.job_id).step();
        } else if constexpr (std::is_same_v<W, store::AddCoreSeconds>) {
          Stmt s(db_, "UPDATE jobs SET core_seconds = core_seconds + ? WHERE id = ?", path_);
          s.bind(w.seconds).bind(w.job_id).step();
        } else if constexpr (std::is_same_v<W, store::SetBuild>) {
          Stmt s(db_, "UPDATE jobs SET build = ?, cpu_kind = ? WHERE id = ?", path_);
          s.bind(w.build_id).bind(w.cpu_kind).bind(w.job_id).step();
        } else if constexpr (std::is_same_v<W, store::SetPaused>) {
          Stmt s(db_, "UPDATE jobs SET paused = ? WHERE id = ?", path_);
          s.bind(int64_t(w.paused)).bind(w.job_id).step();
        } else if constexpr (std::is_same_v<W, store::SetPriority>) {
          Stmt s(db_, "UPDATE jobs SET priority = ? WHERE id = ?", path_);
          s.bind(int64_t(w.priority)).bind(w.job_id).step();
        } else if constexpr (std::is_same_v<W, store::Retry>) {
          Stmt s(db_, "UPDATE jobs SET held = ? WHERE id = ?", path_);
          s.bind(frame_range_text(w.held)).bind(w.job_id).step();
          if (w.forget_failures) {
            Stmt f(db_, "UPDATE task_events SET counted = 0 WHERE job_id = ? AND done != 1", path_);
            f.bind(w.job_id).step();
          }
        } else if constexpr (std::is_same_v<W, store::SetVersions>) {
          Stmt s(db_, "UPDATE jobs SET versions = ? WHERE id = ?", path_);
          s.bind(w.versions).bind(w.job_id).step();
        } else if constexpr (std::is_same_v<W, store::DeleteJob>) {
          Stmt s(db_,
                 "UPDATE jobs SET deleted = 1, spec = x'', error = '', build = '', held = '', "
                 "versions = '', expired = ? WHERE id = ?",
                 path_);
          s.bind(w.expired_unix).bind(w.job_id).step();
          for (const char* sql :
               {"DELETE FROM task_events WHERE job_id = ?", "DELETE FROM leases WHERE job_id = ?",
                "DELETE FROM attempts WHERE job_id = ?"}) {
            Stmt d(db_, sql, path_);
            d.bind(w.job_id).step();
          }
        } else if constexpr (std::is_same_v<W, store::Attempt>) {
          const StoredAttempt& a = w.attempt;
          Stmt s(db_,
                 "INSERT INTO attempts (job_id, frame, pass, tile, lease_id, worker, started, "
                 "ended, outcome, message, log) VALUES (?,?,?,?,?,?,?,?,?,?,?)",
                 path_);
          s.bind(a.job_id)
              .bind(int64_t(a.frame))
              .bind(int64_t(a.pass))
              .bind(int64_t(a.tile))
              .bind(a.lease_id)
              .bind(a.worker_id)
              .bind(a.started_unix)
              .bind(a.ended_unix)
              .bind(int64_t(a.outcome))
              .bind(a.message)
              .bind(join_lines(a.log))
              .step();
        } else if constexpr (std::is_same_v<W, store::TaskEvent>) {
          // task_events.done: 1 done, 0 failed, 2 result refused (TaskEventKind).
          Stmt s(db_,
                 "INSERT INTO task_events (job_id, frame, pass, tile, worker, done, message) "
                 "VALUES (?,?,?,?,?,?,?)",
                 path_);
          s.bind(w.job_id)
              .bind(int64_t(w.frame))
              .bind(int64_t(w.pass))
              .bind(int64_t(w.tile))
              .bind(w.worker_id)
              .bind(int64_t(w.kind))
              .bind(w.message)
              .step();
        } else if constexpr (std::is_same_v<W, store::InsertWorker>) {
          Stmt s(db_,
                 "INSERT OR REPLACE INTO workers (id, principal, build, isa, tags) VALUES "
                 "(?,?,?,?,?)",
                 path_);
          s.bind(w.worker.id)
              .bind(w.worker.principal)
              .bind(w.worker.build_id)
              .bind(w.worker.isa)
              .bind(join_lines(w.worker.tags))
              .step();
        } else if constexpr (std::is_same_v<W, store::RefuseWorker>) {
          Stmt s(db_, "UPDATE workers SET refused = ? WHERE id = ?", path_);
          s.bind(w.why).bind(w.worker_id).step();
        } else if constexpr (std::is_same_v<W, store::DeleteWorker>) {
          Stmt s(db_, "DELETE FROM workers WHERE id = ?", path_);
          s.bind(w.worker_id).step();
        } else if constexpr (std::is_same_v<W, store::AddBlobTenant>) {
          Stmt s(db_, "INSERT OR IGNORE INTO blob_tenants (tenant, sha256) VALUES (?,?)", path_);
          s.bind(w.tenant).bind(w.sha256).step();
        } else if constexpr (std::is_same_v<W, store::ForgetBlob>) {
          Stmt s(db_, "DELETE FROM blob_tenants WHERE sha256 = ?", path_);
          s.bind(w.sha256).step();
        } else if constexpr (std::is_same_v<W, store::InsertLease>) {
          const StoredLease& l = w.lease;
          Stmt s(db_,
                 "INSERT OR REPLACE INTO leases (id, job_id, frame, pass, tile, worker) VALUES "
                 "(?,?,?,?,?,?)",
                 path_);
          s.bind(l.lease_id)
              .bind(l.job_id)
              .bind(int64_t(l.frame))
              .bind(int64_t(l.pass))
              .bind(int64_t(l.tile))
              .bind(l.worker_id)
              .step();
        } else if constexpr (std::is_same_v<W, store::DeleteLeases>) {
          if (w.frame) {
            Stmt s(db_, "DELETE FROM leases WHERE job_id = ? AND frame = ?", path_);
            s.bind(w.job_id).bind(int64_t(*w.frame)).step();
          } else {
            Stmt s(db_, "DELETE FROM leases WHERE job_id = ?", path_);
            s.bind(w.job_id).step();
          }
        }
      },
      write);
}

uint64_t SqliteJobStore::next_seq() const {
  std::lock_guard lock(mu_);
  Stmt s(db_, "SELECT COALESCE(MAX(seq), 0) FROM jobs", path_);
  return s.step() ? uint64_t(s.integer(0)) + 1 : 1;
}

std::vector<StoredJob> SqliteJobStore::jobs() const {
  std::lock_guard lock(mu_);
  Stmt s(db_,
         "SELECT id, seq, spec, state, error, submitted, core_seconds, tenant, build, paused, "
         "priority, held, cpu_kind, versions, ended FROM jobs WHERE deleted = 0 ORDER BY seq",
         path_);
  std::vector<StoredJob> out;
  while (s.step()) {
    out.push_back({s.text(0), uint64_t(s.integer(1)), decode_spec(s.text(2)), int(s.integer(3)),
                   s.text(4), s.integer(5), s.real(6), s.text(7), s.text(8), s.integer(9) != 0,
                   std::nullopt});
    if (!s.null(10)) out.back().priority = int(s.integer(10));
    out.back().cpu_kind = s.text(12);
    out.back().versions = s.text(13);
    out.back().ended_unix = s.integer(14);
    if (std::string held = s.text(11); !held.empty()) {
      try {
        out.back().held = parse_frame_range(held);
      } catch (const std::exception&) {  // not written by rayfarm: the job runs every frame
        out.back().held.clear();
      }
    }
  }
  return out;
}

std::vector<StoredWorker> SqliteJobStore::workers() const {
  std::lock_guard lock(mu_);
  Stmt s(db_, "SELECT id, principal, build, refused, isa, tags FROM workers", path_);
  std::vector<StoredWorker> out;
  while (s.step())
    out.push_back({s.text(0), s.text(1), s.text(2), s.text(3), s.text(4), split_lines(s.text(5))});
  return out;
}

bool SqliteJobStore::blob_tenant(const std::string& tenant, const std::string& sha256) const {
  std::lock_guard lock(mu_);
  Stmt s(db_, "SELECT 1 FROM blob_tenants WHERE tenant = ? AND sha256 = ?", path_);
  s.bind(tenant).bind(sha256);
  return s.step();
}

std::optional<Tombstone> SqliteJobStore::tombstone(const std::string& job_id) const {
  std::lock_guard lock(mu_);
  Stmt s(db_, "SELECT expired, tenant FROM jobs WHERE id = ? AND deleted = 1 AND expired > 0",
         path_);
  s.bind(job_id);
  if (!s.step()) return std::nullopt;
  return Tombstone{s.integer(0), s.text(1)};
}

void SqliteJobStore::for_each_lease(const std::string& job_id,
                                    const std::function<void(const StoredLease&)>& f) const {
  std::lock_guard lock(mu_);
  Stmt s(db_, "SELECT id, frame, pass, tile, worker FROM leases WHERE job_id = ? ORDER BY rowid",
         path_);
  s.bind(job_id);
  while (s.step())
    f({s.text(0), job_id, FrameNumber(s.integer(1)), uint32_t(s.integer(2)), uint32_t(s.integer(3)),
       s.text(4)});
}

std::vector<std::string> SqliteJobStore::refused_workers(const std::string& id) const {
  std::lock_guard lock(mu_);
  Stmt s(db_,
         "SELECT worker FROM task_events WHERE job_id = ? AND done = 2 AND counted = 1 ORDER BY "
         "rowid",
         path_);
  s.bind(id);
  std::vector<std::string> out;
  while (s.step()) out.push_back(s.text(0));
  return out;
}

std::vector<TaskFailure> SqliteJobStore::failures(const std::string& id) const {
  std::vector<TaskFailure> out = failure_history(id);
  std::erase_if(out, [](const TaskFailure& f) { return !f.counted; });
  return out;
}

std::vector<TaskFailure> SqliteJobStore::failure_history(const std::string& id) const {
  std::lock_guard lock(mu_);
  Stmt s(db_,
         "SELECT frame, pass, tile, worker, message, counted FROM task_events WHERE job_id = ? AND "
         "done = 0 ORDER BY rowid",
         path_);
  s.bind(id);
  std::vector<TaskFailure> out;
  while (s.step())
    out.push_back({FrameNumber(s.integer(0)), uint32_t(s.integer(1)), uint32_t(s.integer(2)),
                   s.text(3), s.text(4), s.integer(5) != 0});
  return out;
}

std::vector<StoredAttempt> SqliteJobStore::attempts(const std::string& job_id,
                                                    std::optional<FrameNumber> frame,
                                                    const std::optional<TaskRef>& task,
                                                    size_t limit, bool* more) const {
  std::lock_guard lock(mu_);
  std::string sql =
      "SELECT frame, pass, tile, lease_id, worker, started, ended, outcome, message, log FROM "
      "attempts WHERE job_id = ?";
  if (task)
    sql += " AND frame = ? AND pass = ? AND tile = ?";
  else if (frame)
    sql += " AND frame = ?";
  sql += " ORDER BY rowid DESC LIMIT ?";
  Stmt s(db_, sql.c_str(), path_);
  s.bind(job_id);
  if (task)
    s.bind(int64_t(task->frame)).bind(int64_t(task->pass)).bind(int64_t(task->tile));
  else if (frame)
    s.bind(int64_t(*frame));
  s.bind(int64_t(std::min<size_t>(limit, INT32_MAX)) + 1);
  std::vector<StoredAttempt> out;
  while (s.step()) {
    StoredAttempt a{job_id,
                    FrameNumber(s.integer(0)),
                    uint32_t(s.integer(1)),
                    uint32_t(s.integer(2)),
                    s.text(3),
                    s.text(4),
                    s.real(5),
                    s.real(6),
                    AttemptOutcome(s.integer(7)),
                    s.text(8),
                    split_lines(s.text(9))};
    out.push_back(std::move(a));
  }
  *more = out.size() > limit;
  if (*more) out.pop_back();
  std::reverse(out.begin(), out.end());
  return out;
}

uint64_t SqliteJobStore::tasks_done(const std::string& id) const {
  std::lock_guard lock(mu_);
  Stmt s(db_, "SELECT COUNT(*) FROM task_events WHERE job_id = ? AND done = 1", path_);
  s.bind(id);
  return s.step() ? uint64_t(s.integer(0)) : 0;
}

}  // namespace

std::unique_ptr<JobStore> open_sqlite_store(const std::string& path) {
  return std::make_unique<SqliteJobStore>(path);
}

}  // namespace rf
