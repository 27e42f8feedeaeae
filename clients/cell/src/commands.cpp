#include "commands.hpp"

#include <fcntl.h>
#include <sys/signalfd.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <map>
#include <optional>
#include <set>

#include <fmt/format.h>
#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "cell/bus/entity.hpp"
#include "cell/bus/participant.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/common/version.hpp"
#include "cell/service/directory.hpp"
#include "deploy_gen.hpp"
#include "profile.hpp"
#include "run_dir.hpp"
#include "supervisor.hpp"

namespace cell::launcher {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

/// Prints a (possibly multi-line) error, each line prefixed "cell: ".
void print_error(std::string_view message) {
  while (!message.empty()) {
    const auto nl = message.find('\n');
    std::cerr << "cell: " << message.substr(0, nl) << "\n";
    if (nl == std::string_view::npos) {
      break;
    }
    message.remove_prefix(nl + 1);
  }
}

/// The profile named on the command line (or the default) with environment overrides.
/// `--run-dir` wins over the profile's run_dir (relative to the working directory).
Result<Profile> load(const std::string& option, const std::string& run_dir = {}) {
  const std::string path = option.empty() ? default_profile_path() : option;
  auto profile = load_profile(path);
  if (!profile) {
    return profile;
  }
  CELL_TRY(apply_environment(*profile));
  if (!run_dir.empty()) {
    std::error_code ec;
    profile->run_dir = fs::absolute(run_dir, ec).lexically_normal().string();
  }
  return profile;
}

std::string self_dir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string() : exe.parent_path().string();
}

/// "--profile <path>" when a non-default profile is in use, for the hints we print.
std::string profile_hint(const Profile& profile) {
  std::error_code ec;
  if (fs::equivalent(profile.path, default_profile_path(), ec)) {
    return "";
  }
  return " --profile " + profile.path;
}

std::string banner(const LaunchPlan& plan, pid_t pid, bool detached) {
  std::string hint = profile_hint(plan.profile);
  if (!plan.host.empty()) {
    hint += " --host " + plan.host + " --run-dir " + plan.paths.dir;
  }
  std::string text = fmt::format(
      "cell: supervisor pid {} runs {} service(s) of profile '{}' ({}){}\n"
      "  bus:    domain {}, partition '{}'\n"
      "  logs:   {}/<service>.log{}\n"
      "  status: {}/status.json\n"
      "  check:  cell status{}   |   cellctl ping --domain {} --partition {}\n"
      "  stop:   cell down{}{}\n"
      "{}",
      pid, plan.services.size(), plan.profile.name, plan.profile.path,
      detached ? " in the background" : "", plan.profile.bus.domain_id, plan.profile.bus.partition,
      plan.paths.logs, detached ? fmt::format(" (supervisor: {})", plan.paths.supervisor_log) : "",
      plan.paths.dir, hint, plan.profile.bus.domain_id, plan.profile.bus.partition, hint,
      detached ? "" : "   (or Ctrl-C)",
      plan.host.empty() ? ""
                        : fmt::format("  host:   '{}' of the profile, DDS configuration {}\n",
                                      plan.host, plan.dds_config));
  for (const auto& other : plan.not_here) {
    text += fmt::format("  not started on this host: {}\n", other);
  }
  return text;
}

sigset_t supervisor_signals() {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGCHLD);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  sigaddset(&set, SIGHUP);
  return set;
}

/// Takes the run directory and supervises; returns the exit code.
int supervise_here(const LaunchPlan& plan, int ready_fd) {
  auto lock = PidFileLock::acquire(plan.paths.pid_file);
  if (!lock) {
    if (ready_fd >= 0) {
      const std::string message = "E" + lock.error().message;
      (void)!::write(ready_fd, message.data(), message.size());
      close(ready_fd);
    }
    print_error(lock.error().message);
    return kExitFailure;
  }
  const sigset_t set = supervisor_signals();
  const int signal_fd = signalfd(-1, &set, SFD_NONBLOCK | SFD_CLOEXEC);
  if (signal_fd < 0) {
    const std::string message = fmt::format("signalfd: {}", std::strerror(errno));
    if (ready_fd >= 0) {
      (void)!::write(ready_fd, ("E" + message).data(), message.size() + 1);
      close(ready_fd);
    }
    print_error(message);
    return kExitFailure;
  }
  std::cout << banner(plan, getpid(), ready_fd >= 0) << std::flush;
  if (ready_fd >= 0) {
    const std::string ok = fmt::format("OK{}", getpid());
    (void)!::write(ready_fd, ok.data(), ok.size());
    close(ready_fd);
  }
  const int rc = supervise(plan, signal_fd);
  close(signal_fd);
  lock->release();
  return rc;
}

