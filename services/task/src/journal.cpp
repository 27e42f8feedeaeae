#include "journal.hpp"

#include <sqlite3.h>

#include <filesystem>
#include <utility>

#include <fmt/format.h>

namespace cell::task_service {
namespace {

/// A prepared statement, finalised however we leave.
class Statement {
 public:
  Statement(sqlite3* db, const char* sql) : db_(db) {
    rc_ = sqlite3_prepare_v2(db, sql, -1, &stmt_, nullptr);
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  bool ok() const { return rc_ == SQLITE_OK; }
  void text(int i, const std::string& v) {
    sqlite3_bind_text(stmt_, i, v.data(), static_cast<int>(v.size()), SQLITE_TRANSIENT);
  }
  void integer(int i, std::int64_t v) { sqlite3_bind_int64(stmt_, i, v); }
  int step() { return sqlite3_step(stmt_); }
  std::string column_text(int i) const {
    const auto* p = sqlite3_column_text(stmt_, i);
    return p != nullptr ? std::string(reinterpret_cast<const char*>(p)) : std::string();
  }
  std::int64_t column_int(int i) const { return sqlite3_column_int64(stmt_, i); }
  std::string error() const { return sqlite3_errmsg(db_); }

 private:
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
  int rc_ = SQLITE_ERROR;
};

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

constexpr const char* kColumns =
    "job_id, kind, robot_id, spec_yaml, request_json, state, progress_json, accepted_ns, "
    "updated_ns, steps";

JournalJob read_job(const Statement& s) {
  JournalJob j;
  j.job_id = s.column_text(0);
  j.kind = s.column_text(1);
  j.robot_id = s.column_text(2);
  j.spec_yaml = s.column_text(3);
  j.request_json = s.column_text(4);
  j.state = s.column_text(5);
  j.progress_json = s.column_text(6);
  j.accepted_ns = s.column_int(7);
  j.updated_ns = s.column_int(8);
  j.steps = s.column_int(9);
  return j;
}

}  // namespace

Result<Journal> Journal::open(const std::string& path) {
  std::error_code ec;
  const auto dir = std::filesystem::path(path).parent_path();
  if (!dir.empty()) {
    std::filesystem::create_directories(dir, ec);
    if (ec) {
      return Error{Errc::kConfig, fmt::format("journal {}: cannot create {}: {}", path,
                                              dir.string(), ec.message())};
    }
  }
  sqlite3* db = nullptr;
  if (sqlite3_open(path.c_str(), &db) != SQLITE_OK) {
    std::string why = db != nullptr ? sqlite3_errmsg(db) : "out of memory";
    sqlite3_close(db);
    return Error{Errc::kConfig, fmt::format("journal {}: cannot open: {}", path, why)};
  }
  sqlite3_busy_timeout(db, 5000);
  Journal journal(db, path);
  // WAL: a reader never blocks the writer; FULL: a committed step is on disk when commit returns.
  CELL_TRY(journal.exec("PRAGMA journal_mode=WAL"));
  CELL_TRY(journal.exec("PRAGMA synchronous=FULL"));
  CELL_TRY(journal.exec(
      "CREATE TABLE IF NOT EXISTS jobs (job_id TEXT PRIMARY KEY, kind TEXT NOT NULL, "
      "robot_id TEXT NOT NULL, spec_yaml TEXT NOT NULL, request_json TEXT NOT NULL, "
      "state TEXT NOT NULL, progress_json TEXT NOT NULL, accepted_ns INTEGER NOT NULL, "
      "updated_ns INTEGER NOT NULL, steps INTEGER NOT NULL)"));
  CELL_TRY(journal.exec(
      "CREATE TABLE IF NOT EXISTS steps (job_id TEXT NOT NULL, n INTEGER NOT NULL, "
      "name TEXT NOT NULL, detail_json TEXT NOT NULL, at_ns INTEGER NOT NULL, "
      "PRIMARY KEY (job_id, n))"));
  return journal;
}

Journal::Journal(sqlite3* db, std::string path) : db_(db), path_(std::move(path)) {}

Journal::Journal(Journal&& other) noexcept
    : db_(std::exchange(other.db_, nullptr)),
      path_(std::move(other.path_)),
      mutex_(std::move(other.mutex_)) {}

Journal& Journal::operator=(Journal&& other) noexcept {
  if (this != &other) {
    sqlite3_close(db_);
    db_ = std::exchange(other.db_, nullptr);
    path_ = std::move(other.path_);
    mutex_ = std::move(other.mutex_);
  }
  return *this;
}

Journal::~Journal() { sqlite3_close(db_); }

Status Journal::exec(const char* sql) const {
  char* message = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &message) != SQLITE_OK) {
    std::string why = message != nullptr ? message : sqlite3_errmsg(db_);
    sqlite3_free(message);
    return Error{Errc::kConfig, fmt::format("journal {}: {}: {}", path_, sql, why)};
  }
  return ok_status();
}

