#pragma once

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "cell/common/result.hpp"

struct sqlite3;

namespace cell::task_service {

/// What the journal keeps of one job.
struct JournalJob {
  std::string job_id;
  std::string kind;        ///< "table_pick_place", ...
  std::string robot_id;
  std::string spec_yaml;   ///< as submitted
  std::string request_json;  ///< the JobRequest's other fields (operator, priority, client)
  std::string state;       ///< "queued", "running", "paused", "succeeded", "failed", "cancelled"
  std::string progress_json;  ///< the executor's resumable progress after its last step
  std::int64_t accepted_ns = 0;
  std::int64_t updated_ns = 0;
  std::int64_t steps = 0;  ///< completed steps journaled
};

/// The task service's durable memory: every accepted job and every completed step, in SQLite
/// with write-ahead logging and synchronous=FULL, so that a step reported done survives a kill
/// -9 of the service or a power cut of the PC. One writer (the service); the methods serialise
/// on an internal mutex and may be called from any thread. Not real-time.
///
/// Tables: jobs(job_id PRIMARY KEY, kind, robot_id, spec_yaml, request_json, state,
/// progress_json, accepted_ns, updated_ns, steps) and steps(job_id, n, name, detail_json,
/// at_ns), one row per completed step, for the record.
class Journal {
 public:
  /// Opens (creating if needed) the database at `path` and its directory. Errors: kConfig
  /// naming the path and SQLite's message.
  static Result<Journal> open(const std::string& path);

  Journal(Journal&& other) noexcept;
  Journal& operator=(Journal&& other) noexcept;
  Journal(const Journal&) = delete;
  Journal& operator=(const Journal&) = delete;
  ~Journal();

  /// Records a newly accepted job (state "queued"). Errors: kInvalidArgument when the job id
  /// exists already (the request is a duplicate), kBus-free kConfig for SQLite failures.
  Status accept(const JournalJob& job);

  /// Records a completed step: the job's new progress and state, and the step's row, in one
  /// transaction (all or nothing).
  Status step(const std::string& job_id, const std::string& state, const std::string& name,
              const std::string& detail_json, const std::string& progress_json);

  /// Changes only a job's state (pause, resume, cancel, the end).
  Status set_state(const std::string& job_id, const std::string& state);

  /// The job, or nullopt.
  Result<std::optional<JournalJob>> find(const std::string& job_id) const;

  /// Every job not in a final state (queued, running, paused), oldest first: what a restarted
  /// service resumes.
  Result<std::vector<JournalJob>> unfinished() const;

  /// The most recent `limit` jobs, newest first.
  Result<std::vector<JournalJob>> recent(int limit) const;

  const std::string& path() const noexcept { return path_; }

 private:
  Journal(sqlite3* db, std::string path);
  Status exec(const char* sql) const;
  Result<std::vector<JournalJob>> query_jobs(const char* sql, int limit) const;
  sqlite3* db_ = nullptr;
  std::string path_;
  std::unique_ptr<std::mutex> mutex_ = std::make_unique<std::mutex>();
};

}  // namespace cell::task_service
