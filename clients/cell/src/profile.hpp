#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "cell/common/result.hpp"

/// The launcher's profile: which services make up a cell on this machine and how to run them
/// (deploy/README.md documents the schema; deploy/local.yaml is the default profile).
namespace cell::launcher {

/// One service of the profile, as written in the file (paths not yet resolved).
struct ServiceSpec {
  std::string name;    ///< unique in the profile; the service id on the bus (--id) and log name
  std::string exec;    ///< executable: a name ("cell-echo") or a path (relative to CELL_HOME)
  std::string config;  ///< --config file, relative to CELL_HOME; empty: the service's default
  std::vector<std::string> args;                         ///< extra arguments, appended
  std::vector<std::pair<std::string, std::string>> env;  ///< extra environment, in file order
  std::string host = "local";  ///< "local" or a hostname: `cell up` starts only its own
  std::string where;           ///< "file:line:col" of the entry, for messages
};

/// Restart with exponential back-off: the first restart waits `backoff_initial_s`, each
/// further quick crash doubles the wait up to `backoff_max_s`; a run of `stable_after_s` or
/// longer resets it.
struct RestartPolicy {
  double backoff_initial_s = 0.5;  ///< delay before the first restart, > 0
  double backoff_max_s = 30.0;     ///< cap of the doubling, >= backoff_initial_s
  double stable_after_s = 10.0;    ///< a run this long resets the delay, >= 0
};

/// The DDS bus every service of the profile joins.
struct BusSettings {
  std::uint32_t domain_id = 0;                                ///< 0..230
  std::string partition = "cell";                             ///< not empty
  std::string cyclonedds_config = "config/dds/loopback.xml";  ///< relative to CELL_HOME
};

/// A parsed and validated profile. Immutable once loaded (apply_environment aside).
struct Profile {
  std::string path;                   ///< absolute path of the profile file
  std::string name;                   ///< `profile:`; defaults to the file's stem
  BusSettings bus;                    ///< `bus:`
  std::string run_dir = "run";        ///< logs/, cell.pid, status.json; relative to CELL_HOME
  RestartPolicy restart;              ///< `restart:`
  double stop_grace_s = 5.0;          ///< SIGTERM -> SIGKILL grace per stop
  std::vector<ServiceSpec> services;  ///< at least one, names unique
};

/// The default profile: deploy/local.yaml (relative to the working directory or CELL_HOME).
std::string default_profile_path();

/// Reads `path` strictly (unknown keys are errors) and validates it. Errors (kConfig) name
/// "file:line:col: key 'a.b': what", one per line, every problem at once: wrong types,
/// unknown keys, a missing or empty `services` list, duplicate or malformed service names,
/// negative or inconsistent durations, a domain id outside 0..230.
Result<Profile> load_profile(const std::string& path);

/// Environment overrides of the bus section: CELL_DOMAIN_ID (0..230) and CELL_PARTITION.
/// Errors: kConfig naming the variable and its value.
Status apply_environment(Profile& profile);

/// CELL_HOME (service::cell_home()) as an absolute path.
std::string home_dir();

/// `path` made absolute against CELL_HOME (service::cell_home()); absolute paths unchanged.
std::string home_path(const std::string& path);

/// Absolute run directory of the profile.
std::string run_dir_of(const Profile& profile);

/// True when `host` means this machine: "local", "localhost" or this host's name.
bool is_local_host(const std::string& host);

/// This machine's hostname.
std::string this_host();

}  // namespace cell::launcher
