#pragma once

#include <sys/types.h>

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "cell/common/result.hpp"

/// The run directory a supervisor owns: logs/<service>.log, logs/cell.log (detached
/// supervisor output), cell.pid (held with an exclusive flock while the supervisor lives) and
/// status.json (the supervisor's view of its children, rewritten atomically on every change).
namespace cell::launcher {

/// File names inside one run directory.
struct RunPaths {
  std::string dir;             ///< absolute run directory
  std::string logs;            ///< dir/logs
  std::string pid_file;        ///< dir/cell.pid
  std::string status_file;     ///< dir/status.json
  std::string supervisor_log;  ///< dir/logs/cell.log

  /// The paths inside `dir` (an absolute path). Creates nothing.
  static RunPaths of(const std::string& dir);
  /// dir/logs/<service>.log
  std::string service_log(const std::string& service) const;
};

/// Creates the run and log directories. Errors: kIo naming the path and the reason.
Status make_run_dirs(const RunPaths& paths);

/// The supervisor's exclusive claim on a run directory: an flock on cell.pid, which holds the
/// supervisor's pid. The lock dies with the process, so a crashed supervisor never blocks the
/// next one (a stale pid file is simply taken over). Move-only; the destructor removes the
/// file and releases the lock.
class PidFileLock {
 public:
  /// Takes the lock and writes this process's pid. Errors: kNotReady "a supervisor (pid N)
  /// already owns <dir>" when another live process holds it; kIo on file errors.
  static Result<PidFileLock> acquire(const std::string& pid_file);

  /// An empty lock that owns nothing.
  PidFileLock() = default;
  /// Takes over `other`'s claim; `other` owns nothing afterwards.
  PidFileLock(PidFileLock&& other) noexcept;
  /// Releases this claim, then takes over `other`'s.
  PidFileLock& operator=(PidFileLock&& other) noexcept;
  PidFileLock(const PidFileLock&) = delete;
  PidFileLock& operator=(const PidFileLock&) = delete;
  /// release().
  ~PidFileLock();

  /// Removes the pid file and releases the lock (idempotent).
  void release() noexcept;

 private:
  std::string path_;
  int fd_ = -1;
};

/// The pid of the live supervisor holding `pid_file`'s lock, or nullopt when none does
/// (no file, or a stale file left by a killed supervisor).
std::optional<pid_t> live_supervisor(const std::string& pid_file);

/// One past exit of a service, as status.json keeps it (the last 10).
struct ExitRecord {
  std::int64_t ended_ns = 0;  ///< wall clock, ns since the epoch
  std::string exit;           ///< "exit 0", "exit 134 (signal 6: Aborted)"
  double ran_s = 0.0;         ///< how long that run lasted
  double backoff_s = 0.0;     ///< delay chosen before the next start (0: not restarted)
};

/// The supervisor's view of one service.
struct ServiceStatus {
  std::string name;
  std::string host;
  std::string exec;                 ///< resolved executable path
  std::string log;                  ///< absolute log file path
  pid_t pid = 0;                    ///< 0 when not running
  std::string state;                ///< starting | running | backoff | failed | stopping | stopped
  int restarts = 0;                 ///< times it was started again after an unexpected exit
  std::string last_exit;            ///< "" before the first exit
  std::string reason;               ///< why failed (spawn error, config error), else ""
  std::int64_t started_ns = 0;      ///< wall clock of the current (or last) start
  double backoff_s = 0.0;           ///< delay of the pending or last restart
  std::int64_t next_start_ns = 0;   ///< wall clock of the pending restart (state backoff)
  std::vector<ExitRecord> history;  ///< newest last, at most 10
  std::vector<std::string> last_lines;  ///< output tail of a failed service
};

/// Contents of status.json.
struct StatusFile {
  std::string profile;
  std::string profile_path;
  pid_t supervisor_pid = 0;
  std::string state;  ///< running | stopping | stopped
  std::int64_t started_ns = 0;
  std::int64_t updated_ns = 0;
  std::uint32_t domain_id = 0;
  std::string partition;
  std::vector<ServiceStatus> services;

  /// The entry of `name`, or nullptr.
  const ServiceStatus* find(const std::string& name) const;
};

/// Writes `text` to `path` through a temporary file and a rename (creating the parent
/// directory), so a reader never sees half a file. Errors: kIo naming the file.
Status write_file_atomically(const std::string& path, const std::string& text);

/// Writes `status` as JSON to `path` atomically (temporary file + rename), so a reader never
/// sees half a file. Errors: kIo.
Status write_status(const std::string& path, const StatusFile& status);

/// Reads status.json. Errors: kIo when missing or unreadable, kInvalidArgument when it is not
/// the JSON write_status() writes.
Result<StatusFile> read_status(const std::string& path);

/// True while `pid` is a running process (exists and is not a zombie).
bool process_running(pid_t pid) noexcept;

/// True when the running process `pid` executes `exe` (readlink /proc/<pid>/exe), so a pid
/// recorded earlier is not mistaken for an unrelated process that reused it.
bool process_is(pid_t pid, const std::string& exe) noexcept;

/// Waits until `pid` (not necessarily our child) has exited, up to `timeout_ms`; returns
/// whether it did. Uses a pidfd where the kernel has one, else polls every 20 ms.
bool wait_process_exit(pid_t pid, int timeout_ms) noexcept;

}  // namespace cell::launcher