Status Journal::accept(const JournalJob& job) {
  std::lock_guard lock(*mutex_);
  Statement s(db_, "INSERT INTO jobs (job_id, kind, robot_id, spec_yaml, request_json, state, "
                   "progress_json, accepted_ns, updated_ns, steps) "
                   "VALUES (?, ?, ?, ?, ?, 'queued', ?, ?, ?, 0)");
  if (!s.ok()) {
    return Error{Errc::kConfig, fmt::format("journal {}: {}", path_, s.error())};
  }
  const std::int64_t now = job.accepted_ns != 0 ? job.accepted_ns : now_ns();
  s.text(1, job.job_id);
  s.text(2, job.kind);
  s.text(3, job.robot_id);
  s.text(4, job.spec_yaml);
  s.text(5, job.request_json);
  s.text(6, job.progress_json.empty() ? "{}" : job.progress_json);
  s.integer(7, now);
  s.integer(8, now);
  const int rc = s.step();
  if (rc == SQLITE_CONSTRAINT) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("job '{}' exists already (a job id is used once)", job.job_id)};
  }
  if (rc != SQLITE_DONE) {
    return Error{Errc::kConfig, fmt::format("journal {}: accept '{}': {}", path_, job.job_id,
                                            s.error())};
  }
  return ok_status();
}

Status Journal::step(const std::string& job_id, const std::string& state, const std::string& name,
                     const std::string& detail_json, const std::string& progress_json) {
  std::lock_guard lock(*mutex_);
  CELL_TRY(exec("BEGIN IMMEDIATE"));
  const auto rollback = [&](const std::string& why) -> Status {
    (void)exec("ROLLBACK");
    return Error{Errc::kConfig, fmt::format("journal {}: step '{}' of '{}': {}", path_, name,
                                            job_id, why)};
  };
  const std::int64_t now = now_ns();
  {
    Statement s(db_, "UPDATE jobs SET state = ?, progress_json = ?, updated_ns = ?, "
                     "steps = steps + 1 WHERE job_id = ?");
    s.text(1, state);
    s.text(2, progress_json);
    s.integer(3, now);
    s.text(4, job_id);
    if (!s.ok() || s.step() != SQLITE_DONE) {
      return rollback(s.error());
    }
    if (sqlite3_changes(db_) != 1) {
      return rollback("no such job");
    }
  }
  {
    Statement s(db_, "INSERT INTO steps (job_id, n, name, detail_json, at_ns) "
                     "VALUES (?, (SELECT steps FROM jobs WHERE job_id = ?), ?, ?, ?)");
    s.text(1, job_id);
    s.text(2, job_id);
    s.text(3, name);
    s.text(4, detail_json.empty() ? "{}" : detail_json);
    s.integer(5, now);
    if (!s.ok() || s.step() != SQLITE_DONE) {
      return rollback(s.error());
    }
  }
  return exec("COMMIT");
}

Status Journal::set_state(const std::string& job_id, const std::string& state) {
  std::lock_guard lock(*mutex_);
  Statement s(db_, "UPDATE jobs SET state = ?, updated_ns = ? WHERE job_id = ?");
  s.text(1, state);
  s.integer(2, now_ns());
  s.text(3, job_id);
  if (!s.ok() || s.step() != SQLITE_DONE) {
    return Error{Errc::kConfig, fmt::format("journal {}: state of '{}': {}", path_, job_id,
                                            s.error())};
  }
  return ok_status();
}

Result<std::optional<JournalJob>> Journal::find(const std::string& job_id) const {
  std::lock_guard lock(*mutex_);
  const std::string sql = fmt::format("SELECT {} FROM jobs WHERE job_id = ?", kColumns);
  Statement s(db_, sql.c_str());
  s.text(1, job_id);
  const int rc = s.step();
  if (rc == SQLITE_ROW) {
    return std::optional<JournalJob>(read_job(s));
  }
  if (rc == SQLITE_DONE) {
    return std::optional<JournalJob>();
  }
  return Error{Errc::kConfig, fmt::format("journal {}: find '{}': {}", path_, job_id, s.error())};
}

Result<std::vector<JournalJob>> Journal::query_jobs(const char* sql, int limit) const {
  std::lock_guard lock(*mutex_);
  Statement s(db_, sql);
  if (!s.ok()) {
    return Error{Errc::kConfig, fmt::format("journal {}: {}", path_, s.error())};
  }
  if (limit > 0) {
    s.integer(1, limit);
  }
  std::vector<JournalJob> jobs;
  for (int rc = s.step(); rc != SQLITE_DONE; rc = s.step()) {
    if (rc != SQLITE_ROW) {
      return Error{Errc::kConfig, fmt::format("journal {}: {}", path_, s.error())};
    }
    jobs.push_back(read_job(s));
  }
  return jobs;
}

Result<std::vector<JournalJob>> Journal::unfinished() const {
  const std::string sql = fmt::format(
      "SELECT {} FROM jobs WHERE state IN ('queued', 'running', 'paused') ORDER BY accepted_ns",
      kColumns);
  return query_jobs(sql.c_str(), 0);
}

Result<std::vector<JournalJob>> Journal::recent(int limit) const {
  const std::string sql =
      fmt::format("SELECT {} FROM jobs ORDER BY accepted_ns DESC LIMIT ?", kColumns);
  return query_jobs(sql.c_str(), limit);
}

}  // namespace cell::task_service
