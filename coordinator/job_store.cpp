#include "coordinator/job_store.h"

#include <fcntl.h>
#include <sqlite3.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <set>

namespace rf {

namespace {

// A prepared statement that finalizes itself; bind() takes values in order.
class Stmt {
 public:
  Stmt(sqlite3* db, const char* sql, const std::string& path) : db_(db), path_(path) {
    if (sqlite3_prepare_v2(db, sql, -1, &s_, nullptr) != SQLITE_OK) fail("prepare");
  }
  ~Stmt() { sqlite3_finalize(s_); }
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

 private:
  [[noreturn]] void fail(const char* what) {
    throw StoreError(path_ + ": SQLite " + what + ": " + sqlite3_errmsg(db_));
  }
  sqlite3* db_;
  sqlite3_stmt* s_ = nullptr;
  int n_ = 0;
  const std::string& path_;
};

}  // namespace

StateDirLock::StateDirLock(const std::string& dir) {
  if (dir.empty()) throw StoreError("the coordinator's state directory is not set");
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec)
    throw StoreError(dir + ": cannot create the state directory: " + ec.message() +
                     (ec == std::errc::read_only_file_system || ec == std::errc::permission_denied
                          ? " (the coordinator needs a writable --state-dir)"
                          : ""));
  std::string path = dir + "/lock";
  fd_ = ::open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) throw StoreError(path + ": cannot open: " + std::strerror(errno));
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    int err = errno;
    char pid[32] = {};
    ssize_t n = ::pread(fd_, pid, sizeof pid - 1, 0);
    std::string holder = n > 0 ? std::string(pid, size_t(n)) : std::string("unknown");
    while (!holder.empty() && (holder.back() == '\n' || holder.back() == ' ')) holder.pop_back();
    ::close(fd_);
    fd_ = -1;
    if (err == EWOULDBLOCK)
      throw StoreError("state directory " + dir + " is in use by another coordinator (pid " +
                       holder + ", " + path + "); one coordinator per state directory");
    throw StoreError(path + ": cannot lock: " + std::strerror(err));
  }
  std::string pid = std::to_string(::getpid()) + "\n";
  if (::ftruncate(fd_, 0) != 0 || ::pwrite(fd_, pid.data(), pid.size(), 0) < 0) {
    // The lock holds without the pid; a second coordinator then names it "unknown".
  }
}

StateDirLock::~StateDirLock() {
  if (fd_ >= 0) ::close(fd_);
}

