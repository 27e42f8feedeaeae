#include "supervisor.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/signalfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstring>
#include <deque>
#include <filesystem>
#include <optional>
#include <set>

#include <fmt/format.h>

#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "deploy_gen.hpp"

namespace cell::launcher {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

constexpr double kStartupGraceS = 1.0;  // starting -> running after this long alive
constexpr std::size_t kTailLines = 20;  // output lines kept to explain a failure
constexpr std::size_t kHistory = 10;    // exits kept in status.json
constexpr std::size_t kMaxLine = std::size_t{64} * 1024;  // a longer line without '\n' is cut
constexpr int kExitConfig = 2;  // services' usage/config error (service/runtime.hpp)

void write_all(int fd, std::string_view data) noexcept {
  while (!data.empty()) {
    const ssize_t n = ::write(fd, data.data(), data.size());
    if (n < 0 && errno == EINTR) {
      continue;
    }
    if (n <= 0) {
      return;  // stdout gone (EPIPE: SIGPIPE is blocked) or disk full: output is best effort
    }
    data.remove_prefix(static_cast<std::size_t>(n));
  }
}

std::string seconds(double s) { return fmt::format("{:.1f} s", s); }

std::optional<std::string> find_executable(const std::string& exec, const std::string& self_dir) {
  if (exec.find('/') != std::string::npos) {
    const std::string path = home_path(exec);
    return access(path.c_str(), X_OK) == 0 ? std::optional(path) : std::nullopt;
  }
  if (!self_dir.empty()) {
    const std::string local = (fs::path(self_dir) / exec).string();
    if (access(local.c_str(), X_OK) == 0) {
      return local;
    }
  }
  const std::string found = process::which(exec);
  if (found.find('/') != std::string::npos && access(found.c_str(), X_OK) == 0) {
    return fs::absolute(found).string();
  }
  return std::nullopt;
}

enum class State { kStarting, kRunning, kBackoff, kFailed, kStopping, kStopped };

std::string_view name_of(State state) {
  switch (state) {
    case State::kStarting:
      return "starting";
    case State::kRunning:
      return "running";
    case State::kBackoff:
      return "backoff";
    case State::kFailed:
      return "failed";
    case State::kStopping:
      return "stopping";
    case State::kStopped:
      return "stopped";
  }
  return "stopped";
}

/// One supervised service.
struct Slot {
  explicit Slot(const LaunchSpec& s, const RestartPolicy& policy) : spec(&s), backoff(policy) {}

