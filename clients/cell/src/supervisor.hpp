#pragma once

#include <string>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/process/child.hpp"
#include "profile.hpp"
#include "run_dir.hpp"

/// `cell up`'s supervisor: starts the profile's services as child processes, relays and logs
/// their output, restarts the ones that exit unexpectedly with exponential back-off, and stops
/// them all in order on SIGTERM/SIGINT/SIGHUP.
namespace cell::launcher {

/// Exponential back-off of one service (see RestartPolicy). Not thread-safe; cheap to copy.
class Backoff {
 public:
  explicit Backoff(const RestartPolicy& policy) noexcept;

  /// The delay in seconds before restarting a service whose last run lasted `ran_s`, and
  /// advances the policy: a run of stable_after_s or more resets the delay to
  /// backoff_initial_s; each delay handed out doubles the next one, up to backoff_max_s.
  double next_delay_s(double ran_s) noexcept;

 private:
  RestartPolicy policy_;
  double current_s_;
};

/// How a child ended, for humans and status.json: "exit 0", "exit 2",
/// "exit 134 (signal 6: Aborted)" (signals shown as the shell's 128 + n).
std::string describe_exit(const process::ExitInfo& info);

/// One service ready to start: every path resolved.
struct LaunchSpec {
  std::string name;               ///< the profile's name: --id and log file name
  std::string host;               ///< this machine's hostname
  std::string executable;         ///< absolute path
  std::vector<std::string> args;  ///< argv[1..]: --config <abs> --id <name> <profile args>
  std::vector<std::string> env;   ///< KEY=VALUE over the launcher's environment
  std::string log_file;           ///< absolute path of <run_dir>/logs/<name>.log
};

/// Everything `cell up` needs, resolved and checked before anything starts.
struct LaunchPlan {
  Profile profile;                    ///< the profile, environment overrides applied
  RunPaths paths;                     ///< its run directory
  std::string host;                   ///< the profile host this machine is; empty: no hosts
  std::string dds_config;             ///< absolute path of the network configuration
  std::string dds_config_text;        ///< generated XML to write there first (hosts); or empty
  std::string cyclonedds_uri;         ///< file://<dds_config> (per service: + identity)
  std::vector<LaunchSpec> services;   ///< the services to start on this machine
  std::vector<std::string> not_here;  ///< "name (host h)": profile services of other hosts
};

/// Resolves `profile` into a plan. Executables are looked up first in `self_dir` (the
/// directory of the `cell` binary, so a build tree works), then in PATH; a name with a '/' is
/// a path relative to CELL_HOME. `only` (service names) restricts what starts; empty = all.
/// Children get CELL_HOME, CELL_DOMAIN_ID, CELL_PARTITION, CYCLONEDDS_URI, then the profile's
/// own env entries (which win). Errors (kConfig): an executable or config file not found, an
/// unknown name in `only`, a missing Cyclone DDS configuration; each names the profile entry
/// (file:line:col) and what was looked for.
///
/// `host` (from select_host) picks a multi-host profile's share: the services with that
/// `host:`, and a Cyclone configuration generated for that host (host_dds_config), to be
/// written to <run_dir>/dds/<host>.xml before they start (write_dds_config). With security
/// enabled each service's CYCLONEDDS_URI adds its identity, <security.dir>/<name>.xml, which
/// must exist.
Result<LaunchPlan> make_plan(const Profile& profile,
                             const std::vector<std::string>& only,
                             const std::string& self_dir,
                             const std::string& host = {});

/// Writes plan.dds_config_text to plan.dds_config (atomically) when the plan generated one.
/// Errors: kIo naming the file.
Status write_dds_config(const LaunchPlan& plan);

/// Runs the supervisor until a stop signal arrives, then stops every child (SIGTERM to its
/// process group, SIGKILL after profile.stop_grace_s) and returns the exit code (0).
///
/// `signal_fd` is a signalfd for SIGCHLD, SIGINT, SIGTERM and SIGHUP, which the caller has
/// blocked (before any thread exists); the loop sleeps in poll() on it and on the children's
/// output pipes, with a timeout only for back-off and state timers. Every change is written to
/// plan.paths.status_file; child output goes to stdout prefixed "[name] " and, raw, to the
/// service's log file. A child exiting with code 2 (usage or configuration error) is marked
/// failed and not restarted; any other unexpected exit (clean ones included) and a failure to
/// start (exec or fork failing) is retried with back-off. Single-threaded; never throws.
int supervise(const LaunchPlan& plan, int signal_fd);

}  // namespace cell::launcher
