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
  int memory_max_mib = 0;      ///< systemd MemoryMax (`limits.memory_mib`); 0: 2048
  int cpu_quota_percent = 0;   ///< systemd CPUQuota (`limits.cpu_percent`); 0: none
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
  // Used only by profiles with `hosts:` (the Cyclone configuration is generated per host):
  bool multicast = false;            ///< SPDP/data multicast; false: unicast to every host
  double receive_buffer_mib = 8.0;   ///< socket receive buffer asked for (images, bursts)
  bool images_across_hosts = false;  ///< raw images reach hosts without a camera service
};

/// One PC of a multi-host profile (`hosts:` map). Its services say `host: <name>`.
struct HostSpec {
  std::string name;       ///< the key: vision, control, operations, ...
  std::string address;    ///< IPv4 address the cell's DDS traffic uses on that PC
  std::string interface;  ///< optional: the interface name, for the record and the units
  std::string where;      ///< file:line:col, for messages
};

/// DDS Security (deploy/security/README.md): each service joins with its own identity, the
/// Cyclone fragment `<dir>/<service name>.xml` that deploy/security/make-pki.sh writes.
struct SecuritySettings {
  bool enabled = false;
  std::string dir = "run/dds-security";  ///< relative to CELL_HOME
};

/// A parsed and validated profile. Immutable once loaded (apply_environment aside).
struct Profile {
  std::string path;                   ///< absolute path of the profile file
  std::string name;                   ///< `profile:`; defaults to the file's stem
  BusSettings bus;                    ///< `bus:`
  std::string run_dir = "run";        ///< logs/, cell.pid, status.json; relative to CELL_HOME
  RestartPolicy restart;              ///< `restart:`
  double stop_grace_s = 5.0;          ///< SIGTERM -> SIGKILL grace per stop
  std::vector<HostSpec> hosts;        ///< empty: one machine (services' `host` is a hostname)
  SecuritySettings security;          ///< `security:`
  std::vector<ServiceSpec> services;  ///< at least one, names unique

  /// The host named `name`, or nullptr.
  const HostSpec* host(const std::string& name) const;
};

/// The default profile: deploy/local.yaml (relative to the working directory or CELL_HOME).
std::string default_profile_path();

/// Reads `path` strictly (unknown keys are errors) and validates it. Errors (kConfig) name
/// "file:line:col: key 'a.b': what", one per line, every problem at once: wrong types,
/// unknown keys, a missing or empty `services` list, duplicate or malformed service names,
/// negative or inconsistent durations, a domain id outside 0..230.
Result<Profile> load_profile(const std::string& path);

/// Environment overrides: CELL_DOMAIN_ID (0..230), CELL_PARTITION, and per host
/// CELL_HOST_<NAME>_ADDRESS (name upper-cased, '-' and '.' as '_'), e.g.
/// CELL_HOST_CONTROL_ADDRESS=192.168.10.2. Errors: kConfig naming the variable and its value.
Status apply_environment(Profile& profile);

/// CELL_HOME (service::cell_home()) as an absolute path.
std::string home_dir();

/// `path` made absolute against CELL_HOME (service::cell_home()); absolute paths unchanged.
std::string home_path(const std::string& path);

/// Absolute run directory of the profile.
std::string run_dir_of(const Profile& profile);

/// Which host of `profile` this machine is: `requested` (--host) when given, which must name
/// one of its hosts; otherwise, for a profile with hosts, the host whose name is this machine's
/// hostname; for a profile without hosts, empty (every `local` service runs here). Errors
/// (kConfig) list the hosts there are.
Result<std::string> select_host(const Profile& profile, const std::string& requested);

/// True when `spec` runs on `host` (a key of the profile's hosts), or, with `host` empty, on
/// this machine (is_local_host).
bool runs_on(const ServiceSpec& spec, const std::string& host);

/// True when `host` means this machine: "local", "localhost" or this host's name.
bool is_local_host(const std::string& host);

/// This machine's hostname.
std::string this_host();

}  // namespace cell::launcher