/// Forks a session leader that supervises with its output in logs/cell.log; returns once it
/// holds the pid file (or failed to).
int detach_and_supervise(const LaunchPlan& plan) {
  int ready[2];
  if (pipe2(ready, O_CLOEXEC) != 0) {
    print_error(fmt::format("pipe: {}", std::strerror(errno)));
    return kExitFailure;
  }
  const pid_t pid = fork();
  if (pid < 0) {
    print_error(fmt::format("fork: {}", std::strerror(errno)));
    return kExitFailure;
  }
  if (pid == 0) {
    close(ready[0]);
    setsid();
    const int null_fd = open("/dev/null", O_RDONLY | O_CLOEXEC);
    const int log_fd =
        open(plan.paths.supervisor_log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (null_fd >= 0) {
      dup2(null_fd, STDIN_FILENO);
    }
    if (log_fd >= 0) {
      dup2(log_fd, STDOUT_FILENO);
      dup2(log_fd, STDERR_FILENO);
    }
    if (chdir(plan.paths.dir.c_str()) != 0) {
      // Not fatal: every path is absolute already.
    }
    std::exit(supervise_here(plan, ready[1]));
  }
  close(ready[1]);
  std::string answer;
  char buf[512];
  for (;;) {
    const ssize_t n = ::read(ready[0], buf, sizeof buf);
    if (n > 0) {
      answer.append(buf, static_cast<std::size_t>(n));
      continue;
    }
    if (n < 0 && errno == EINTR) {
      continue;
    }
    break;
  }
  close(ready[0]);
  if (answer.starts_with("OK")) {
    const pid_t daemon = static_cast<pid_t>(std::strtol(answer.c_str() + 2, nullptr, 10));
    std::cout << banner(plan, daemon, true) << std::flush;
    return kExitOk;
  }
  int status = 0;
  waitpid(pid, &status, 0);
  print_error(answer.size() > 1 ? answer.substr(1)
                                : fmt::format("the background supervisor exited early; see {}",
                                              plan.paths.supervisor_log));
  return kExitFailure;
}

/// A service process recorded in status.json.
struct Recorded {
  std::string name;
  pid_t pid = 0;
  std::string exec;
};

/// Live processes recorded in status.json that still run their recorded executable.
std::vector<Recorded> recorded_children(const RunPaths& paths) {
  std::vector<Recorded> out;
  auto status = read_status(paths.status_file);
  if (!status) {
    return out;
  }
  for (const auto& s : status->services) {
    if (s.pid > 0 && process_is(s.pid, s.exec)) {
      out.push_back(Recorded{s.name, s.pid, s.exec});
    }
  }
  return out;
}

/// SIGKILLs each recorded child (its process group) that still runs its executable; returns
/// their names.
std::vector<std::string> kill_children(const std::vector<Recorded>& kids) {
  std::vector<std::string> killed;
  for (const auto& kid : kids) {
    if (process_is(kid.pid, kid.exec)) {
      if (kill(-kid.pid, SIGKILL) != 0) {
        kill(kid.pid, SIGKILL);
      }
      (void)wait_process_exit(kid.pid, 2000);
      killed.push_back(fmt::format("{} (pid {})", kid.name, kid.pid));
    }
  }
  return killed;
}

std::string join(const std::vector<std::string>& items) {
  std::string out;
  for (const auto& item : items) {
    out += (out.empty() ? "" : ", ") + item;
  }
  return out;
}

/// Prints rows as left-aligned columns.
void print_table(std::ostream& out, const std::vector<std::vector<std::string>>& rows) {
  std::vector<std::size_t> width;
  for (const auto& row : rows) {
    width.resize(std::max(width.size(), row.size()), 0);
    for (std::size_t i = 0; i < row.size(); ++i) {
      width[i] = std::max(width[i], row[i].size());
    }
  }
  for (const auto& row : rows) {
    std::string line;
    for (std::size_t i = 0; i < row.size(); ++i) {
      line += row[i];
      if (i + 1 < row.size()) {
        line += std::string(width[i] - row[i].size() + 2, ' ');
      }
    }
    while (!line.empty() && line.back() == ' ') {
      line.pop_back();
    }
    out << line << "\n";
  }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
int run_up(const UpOptions& options) {
  // Before anything else (no thread exists in `cell up`): the supervisor takes these through a
  // signalfd; children get a clean mask from process::Child. SIGPIPE stays blocked so a closed
  // terminal turns into EPIPE instead of killing the supervisor.
  sigset_t set = supervisor_signals();
  sigaddset(&set, SIGPIPE);
  sigprocmask(SIG_BLOCK, &set, nullptr);
  log::init("cell");

  auto profile = load(options.profile, options.run_dir);
  if (!profile) {
    print_error(profile.error().message);
    return kExitUsage;
  }
  const auto host = select_host(*profile, options.host);
  if (!host) {
    print_error(host.error().message);
    return kExitUsage;
  }
  auto plan = make_plan(*profile, options.only, self_dir(), *host);
  if (!plan) {
    print_error(plan.error().message);
    return kExitUsage;
  }
  if (auto made = make_run_dirs(plan->paths); !made) {
    print_error(made.error().message);
    return kExitFailure;
  }
  if (const auto owner = live_supervisor(plan->paths.pid_file)) {
    print_error(
        fmt::format("a supervisor (pid {}) already owns run directory '{}'; stop it "
                    "first with `cell down{}`",
                    *owner, plan->paths.dir, profile_hint(*profile)));
    return kExitFailure;
  }
  if (auto written = write_dds_config(*plan); !written) {
    print_error(written.error().message);
    return kExitFailure;
  }
  if (options.detach) {
    return detach_and_supervise(*plan);
  }
  return supervise_here(*plan, -1);
}

int run_down(const DownOptions& options) {
  log::init("cell");
  auto profile = load(options.profile, options.run_dir);
  if (!profile) {
    print_error(profile.error().message);
    return kExitUsage;
  }
  const RunPaths paths = RunPaths::of(run_dir_of(*profile));
  const auto children = recorded_children(paths);
  const auto supervisor = live_supervisor(paths.pid_file);
  if (!supervisor) {
    std::error_code ec;
    fs::remove(paths.pid_file, ec);  // stale, if any
    const auto strays = kill_children(children);
    if (strays.empty()) {
      std::cout << fmt::format("cell: nothing to stop: no supervisor owns '{}'\n", paths.dir);
    } else {
      std::cout << fmt::format("cell: no supervisor owns '{}'; killed stray services: {}\n",
                               paths.dir, join(strays));
    }
    return kExitOk;
  }
  const auto t0 = std::chrono::steady_clock::now();
  std::cout << fmt::format("cell: stopping supervisor pid {} ({}) ...\n", *supervisor, paths.dir)
            << std::flush;
  if (kill(*supervisor, SIGTERM) != 0 && errno != ESRCH) {
    print_error(
        fmt::format("cannot signal supervisor pid {}: {}", *supervisor, std::strerror(errno)));
    return kExitFailure;
  }
  const int timeout_ms = static_cast<int>(std::lround(options.timeout_s * 1000.0));
  bool forced = false;
  if (!wait_process_exit(*supervisor, timeout_ms)) {
    forced = true;
    print_error(
        fmt::format("supervisor pid {} did not stop within {} s: killing it and its "
                    "services",
                    *supervisor, options.timeout_s));
    kill(*supervisor, SIGKILL);
    (void)wait_process_exit(*supervisor, 5000);
  }
  const auto left = kill_children(children);
  if (forced) {
    std::error_code ec;
    fs::remove(paths.pid_file, ec);
  }
  const double took_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (process_running(*supervisor)) {
    print_error(fmt::format("supervisor pid {} is still running", *supervisor));
    return kExitFailure;
  }
  if (!left.empty()) {
    print_error(fmt::format("services outlived the supervisor and were killed: {}", join(left)));
  }
  std::cout << fmt::format("cell: stopped in {:.2f} s (supervisor pid {}, {} service(s)){}\n",
                           took_s, *supervisor, children.size(), forced ? " by force" : "");
  return forced || !left.empty() ? kExitFailure : kExitOk;
}

int run_status(const StatusOptions& options) {
  log::init("cell", log::Level::kWarn);
  auto profile = load(options.profile, options.run_dir);
  if (!profile) {
    print_error(profile.error().message);
    return kExitUsage;
  }
  const RunPaths paths = RunPaths::of(run_dir_of(*profile));
  const auto supervisor = live_supervisor(paths.pid_file);
  std::optional<StatusFile> launched;
  if (auto s = read_status(paths.status_file);
      s && supervisor && s->supervisor_pid == *supervisor) {
    launched = std::move(*s);
  }

  // The services were given the profile's Cyclone configuration: look with the same eyes.
  const auto host = select_host(*profile, options.host);
  if (!host) {
    print_error(host.error().message);
    return kExitUsage;
  }
  std::string uri;
  if (host->empty()) {
    const std::string dds_config = home_path(profile->bus.cyclonedds_config);
    if (access(dds_config.c_str(), R_OK) != 0) {
      print_error(fmt::format("{}: key 'bus.cyclonedds_config': cannot read '{}': {}",
                              profile->path, dds_config, std::strerror(errno)));
      return kExitUsage;
    }
    uri = "file://" + dds_config;
  } else {
    const std::string dds_config = paths.dir + "/dds/" + *host + ".status.xml";
    if (auto w = write_file_atomically(dds_config, host_dds_config(*profile, *host)); !w) {
      print_error(w.error().message);
      return kExitFailure;
    }
    uri = "file://" + dds_config;
  }
  if (profile->security.enabled) {
    const std::string identity = home_path(profile->security.dir) + "/" + options.identity + ".xml";
    if (access(identity.c_str(), R_OK) != 0) {
      print_error(fmt::format("security is enabled in {} but identity '{}' cannot be read: {}",
                              profile->path, identity, std::strerror(errno)));
      return kExitUsage;
    }
    uri += ",file://" + identity;
  }
  setenv("CYCLONEDDS_URI", uri.c_str(), 1);

  std::set<std::string> expected;
  for (const auto& spec : profile->services) {
    expected.insert(spec.name);
  }
  std::vector<service::ServiceEntry> seen;
  try {
    bus::Participant participant(profile->bus.domain_id, profile->bus.partition);
    service::ServiceDirectory directory(participant, "cell-status");
    auto snap = directory.wait_settled(
        std::chrono::milliseconds(std::lround(options.timeout_s * 1000.0)), expected);
    if (!snap) {
      print_error(snap.error().message);
      return kExitFailure;
    }
    seen = std::move(*snap);
  } catch (const bus::BusError& e) {
    print_error(fmt::format("cannot join the bus (domain {}, partition '{}'): {}",
                            profile->bus.domain_id, profile->bus.partition, e.what()));
    return kExitFailure;
  }

  std::map<std::string, const service::ServiceEntry*> by_id;
  for (const auto& entry : seen) {
    by_id[entry.service_id] = &entry;
  }
  json rows = json::array();
  std::vector<std::vector<std::string>> table{
      {"NAME", "HOST", "PID", "STATE", "UPTIME", "RESTARTS", "DETAIL"}};
  bool all_serving = true;
  for (const auto& spec : profile->services) {
    const auto it = by_id.find(spec.name);
    const service::ServiceEntry* entry = it != by_id.end() ? it->second : nullptr;
    const ServiceStatus* local = launched ? launched->find(spec.name) : nullptr;
    const std::string state = entry != nullptr ? std::string(entry->status()) : "missing";
    all_serving = all_serving && state == "serving";
    std::string detail = entry != nullptr ? entry->detail : "";
    if (entry == nullptr || entry->lost) {
      std::string why;
      if (local != nullptr) {
        why = "launcher: " + local->state;
        if (!local->last_exit.empty()) {
          why += ", last " + local->last_exit;
        }
        if (!local->reason.empty()) {
          why += ": " + local->reason;
        }
      } else if (runs_on(spec, *host)) {
        why = supervisor ? "not started by the supervisor" : "supervisor not running";
      } else {
        why = "no heartbeat from host " + spec.host;
      }
      if (!detail.empty()) {
        detail += "; ";
      }
      detail += why;
    }
    const std::string where = entry != nullptr           ? entry->host
                              : is_local_host(spec.host) ? this_host()
                                                         : spec.host;
    const pid_t pid = entry != nullptr ? entry->pid : (local != nullptr ? local->pid : 0);
    table.push_back({spec.name, where, pid > 0 ? std::to_string(pid) : "-", state,
                     entry != nullptr ? format_duration(entry->uptime_s) : "-",
                     local != nullptr ? std::to_string(local->restarts) : "-", detail});
    json row{{"name", spec.name}, {"host", where},    {"pid", pid},
             {"state", state},    {"detail", detail}, {"in_profile", true}};
    row["uptime_s"] = entry != nullptr ? json(entry->uptime_s) : json(nullptr);
    row["restarts"] = local != nullptr ? json(local->restarts) : json(nullptr);
    row["launcher_state"] = local != nullptr ? json(local->state) : json(nullptr);
    row["last_exit"] = local != nullptr ? json(local->last_exit) : json(nullptr);
    rows.push_back(std::move(row));
  }
  for (const auto& entry : seen) {
    if (expected.count(entry.service_id) > 0) {
      continue;
    }
    const std::string detail =
        entry.detail.empty() ? "not in the profile" : entry.detail + "; not in the profile";
    table.push_back({entry.service_id, entry.host, std::to_string(entry.pid),
                     std::string(entry.status()), format_duration(entry.uptime_s), "-", detail});
    rows.push_back(json{{"name", entry.service_id},
                        {"host", entry.host},
                        {"pid", entry.pid},
                        {"state", std::string(entry.status())},
                        {"detail", entry.detail},
                        {"in_profile", false},
                        {"uptime_s", entry.uptime_s},
                        {"restarts", nullptr},
                        {"launcher_state", nullptr},
                        {"last_exit", nullptr}});
  }

  if (options.json) {
    json doc{{"profile", profile->name},
             {"profile_path", profile->path},
             {"run_dir", paths.dir},
             {"domain", profile->bus.domain_id},
             {"partition", profile->bus.partition},
             {"supervisor", {{"running", supervisor.has_value()}, {"pid", supervisor.value_or(0)}}},
             {"all_serving", all_serving},
             {"services", rows}};
    std::cout << doc.dump(2) << "\n";
  } else {
    std::cout << fmt::format("cell '{}': {}; domain {}, partition '{}'\n", profile->name,
                             supervisor
                                 ? fmt::format("supervisor pid {} ({})", *supervisor, paths.dir)
                                 : fmt::format("no supervisor running ({})", paths.dir),
                             profile->bus.domain_id, profile->bus.partition);
    print_table(std::cout, table);
    if (!all_serving) {
      std::cout << "cell: not every service is serving\n";
    }
  }
  return all_serving ? kExitOk : kExitFailure;
}

namespace {

/// The plan of one host of a multi-host profile, for the generators.
Result<LaunchPlan> host_plan(const GenerateOptions& options) {
  auto profile = load(options.profile, options.run_dir);
  if (!profile) {
    return std::move(profile).error();
  }
  auto host = select_host(*profile, options.host);
  if (!host) {
    return std::move(host).error();
  }
  if (host->empty()) {
    return Error{Errc::kConfig,
                 fmt::format("{}: has no `hosts:` section: its services use {} as it is",
                             profile->path, profile->bus.cyclonedds_config)};
  }
  return make_plan(*profile, {}, self_dir(), *host);
}

}  // namespace

int run_dds_config(const GenerateOptions& options) {
  log::init("cell", log::Level::kWarn);
  auto plan = host_plan(options);
  if (!plan) {
    print_error(plan.error().message);
    return kExitUsage;
  }
  std::cout << plan->dds_config_text;
  return kExitOk;
}

int run_systemd(const GenerateOptions& options) {
  log::init("cell", log::Level::kWarn);
  auto plan = host_plan(options);
  if (!plan) {
    print_error(plan.error().message);
    return kExitUsage;
  }
  const std::string out = options.install ? "/etc/systemd/system" : options.out;
  if (out.empty()) {
    print_error("cell systemd: say where the units go: --out DIR, or --install");
    return kExitUsage;
  }
  // The units point at <run_dir>/dds/<host>.xml and run in <run_dir>: make both now.
  if (auto made = make_run_dirs(plan->paths); !made) {
    print_error(made.error().message);
    return kExitFailure;
  }
  if (auto written = write_dds_config(*plan); !written) {
    print_error(written.error().message);
    return kExitFailure;
  }
  std::string target;
  for (const auto& file : systemd_units(*plan)) {
    const std::string path = out + "/" + file.name;
    if (auto w = write_file_atomically(path, file.text); !w) {
      print_error(w.error().message);
      return kExitFailure;
    }
    std::cout << "cell: wrote " << path << "\n";
    if (file.name.ends_with(".target")) {
      target = file.name;
    }
  }
  std::cout << "cell: wrote " << plan->dds_config << " (the DDS configuration of host '"
            << plan->host << "')\n";
  if (!options.install) {
    std::cout << fmt::format(
        "cell: install with `cell systemd --install{} --host {}`, then `systemctl enable --now "
        "{}`\n",
        profile_hint(plan->profile), plan->host, target);
    return kExitOk;
  }
  if (access("/run/systemd/system", F_OK) != 0) {
    std::cout << "cell: systemd is not running on this machine: run `systemctl daemon-reload` "
                 "and `systemctl enable --now "
              << target << "` once it is\n";
    return kExitOk;
  }
  const int rc = std::system("systemctl daemon-reload");
  if (rc != 0) {
    print_error(fmt::format("`systemctl daemon-reload` failed (status {})", rc));
    return kExitFailure;
  }
  std::cout << "cell: systemd reloaded; start with `systemctl enable --now " << target << "`\n";
  return kExitOk;
}

int main_cli(int argc, char** argv) {
  CLI::App app("cell: start, supervise and stop the services of a workcell", "cell");
  app.set_version_flag("--version",
                       fmt::format("cell {} (Cyclone DDS {})", version(), dds_version()));
  app.require_subcommand(1);
  app.footer(
      "Profiles: deploy/local.yaml by default (deploy/README.md documents the schema); relative "
      "paths\nresolve against CELL_HOME. CELL_DOMAIN_ID and CELL_PARTITION override the "
      "profile's bus section.\nExit codes: 0 ok, 1 failure (or not every service serving), 2 "
      "usage or profile error.");

  UpOptions up;
  auto* up_cmd = app.add_subcommand("up", "start the profile's services and supervise them");
  up_cmd->add_option("-p,--profile", up.profile, "profile YAML (default deploy/local.yaml)");
  up_cmd->add_flag("-d,--detach", up.detach,
                   "run in the background (output in <run_dir>/logs/cell.log)");
  up_cmd->add_option("--only", up.only, "start only this service (repeatable)");
  up_cmd->add_option("--host", up.host,
                     "which host of a multi-host profile this machine is (default: the host "
                     "named like this machine)");
  up_cmd->add_option("--run-dir", up.run_dir, "run directory (default: the profile's run_dir)");

  DownOptions down;
  auto* down_cmd = app.add_subcommand("down", "stop the supervisor and every service");
  down_cmd->add_option("-p,--profile", down.profile, "profile YAML (default deploy/local.yaml)");
  down_cmd->add_option("--timeout", down.timeout_s, "seconds to wait before killing, default 30")
      ->check(CLI::PositiveNumber);
  down_cmd->add_option("--run-dir", down.run_dir, "run directory (default: the profile's)");

  StatusOptions status;
  auto* status_cmd = app.add_subcommand("status", "show every service of the profile");
  status_cmd->add_option("-p,--profile", status.profile,
                         "profile YAML (default deploy/local.yaml)");
  status_cmd->add_flag("--json", status.json, "print JSON");
  status_cmd->add_option("--timeout", status.timeout_s, "seconds of bus discovery, default 2")
      ->check(CLI::PositiveNumber);
  status_cmd->add_option("--host", status.host, "look from this host of a multi-host profile");
  status_cmd->add_option("--run-dir", status.run_dir, "run directory (default: the profile's)");
  status_cmd->add_option("--identity", status.identity,
                         "DDS identity when the profile's security is on (default viewer)");

  GenerateOptions gen;
  auto* dds_cmd =
      app.add_subcommand("dds-config", "print the Cyclone DDS configuration of a profile host");
  auto* systemd_cmd =
      app.add_subcommand("systemd", "write systemd units for the services of a profile host");
  for (auto* cmd : {dds_cmd, systemd_cmd}) {
    cmd->add_option("-p,--profile", gen.profile, "profile YAML with a `hosts:` section")
        ->required();
    cmd->add_option("--host", gen.host, "the host (default: the one named like this machine)");
    cmd->add_option("--run-dir", gen.run_dir, "run directory (default: the profile's)");
  }
  systemd_cmd->add_option("--out", gen.out, "directory for the unit files");
  systemd_cmd->add_flag("--install", gen.install,
                        "write them to /etc/systemd/system and reload systemd");

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    return rc == 0 ? kExitOk : kExitUsage;
  }
  if (up_cmd->parsed()) {
    return run_up(up);
  }
  if (down_cmd->parsed()) {
    return run_down(down);
  }
  if (dds_cmd->parsed()) {
    return run_dds_config(gen);
  }
  if (systemd_cmd->parsed()) {
    return run_systemd(gen);
  }
  return run_status(status);
}

}  // namespace cell::launcher