JobStore::JobStore(const std::string& path) : path_(path) {
  if (sqlite3_open(path.c_str(), &db_) != SQLITE_OK) {
    std::string why = db_ ? sqlite3_errmsg(db_) : "out of memory";
    sqlite3_close(db_);
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
    sqlite3_close(db_);
    db_ = nullptr;
    throw;
  } catch (const StoreError& e) {
    int code = db_ ? sqlite3_errcode(db_) : 0;
    sqlite3_close(db_);
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

std::string JobStore::damage_advice() const {
  return ". To recover: stop, move " + path_ +
         " and its -wal and -shm files aside (keep them for "
         "a post-mortem), and start again: each job is recovered from its folder under jobs/ "
         "(its spec, state and checkpoints), with its merged passes; task failure counts and "
         "worker registrations start afresh";
}

void JobStore::open_schema() {
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
  exec(
      "CREATE TABLE IF NOT EXISTS leases (id TEXT PRIMARY KEY, job_id TEXT NOT NULL, frame "
      "INTEGER NOT NULL, pass INTEGER NOT NULL, tile INTEGER NOT NULL, worker TEXT NOT NULL)");
  exec("DROP INDEX IF EXISTS leases_job");
  exec("CREATE INDEX IF NOT EXISTS leases_job_frame ON leases (job_id, frame)");
  exec(
      "CREATE TABLE IF NOT EXISTS blob_tenants (tenant TEXT NOT NULL, sha256 TEXT NOT NULL, "
      "PRIMARY KEY (tenant, sha256)) WITHOUT ROWID");
}

JobStore::~JobStore() { sqlite3_close(db_); }

void JobStore::exec(const std::string& sql) {
  char* err = nullptr;
  if (sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
    std::string why = err ? err : "unknown error";
    sqlite3_free(err);
    throw StoreError(path_ + ": SQLite: " + why + " (in: " + sql.substr(0, 60) + ")");
  }
}

uint64_t JobStore::next_seq() {
  Stmt s(db_, "SELECT COALESCE(MAX(seq), 0) FROM jobs", path_);
  return s.step() ? uint64_t(s.integer(0)) + 1 : 1;
}

void JobStore::insert_job(const StoredJob& j) {
  Stmt s(db_,
         "INSERT INTO jobs (id, seq, spec, state, error, submitted, tenant) VALUES "
         "(?,?,?,?,?,?,?)",
         path_);
  s.bind(j.id)
      .bind(int64_t(j.seq))
      .bind_blob(j.spec)
      .bind(int64_t(j.state))
      .bind(j.error)
      .bind(j.submitted_unix)
      .bind(j.tenant)
      .step();
}

void JobStore::set_state(const std::string& id, int state, const std::string& error) {
  Stmt s(db_, "UPDATE jobs SET state = ?, error = ? WHERE id = ?", path_);
  s.bind(int64_t(state)).bind(error).bind(id).step();
}

void JobStore::add_core_seconds(const std::string& id, double seconds) {
  Stmt s(db_, "UPDATE jobs SET core_seconds = core_seconds + ? WHERE id = ?", path_);
  s.bind(seconds).bind(id).step();
}

void JobStore::task_done(const std::string& id, uint32_t frame, uint32_t pass, uint32_t tile,
                         const std::string& worker) {
  insert_event(id, frame, pass, tile, worker, 1, "");
}

// task_events.done: 1 done, 0 failed, 2 result refused.
void JobStore::insert_event(const std::string& id, uint32_t frame, uint32_t pass, uint32_t tile,
                            const std::string& worker, int kind, const std::string& message) {
  Stmt s(db_,
         "INSERT INTO task_events (job_id, frame, pass, tile, worker, done, message) VALUES "
         "(?,?,?,?,?,?,?)",
         path_);
  s.bind(id)
      .bind(int64_t(frame))
      .bind(int64_t(pass))
      .bind(int64_t(tile))
      .bind(worker)
      .bind(int64_t(kind))
      .bind(message)
      .step();
}

void JobStore::task_failed(const std::string& id, uint32_t frame, uint32_t pass, uint32_t tile,
                           const std::string& worker, const std::string& message) {
  insert_event(id, frame, pass, tile, worker, 0, message);
}

std::vector<StoredJob> JobStore::jobs() const {
  Stmt s(db_,
         "SELECT id, seq, spec, state, error, submitted, core_seconds, tenant, build FROM jobs "
         "ORDER BY seq",
         path_);
  std::vector<StoredJob> out;
  while (s.step())
    out.push_back({s.text(0), uint64_t(s.integer(1)), s.text(2), int(s.integer(3)), s.text(4),
                   s.integer(5), s.real(6), s.text(7), s.text(8)});
  return out;
}

void JobStore::insert_worker(const StoredWorker& w) {
  Stmt s(db_, "INSERT OR REPLACE INTO workers (id, principal, build) VALUES (?,?,?)", path_);
  s.bind(w.id).bind(w.principal).bind(w.build_id).step();
}

std::vector<JobStore::StoredWorker> JobStore::workers() const {
  Stmt s(db_, "SELECT id, principal, build, refused FROM workers", path_);
  std::vector<StoredWorker> out;
  while (s.step()) out.push_back({s.text(0), s.text(1), s.text(2), s.text(3)});
  return out;
}

void JobStore::delete_worker(const std::string& id) {
  Stmt s(db_, "DELETE FROM workers WHERE id = ?", path_);
  s.bind(id).step();
}

void JobStore::refuse_worker(const std::string& id, const std::string& why) {
  Stmt s(db_, "UPDATE workers SET refused = ? WHERE id = ?", path_);
  s.bind(why).bind(id).step();
}

void JobStore::add_blob_tenant(const std::string& tenant, const std::string& sha256) {
  Stmt s(db_, "INSERT OR IGNORE INTO blob_tenants (tenant, sha256) VALUES (?,?)", path_);
  s.bind(tenant).bind(sha256).step();
}

bool JobStore::blob_tenant(const std::string& tenant, const std::string& sha256) const {
  Stmt s(db_, "SELECT 1 FROM blob_tenants WHERE tenant = ? AND sha256 = ?", path_);
  s.bind(tenant).bind(sha256);
  return s.step();
}

void JobStore::set_build(const std::string& id, const std::string& build) {
  Stmt s(db_, "UPDATE jobs SET build = ? WHERE id = ?", path_);
  s.bind(build).bind(id).step();
}

void JobStore::insert_lease(const StoredLease& l) {
  exec("PRAGMA synchronous=NORMAL");
  try {
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
  } catch (...) {
    exec("PRAGMA synchronous=FULL");
    throw;
  }
  exec("PRAGMA synchronous=FULL");
}

void JobStore::for_each_lease(const std::string& job_id,
                              const std::function<void(const StoredLease&)>& f) const {
  Stmt s(db_, "SELECT id, frame, pass, tile, worker FROM leases WHERE job_id = ? ORDER BY rowid",
         path_);
  s.bind(job_id);
  while (s.step())
    f({s.text(0), job_id, uint32_t(s.integer(1)), uint32_t(s.integer(2)), uint32_t(s.integer(3)),
       s.text(4)});
}

std::vector<StoredLease> JobStore::leases(const std::string& job_id) const {
  std::vector<StoredLease> out;
  for_each_lease(job_id, [&](const StoredLease& l) { out.push_back(l); });
  return out;
}

void JobStore::delete_leases(const std::string& job_id) {
  Stmt s(db_, "DELETE FROM leases WHERE job_id = ?", path_);
  s.bind(job_id).step();
}

void JobStore::delete_leases(const std::string& job_id, uint32_t frame) {
  Stmt s(db_, "DELETE FROM leases WHERE job_id = ? AND frame = ?", path_);
  s.bind(job_id).bind(int64_t(frame)).step();
}

void JobStore::result_refused(const std::string& id, uint32_t frame, uint32_t pass, uint32_t tile,
                              const std::string& worker, const std::string& why) {
  insert_event(id, frame, pass, tile, worker, 2, why);
}

std::vector<std::string> JobStore::refused_workers(const std::string& id) const {
  Stmt s(db_, "SELECT worker FROM task_events WHERE job_id = ? AND done = 2 ORDER BY rowid", path_);
  s.bind(id);
  std::vector<std::string> out;
  while (s.step()) out.push_back(s.text(0));
  return out;
}

std::vector<JobStore::TaskFailure> JobStore::failures(const std::string& id) const {
  Stmt s(db_,
         "SELECT frame, pass, tile, worker, message FROM task_events WHERE job_id = ? AND done = 0 "
         "ORDER BY rowid",
         path_);
  s.bind(id);
  std::vector<TaskFailure> out;
  while (s.step())
    out.push_back({uint32_t(s.integer(0)), uint32_t(s.integer(1)), uint32_t(s.integer(2)),
                   s.text(3), s.text(4)});
  return out;
}

uint64_t JobStore::tasks_done(const std::string& id) const {
  Stmt s(db_, "SELECT COUNT(*) FROM task_events WHERE job_id = ? AND done = 1", path_);
  s.bind(id);
  return s.step() ? uint64_t(s.integer(0)) : 0;
}

}  // namespace rf
