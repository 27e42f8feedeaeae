#pragma once

#include <string>
#include <vector>

/// The `cell` command line: `cell up`, `cell down`, `cell status`.
namespace cell::launcher {

/// Exit codes of `cell`.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;  ///< refused, not everything serving, could not stop
inline constexpr int kExitUsage = 2;    ///< bad command line or bad profile

/// `cell up`.
struct UpOptions {
  std::string profile;            ///< empty: deploy/local.yaml
  std::string host;               ///< --host: which host of a multi-host profile this is
  std::string run_dir;            ///< --run-dir: overrides the profile's run_dir
  bool detach = false;            ///< daemonise; return once the pid file exists
  std::vector<std::string> only;  ///< start only these services
};

/// Loads the profile, resolves it, takes the run directory and supervises until stopped.
/// Blocks SIGCHLD/SIGINT/SIGTERM/SIGHUP/SIGPIPE first, so call it before any thread exists.
int run_up(const UpOptions& options);

/// `cell down`.
struct DownOptions {
  std::string profile;
  std::string run_dir;  ///< --run-dir
  double timeout_s = 30.0;  ///< wait for the supervisor this long, then SIGKILL everything
};

/// SIGTERM to the supervisor owning the profile's run directory; waits until it has exited
/// (its children with it), killing what is left after the timeout. Exit 0 when nothing of
/// the cell remains (also when nothing was running), 1 otherwise, 2 for a bad profile.
int run_down(const DownOptions& options);

/// `cell status`.
struct StatusOptions {
  std::string profile;
  std::string host;               ///< --host: look from this host's DDS configuration
  std::string run_dir;            ///< --run-dir
  std::string identity = "viewer";  ///< DDS identity when the profile's security is enabled
  bool json = false;
  double timeout_s = 2.0;  ///< discovery budget on the bus
};

/// One row per profile service: heartbeat state from the bus (or "lost"/"missing"), plus the
/// supervisor's restarts from status.json. Exit 0 when every profile service is serving.
int run_status(const StatusOptions& options);

/// `cell dds-config` and `cell systemd`: what a multi-host profile generates for one host.
struct GenerateOptions {
  std::string profile;
  std::string host;
  std::string run_dir;
  std::string out;       ///< systemd: the directory to write the units into
  bool install = false;  ///< systemd: write to /etc/systemd/system and reload systemd
};

/// Prints the host's Cyclone DDS configuration (host_dds_config). Exit 2 for a bad profile or
/// host.
int run_dds_config(const GenerateOptions& options);

/// Writes the host's systemd units (systemd_units) and its DDS configuration to options.out
/// (or /etc/systemd/system with --install, then `systemctl daemon-reload` when systemd runs).
int run_systemd(const GenerateOptions& options);

/// Parses argv and runs the chosen command; returns the process exit code.
int main_cli(int argc, char** argv);

}  // namespace cell::launcher