  const LaunchSpec* spec;
  process::Child child;
  State state = State::kStopped;
  Backoff backoff;
  ServiceStatus status;
  Clock::time_point started_at{};
  Clock::time_point next_start{};
  std::string pending;  // output read but not yet ended by '\n'
  std::deque<std::string> tail;
  int log_fd = -1;
};

class Supervisor {
 public:
  Supervisor(const LaunchPlan& plan, int signal_fd) : plan_(plan), signal_fd_(signal_fd) {
    slots_.reserve(plan.services.size());
    for (const auto& spec : plan.services) {
      Slot& slot = slots_.emplace_back(spec, plan.profile.restart);
      slot.status.name = spec.name;
      slot.status.host = spec.host;
      slot.status.exec = spec.executable;
      slot.status.log = spec.log_file;
      slot.log_fd = open(spec.log_file.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
      if (slot.log_fd < 0) {
        log::warn("log", "cannot open the service log; output goes to stdout only",
                  {{"service", spec.name}, {"file", spec.log_file}, {"error", strerror(errno)}});
      }
    }
    status_.profile = plan.profile.name;
    status_.profile_path = plan.profile.path;
    status_.supervisor_pid = getpid();
    status_.state = "running";
    status_.started_ns = wall_time_ns();
    status_.domain_id = plan.profile.bus.domain_id;
    status_.partition = plan.profile.bus.partition;
  }

  ~Supervisor() {
    for (auto& slot : slots_) {
      if (slot.log_fd >= 0) {
        close(slot.log_fd);
      }
    }
  }

  Supervisor(const Supervisor&) = delete;
  Supervisor& operator=(const Supervisor&) = delete;

  int run() {
    for (auto& slot : slots_) {
      start(slot);
    }
    write_status_file();
    while (!(stopping_ && none_running())) {
      wait_and_dispatch();
      handle_timers();
      if (dirty_) {
        write_status_file();
      }
    }
    status_.state = "stopped";
    write_status_file();
    log::info("stopped", "every service stopped; supervisor exiting",
              {{"profile", plan_.profile.name}});
    return 0;
  }

 private:
  bool none_running() const {
    return std::none_of(slots_.begin(), slots_.end(),
                        [](const Slot& s) { return s.child.running(); });
  }

  void set_state(Slot& slot, State state) {
    slot.state = state;
    slot.status.state = std::string(name_of(state));
    dirty_ = true;
  }

  void start(Slot& slot) {
    process::SpawnOptions options;
    options.executable = slot.spec->executable;
    options.args = slot.spec->args;
    options.env = slot.spec->env;
    options.working_dir = plan_.paths.dir;
    options.capture_output = true;
    options.new_process_group = true;
    options.die_with_parent = true;
    slot.pending.clear();
    slot.tail.clear();
    auto child = process::Child::spawn(options);
    if (!child) {
      // The plan found the executable, so this is transient (a rebuild replacing the binary,
      // fork failing under memory pressure): retry with back-off rather than give up.
      slot.status.pid = 0;
      slot.status.reason = child.error().message;
      schedule_restart(slot, "cannot start: " + child.error().message, 0.0);
      return;
    }
    slot.child = std::move(*child);
    slot.started_at = Clock::now();
    slot.status.pid = slot.child.pid();
    slot.status.started_ns = wall_time_ns();
    slot.status.next_start_ns = 0;
    slot.status.reason.clear();
    slot.status.last_lines.clear();
    set_state(slot, State::kStarting);
    log::info("start", "started",
              {{"service", slot.spec->name},
               {"pid", std::to_string(slot.child.pid())},
               {"restarts", std::to_string(slot.status.restarts)}});
  }

  /// Relays whatever the child printed; `final` flushes an unterminated last line.
  void relay_output(Slot& slot, bool final) {
    if (slot.child.output_fd() >= 0) {
      (void)slot.child.read_available(slot.pending);
    }
    std::size_t begin = 0;
    for (;;) {
      const std::size_t nl = slot.pending.find('\n', begin);
      if (nl == std::string::npos) {
        break;
      }
      emit_line(slot, std::string_view(slot.pending).substr(begin, nl - begin));
      begin = nl + 1;
    }
    slot.pending.erase(0, begin);
    if (slot.pending.size() >= kMaxLine || (final && !slot.pending.empty())) {
      emit_line(slot, slot.pending);
      slot.pending.clear();
    }
  }

  void emit_line(Slot& slot, std::string_view line) {
    if (!line.empty() && line.back() == '\r') {
      line.remove_suffix(1);
    }
    std::string prefixed;
    prefixed.reserve(line.size() + slot.spec->name.size() + 4);
    prefixed.append("[").append(slot.spec->name).append("] ").append(line).append("\n");
    write_all(STDOUT_FILENO, prefixed);
    if (slot.log_fd >= 0) {
      std::string raw(line);
      raw += '\n';
      write_all(slot.log_fd, raw);
    }
    slot.tail.emplace_back(line);
    if (slot.tail.size() > kTailLines) {
      slot.tail.pop_front();
    }
  }

  void wait_and_dispatch() {
    std::vector<pollfd> fds;
    std::vector<Slot*> owners;
    fds.push_back(pollfd{signal_fd_, POLLIN, 0});
    owners.push_back(nullptr);
    for (auto& slot : slots_) {
      if (slot.child.output_fd() >= 0) {
        fds.push_back(pollfd{slot.child.output_fd(), POLLIN, 0});
        owners.push_back(&slot);
      }
    }
    const int rc = ::poll(fds.data(), fds.size(), timeout_ms());
    if (rc < 0) {
      if (errno != EINTR) {
        log::error("poll", strerror(errno));
      }
      return;
    }
    for (std::size_t i = 1; i < fds.size(); ++i) {
      if (fds[i].revents != 0) {
        relay_output(*owners[i], false);
      }
    }
    if (fds[0].revents & POLLIN) {
      handle_signals();
    }
  }

  void handle_signals() {
    bool child_event = false;
    for (;;) {
      signalfd_siginfo info{};
      const ssize_t n = ::read(signal_fd_, &info, sizeof info);
      if (n != static_cast<ssize_t>(sizeof info)) {
        break;  // EAGAIN: drained
      }
      if (info.ssi_signo == SIGCHLD) {
        child_event = true;
      } else {
        const int sig = static_cast<int>(info.ssi_signo);
        if (stopping_) {
          log::warn("signal", "second stop signal: killing every service now",
                    {{"signal", strsignal(sig)}});
          kill_remaining();
        } else {
          begin_stop(strsignal(sig));
        }
      }
    }
    if (child_event) {
      reap();  // SIGCHLDs coalesce: look at every child
    }
  }

  void reap() {
    for (auto& slot : slots_) {
      if (!slot.child.running()) {
        continue;
      }
      if (auto info = slot.child.poll()) {
        on_exit(slot, *info);
      }
    }
  }

  void on_exit(Slot& slot, const process::ExitInfo& info) {
    relay_output(slot, true);
    slot.child = process::Child();  // closes the pipe (a grandchild may still hold it)
    const double ran_s = std::chrono::duration<double>(Clock::now() - slot.started_at).count();
    const std::string how = describe_exit(info);
    slot.status.pid = 0;
    slot.status.last_exit = how;
    ExitRecord record{wall_time_ns(), how, ran_s, 0.0};
    const std::string& name = slot.spec->name;

    if (stopping_ || slot.state == State::kStopping) {
      set_state(slot, State::kStopped);
      log::info("stopped", "service stopped", {{"service", name}, {"exit", how}});
    } else if (info.exited && info.code == kExitConfig) {
      slot.status.reason =
          "usage or configuration error (exit 2): fix its config, then run "
          "`cell down` and `cell up` again";
      slot.status.last_lines.assign(slot.tail.begin(), slot.tail.end());
      set_state(slot, State::kFailed);
      log::error("failed", "configuration or usage error; not restarting it",
                 {{"service", name},
                  {"exit", how},
                  {"ran_s", fmt::format("{:.1f}", ran_s)},
                  {"log", slot.spec->log_file}});
      std::string report =
          fmt::format("cell: service '{}' failed ({}); its last lines:\n", name, how);
      for (const auto& line : slot.tail) {
        report += fmt::format("    {}\n", line);
      }
      write_all(STDERR_FILENO, report);
    } else {
      schedule_restart(slot, how, ran_s);
      return;
    }
    add_history(slot, record);
  }

  /// Puts `slot` in back-off after an unexpected end (`how`) of a run of `ran_s`.
  void schedule_restart(Slot& slot, const std::string& how, double ran_s) {
    const double delay_s = slot.backoff.next_delay_s(ran_s);
    slot.next_start = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                         std::chrono::duration<double>(delay_s));
    slot.status.last_exit = how;
    slot.status.backoff_s = delay_s;
    slot.status.next_start_ns =
        wall_time_ns() + static_cast<std::int64_t>(std::llround(delay_s * 1e9));
    set_state(slot, State::kBackoff);
    log::warn("exit",
              fmt::format("exited unexpectedly: {} after {}; restart #{} in {:.2f} s", how,
                          seconds(ran_s), slot.status.restarts + 1, delay_s),
              {{"service", slot.spec->name}, {"exit", how}});
    add_history(slot, ExitRecord{wall_time_ns(), how, ran_s, delay_s});
  }

