#pragma once

#include <sys/types.h>

#include <chrono>
#include <optional>
#include <string>
#include <vector>

#include "cell/common/result.hpp"

namespace cell::process {

/// How to start a child process.
struct SpawnOptions {
  std::string executable;                ///< path, or a name looked up in PATH
  std::vector<std::string> args;         ///< argv[1..]
  std::vector<std::string> env;          ///< extra "KEY=VALUE" entries over the parent's env
                                         ///< (a later entry for a key wins)
  std::string working_dir;               ///< empty: inherit
  bool capture_output = true;            ///< stdout+stderr into one pipe (read via output_fd)
  /// When not empty: stdout+stderr appended to this file instead of a pipe (capture_output is
  /// then ignored, output() stays empty). A long run then never stalls on a full pipe that
  /// nobody read (64 KiB of log lines block a child's next write).
  std::string output_path;
  bool new_process_group = true;         ///< child leads its own group (signals reach its tree)
  bool die_with_parent = true;           ///< PR_SET_PDEATHSIG(SIGTERM): no orphan if we die
};

/// How a child ended.
struct ExitInfo {
  bool exited = false;    ///< returned from main / called exit
  int code = 0;           ///< exit code when exited
  int signal = 0;         ///< terminating signal when !exited
  /// "exit 0", "exit 2", "signal 9 (Killed)".
  std::string describe() const;
};

/// Owner of one child process. Move-only. The destructor kills (SIGKILL) and reaps a child
/// still running, so a test or launcher never leaves strays behind. Not thread-safe.
class Child {
 public:
  /// Starts the child. Errors: kIo when fork/exec fails (exec failure is detected through a
  /// close-on-exec pipe, so a missing executable is reported here, not as exit 127).
  static Result<Child> spawn(const SpawnOptions& options);

  Child() = default;
  Child(Child&& other) noexcept;
  Child& operator=(Child&& other) noexcept;
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  ~Child();

  pid_t pid() const noexcept { return pid_; }
  bool running() const noexcept { return pid_ > 0 && !exit_.has_value(); }

  /// Read end of the merged stdout/stderr pipe (non-blocking), or -1 when not captured.
  int output_fd() const noexcept { return output_fd_; }

  /// Non-blocking: reads what is available from the output pipe and appends to `out`.
  /// Returns false once the pipe reached end of file.
  bool read_available(std::string& out);

  /// Non-blocking reap. Returns the exit info once the child has ended.
  std::optional<ExitInfo> poll();

  /// Waits up to `timeout` for the child to end (reading its output meanwhile into the
  /// buffer returned by output()). Returns nullopt on timeout.
  std::optional<ExitInfo> wait_for(std::chrono::milliseconds timeout);

  /// Sends `sig` to the child (to its process group when it leads one).
  void signal(int sig) const noexcept;

  /// SIGTERM, wait up to `grace`, then SIGKILL; always reaps. Returns how it ended.
  ExitInfo stop(std::chrono::milliseconds grace);

  /// Everything read from the output pipe so far (by read_available/wait_for/stop).
  const std::string& output() const noexcept { return output_; }

 private:
  void close_fd() noexcept;
  pid_t pid_ = -1;
  int output_fd_ = -1;
  bool group_leader_ = false;
  std::optional<ExitInfo> exit_;
  std::string output_;
};

/// Resolves `name` against PATH (or returns it unchanged if it contains a '/').
std::string which(const std::string& name);

/// True if a process with this pid exists (kill(pid, 0)), zombie included.
bool pid_alive(pid_t pid) noexcept;

}  // namespace cell::process