  void add_history(Slot& slot, const ExitRecord& record) {
    slot.status.history.push_back(record);
    if (slot.status.history.size() > kHistory) {
      slot.status.history.erase(slot.status.history.begin());
    }
    dirty_ = true;
  }

  void begin_stop(std::string_view why) {
    stopping_ = true;
    status_.state = "stopping";
    dirty_ = true;
    stop_deadline_ = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(plan_.profile.stop_grace_s));
    log::info("stopping", "stopping every service",
              {{"reason", why}, {"grace_s", fmt::format("{}", plan_.profile.stop_grace_s)}});
    for (auto& slot : slots_) {
      if (slot.child.running()) {
        slot.child.signal(SIGTERM);
        set_state(slot, State::kStopping);
      } else if (slot.state == State::kBackoff) {
        slot.status.next_start_ns = 0;
        set_state(slot, State::kStopped);
      }
    }
  }

  void kill_remaining() {
    for (auto& slot : slots_) {
      if (!slot.child.running()) {
        continue;
      }
      log::warn("kill", "did not stop in time: SIGKILL", {{"service", slot.spec->name}});
      slot.child.signal(SIGKILL);
      const process::ExitInfo info = slot.child.stop(std::chrono::milliseconds(0));  // reaps
      on_exit(slot, info);
    }
  }

  int timeout_ms() const {
    std::optional<Clock::time_point> next;
    auto consider = [&](Clock::time_point t) {
      if (!next || t < *next) {
        next = t;
      }
    };
    for (const auto& slot : slots_) {
      if (slot.state == State::kBackoff && !stopping_) {
        consider(slot.next_start);
      } else if (slot.state == State::kStarting) {
        consider(slot.started_at + std::chrono::duration_cast<Clock::duration>(
                                       std::chrono::duration<double>(kStartupGraceS)));
      }
    }
    if (stopping_) {
      consider(stop_deadline_);
    }
    if (!next) {
      return -1;  // nothing timed: sleep until a signal or output
    }
    const auto left = std::chrono::ceil<std::chrono::milliseconds>(*next - Clock::now());
    return static_cast<int>(std::clamp<std::int64_t>(left.count(), 0, 60'000));
  }

  void handle_timers() {
    const auto now = Clock::now();
    if (stopping_) {
      if (now >= stop_deadline_ && !none_running()) {
        kill_remaining();
      }
      return;
    }
    for (auto& slot : slots_) {
      if (slot.state == State::kBackoff && now >= slot.next_start) {
        ++slot.status.restarts;
        start(slot);
      } else if (slot.state == State::kStarting &&
                 now - slot.started_at >= std::chrono::duration<double>(kStartupGraceS)) {
        set_state(slot, State::kRunning);
      }
    }
  }

  void write_status_file() {
    status_.updated_ns = wall_time_ns();
    status_.services.clear();
    for (const auto& slot : slots_) {
      status_.services.push_back(slot.status);
    }
    if (auto s = write_status(plan_.paths.status_file, status_); !s) {
      log::warn("status", s.error().message);
    }
    dirty_ = false;
  }

  const LaunchPlan& plan_;
  int signal_fd_;
  std::vector<Slot> slots_;
  StatusFile status_;
  bool stopping_ = false;
  bool dirty_ = false;
  Clock::time_point stop_deadline_{};
};

}  // namespace

Backoff::Backoff(const RestartPolicy& policy) noexcept
    : policy_(policy), current_s_(policy.backoff_initial_s) {}

double Backoff::next_delay_s(double ran_s) noexcept {
  if (ran_s >= policy_.stable_after_s) {
    current_s_ = policy_.backoff_initial_s;
  }
  const double delay = current_s_;
  current_s_ = std::min(current_s_ * 2.0, policy_.backoff_max_s);
  return delay;
}

std::string describe_exit(const process::ExitInfo& info) {
  if (info.exited) {
    return fmt::format("exit {}", info.code);
  }
  const char* name = strsignal(info.signal);
  return fmt::format("exit {} (signal {}: {})", 128 + info.signal, info.signal,
                     name != nullptr ? name : "unknown");
}

Result<LaunchPlan> make_plan(const Profile& profile,
                             const std::vector<std::string>& only,
                             const std::string& self_dir,
                             const std::string& host) {
  LaunchPlan plan;
  plan.profile = profile;
  plan.paths = RunPaths::of(run_dir_of(profile));

  std::vector<std::string> errors;
  std::set<std::string> names;
  for (const auto& spec : profile.services) {
    names.insert(spec.name);
  }
  for (const auto& name : only) {
    if (names.count(name) == 0) {
      std::string known;
      for (const auto& n : names) {
        known += (known.empty() ? "" : ", ") + n;
      }
      errors.push_back(fmt::format("{}: --only {}: no such service in the profile (it has: {})",
                                   profile.path, name, known));
    }
  }

  plan.host = host;
  if (host.empty()) {
    plan.dds_config = home_path(profile.bus.cyclonedds_config);
    if (access(plan.dds_config.c_str(), R_OK) != 0) {
      errors.push_back(fmt::format("{}: key 'bus.cyclonedds_config': cannot read '{}': {}",
                                   profile.path, plan.dds_config, strerror(errno)));
    }
  } else {
    plan.dds_config = plan.paths.dir + "/dds/" + host + ".xml";
    plan.dds_config_text = host_dds_config(profile, host);
  }
  plan.cyclonedds_uri = "file://" + plan.dds_config;
  const std::string security_dir = home_path(profile.security.dir);

  for (const auto& spec : profile.services) {
    if (!only.empty() && std::find(only.begin(), only.end(), spec.name) == only.end()) {
      continue;
    }
    if (!runs_on(spec, host)) {
      plan.not_here.push_back(fmt::format("{} (host {})", spec.name, spec.host));
      continue;
    }
    std::string uri = plan.cyclonedds_uri;
    if (profile.security.enabled) {
      const std::string identity = security_dir + "/" + spec.name + ".xml";
      if (access(identity.c_str(), R_OK) != 0) {
        errors.push_back(fmt::format(
            "{}: service '{}': security is enabled but its DDS identity '{}' cannot be read "
            "({}); make the identities with deploy/security/make-pki.sh --out {}",
            spec.where, spec.name, identity, strerror(errno), security_dir));
        continue;
      }
      uri += ",file://" + identity;
    }
    LaunchSpec launch;
    launch.name = spec.name;
    launch.host = this_host();
    const auto exe = find_executable(spec.exec, self_dir);
    if (!exe) {
      errors.push_back(
          spec.exec.find('/') != std::string::npos
              ? fmt::format("{}: service '{}': executable '{}' not found or not executable",
                            spec.where, spec.name, home_path(spec.exec))
              : fmt::format("{}: service '{}': executable '{}' not found in {} nor in PATH",
                            spec.where, spec.name, spec.exec,
                            self_dir.empty() ? std::string("<unknown>") : self_dir));
      continue;
    }
    launch.executable = *exe;
    if (!spec.config.empty()) {
      const std::string config = home_path(spec.config);
      if (access(config.c_str(), R_OK) != 0) {
        errors.push_back(fmt::format("{}: service '{}': cannot read config '{}': {}", spec.where,
                                     spec.name, config, strerror(errno)));
        continue;
      }
      launch.args = {"--config", config};
    }
    launch.args.insert(launch.args.end(), {"--id", spec.name});
    launch.args.insert(launch.args.end(), spec.args.begin(), spec.args.end());
    launch.env = {
        "CELL_HOME=" + home_dir(), fmt::format("CELL_DOMAIN_ID={}", profile.bus.domain_id),
        "CELL_PARTITION=" + profile.bus.partition, "CYCLONEDDS_URI=" + uri};
    for (const auto& [key, value] : spec.env) {
      std::erase_if(launch.env, [&key = key](const std::string& entry) {
        return entry.compare(0, key.size() + 1, key + "=") == 0;
      });
      launch.env.push_back(fmt::format("{}={}", key, value));
    }
    launch.log_file = plan.paths.service_log(spec.name);
    plan.services.push_back(std::move(launch));
  }
  if (plan.services.empty() && errors.empty()) {
    errors.push_back(host.empty()
                         ? fmt::format("{}: no service of this profile runs on this host ('{}')",
                                       profile.path, this_host())
                         : fmt::format("{}: no service of this profile runs on host '{}'",
                                       profile.path, host));
  }
  if (!errors.empty()) {
    std::string message;
    for (const auto& e : errors) {
      message += (message.empty() ? "" : "\n") + e;
    }
    return Error{Errc::kConfig, std::move(message)};
  }
  return plan;
}

Status write_dds_config(const LaunchPlan& plan) {
  if (plan.dds_config_text.empty()) {
    return ok_status();
  }
  return write_file_atomically(plan.dds_config, plan.dds_config_text);
}

int supervise(const LaunchPlan& plan, int signal_fd) {
  Supervisor supervisor(plan, signal_fd);
  return supervisor.run();
}

}  // namespace cell::launcher
