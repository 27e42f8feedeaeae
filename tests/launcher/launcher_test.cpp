// Multi-process tests of `cell up/down/status`, `cellctl ping` and cell-echo: the real
// executables on a private domain/partition (CELL_DOMAIN_ID/CELL_PARTITION), with a temporary
// run directory and profile per test. Every wait is a condition with a deadline.
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cell/bus/participant.hpp"
#include "cell/process/child.hpp"
#include "cell/service/directory.hpp"
#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"

namespace cell {
namespace {

using ::cell::testing::eventually;
using ::cell::testing::IsOk;
using ::cell::testing::ToolRun;
using nlohmann::json;
using ::testing::HasSubstr;
using namespace std::chrono_literals;

std::string read_file(const std::string& path) {
  std::ifstream in(path);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

/// One cell in a temporary directory, on this test's private bus.
class LauncherTest : public ::testing::Test {
 protected:
  LauncherTest()
      : domain_(cell::testing::test_domain_id()), partition_(cell::testing::unique_partition()) {
    // Orphans (the detached supervisor, services outliving it) come to us rather than to
    // init, so gone() can reap them and pid_alive() never sees a zombie.
    prctl(PR_SET_CHILD_SUBREAPER, 1);
    // ctest should set these (cell_add_test); do not depend on it: the tools sit beside this
    // binary, and this process's own DDS participant must use the loopback config too.
    if (std::getenv("CELL_BIN_DIR") == nullptr) {
      const auto self = std::filesystem::read_symlink("/proc/self/exe");
      setenv("CELL_BIN_DIR", self.parent_path().c_str(), 1);
    }
    if (std::getenv("CYCLONEDDS_URI") == nullptr) {
      setenv("CYCLONEDDS_URI",
             ("file://" + cell::testing::source_dir() + "/config/dds/loopback.xml").c_str(), 1);
    }
    std::string pattern = "/tmp/cell-launcher-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp/cell-launcher-fallback";
    run_dir_ = dir_ + "/run";
    profile_ = dir_ + "/profile.yaml";
    env_ = cell::testing::bus_env(domain_, partition_);
    env_.push_back("CELL_HOME=" + cell::testing::source_dir());
  }

  ~LauncherTest() override {
    try {  // a destructor must not throw: a failed cleanup is reported, not fatal
      if (std::filesystem::exists(run_dir_ + "/cell.pid")) {
        (void)run_cell({"down", "--timeout", "10"});
      }
      for (const pid_t pid : service_pids()) {  // belt and braces: nothing may outlive a test
        if (!gone(pid)) {
          kill(-pid, SIGKILL);
          kill(pid, SIGKILL);
        }
      }
      while (waitpid(-1, nullptr, WNOHANG) > 0) {
      }
      std::error_code ec;
      std::filesystem::remove_all(dir_, ec);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "LauncherTest cleanup: %s\n", e.what());
    }
  }

  /// Writes an echo config with the fast heartbeat the tests need plus `extra` YAML lines.
  std::string echo_config(const std::string& name, const std::string& extra = {}) {
    std::string path = fmt::format("{}/{}.yaml", dir_, name);
    std::ofstream(path) << "service:\n  heartbeat_period_s: 0.2\n  stall_timeout_s: 1.0\n" << extra;
    return path;
  }

  /// One profile entry: cell-echo with `config`, unless `exec` says otherwise.
  struct Entry {
    std::string name;
    std::string config;
    std::string exec = "cell-echo";
  };

  /// Writes the profile with `services` and the given restart policy.
  void write_profile(const std::vector<Entry>& services,
                     const std::string& restart =
                         "{backoff_initial_s: 0.2, backoff_max_s: 2, "
                         "stable_after_s: 30}") {
    std::ofstream out(profile_);
    out << "profile: test\n"
        << "bus: {domain_id: 0, partition: overridden-by-the-environment}\n"
        << "run_dir: " << run_dir_ << "\n"
        << "restart: " << restart << "\n"
        << "stop_grace_s: " << stop_grace_s_ << "\n"
        << "services:\n";
    for (const auto& entry : services) {
      out << "  - {name: " << entry.name << ", exec: " << entry.exec;
      if (!entry.config.empty()) {
        out << ", config: " << entry.config;
      }
      out << "}\n";
    }
  }

  /// Runs `cell <args> --profile <profile>`.
  ToolRun run_cell(std::vector<std::string> args) {
    args.insert(args.begin() + 1, {"--profile", profile_});
    return cell::testing::run_tool("cell", args, env_, 40s);
  }

  /// `cellctl --json ping`, parsed; null when it failed.
  json ping() {
    const ToolRun run =
        cell::testing::run_tool("cellctl", {"--json", "--timeout", "2", "ping"}, env_);
    if (run.exit.code != 0 || !run.exit.exited) {
      return json();
    }
    const auto begin = run.output.find('{');
    return begin == std::string::npos ? json()
                                      : json::parse(run.output.substr(begin), nullptr, false);
  }

  /// The service `id` in a ping result, or null.
  static json service_in(const json& ping, const std::string& id) {
    if (ping.is_object() && ping.contains("services")) {
      for (const auto& s : ping["services"]) {
        if (s["id"] == id) {
          return s;
        }
      }
    }
    return json();
  }

  /// run/status.json, or null while it does not exist.
  json status() const {
    const std::string text = read_file(run_dir_ + "/status.json");
    return text.empty() ? json() : json::parse(text, nullptr, false);
  }

  static json service_status(const json& status, const std::string& name) {
    if (status.is_object()) {
      for (const auto& s : status["services"]) {
        if (s["name"] == name) {
          return s;
        }
      }
    }
    return json();
  }

  std::vector<pid_t> service_pids() const {
    std::vector<pid_t> pids;
    const json s = status();
    if (s.is_object()) {
      for (const auto& svc : s["services"]) {
        if (svc["pid"].get<int>() > 0) {
          pids.push_back(svc["pid"].get<pid_t>());
        }
      }
    }
    return pids;
  }

  pid_t supervisor_pid() const {
    return static_cast<pid_t>(std::atoi(read_file(run_dir_ + "/cell.pid").c_str()));
  }

  /// True once `pid` has exited (reaping it if it was orphaned to us).
  static bool gone(pid_t pid) {
    waitpid(pid, nullptr, WNOHANG);
    return !process::pid_alive(pid);
  }

  /// Starts the cell in the background and waits until cellctl lists every name serving.
  void up_and_serving(const std::set<std::string>& names) {
    const ToolRun up = run_cell({"up", "--detach"});
    ASSERT_TRUE(up.exit.exited && up.exit.code == 0) << up.output;
    ASSERT_TRUE(eventually(
        [&] {
          const json p = ping();
          for (const auto& name : names) {
            if (service_in(p, name)["state"] != "serving") {
              return false;
            }
          }
          return true;
        },
        30s))
        << read_file(run_dir_ + "/logs/cell.log");
  }

  std::uint32_t domain_;
  std::string partition_;
  std::string dir_;
  std::string run_dir_;
  std::string profile_;
  std::vector<std::string> env_;
  double stop_grace_s_ = 3.0;
};

TEST_F(LauncherTest, UpStartsEveryServiceAndCellctlPingListsThem) {
  write_profile({{"alpha", echo_config("alpha")},
                 {"beta", echo_config("beta")},
                 {"gamma", echo_config("gamma")}});
  const ToolRun up = run_cell({"up", "--detach"});
  ASSERT_EQ(up.exit.code, 0) << up.output;
  EXPECT_THAT(up.output, HasSubstr(run_dir_ + "/logs"));
  EXPECT_THAT(up.output, HasSubstr("cellctl ping"));
  EXPECT_THAT(up.output, HasSubstr("cell status"));
  EXPECT_THAT(up.output, HasSubstr("cell down"));
  const pid_t supervisor = supervisor_pid();
  EXPECT_TRUE(process::pid_alive(supervisor));

  json listed;
  ASSERT_TRUE(eventually(
      [&] {
        listed = ping();
        return listed.is_object() && listed["services"].size() == 3 &&
               service_in(listed, "alpha")["state"] == "serving" &&
               service_in(listed, "beta")["state"] == "serving" &&
               service_in(listed, "gamma")["state"] == "serving";
      },
      30s))
      << listed.dump(2) << read_file(run_dir_ + "/logs/cell.log");
  EXPECT_EQ(listed["domain"].get<std::uint32_t>(), domain_);
  EXPECT_EQ(listed["partition"], partition_);
  const json launched = status();
  for (const std::string name : {"alpha", "beta", "gamma"}) {
    const json s = service_in(listed, name);
    EXPECT_EQ(s["kind"], "echo");
    const pid_t pid = s["pid"].get<pid_t>();
    EXPECT_TRUE(process::pid_alive(pid)) << name;
    EXPECT_EQ(service_status(launched, name)["pid"].get<pid_t>(), pid) << name;
    EXPECT_EQ(service_status(launched, name)["restarts"], 0) << name;
  }

  const ToolRun table = run_cell({"status"});
  EXPECT_EQ(table.exit.code, 0) << table.output;
  EXPECT_THAT(table.output, HasSubstr("NAME"));
  EXPECT_THAT(table.output, HasSubstr(fmt::format("supervisor pid {}", supervisor)));

  // One supervisor per run directory.
  const ToolRun again = run_cell({"up", "--detach"});
  EXPECT_EQ(again.exit.code, 1) << again.output;
  EXPECT_THAT(again.output, HasSubstr(fmt::format(
                                "a supervisor (pid {}) already owns run directory", supervisor)));
}

TEST_F(LauncherTest, KilledServiceIsNoticedLostThenRestartedWithANewPid) {
  // A long first back-off keeps the dead service dead long enough to watch it be noticed.
  write_profile({{"victim", echo_config("victim")}, {"bystander", echo_config("bystander")}},
                "{backoff_initial_s: 5, backoff_max_s: 10, stable_after_s: 30}");
  bus::Participant participant(domain_, partition_);
  service::ServiceDirectory directory(participant, "launcher-test");
  up_and_serving({"victim", "bystander"});
  ASSERT_THAT(directory.wait_settled(10s, {"victim", "bystander"}), IsOk());
  const pid_t old_pid = service_in(ping(), "victim")["pid"].get<pid_t>();
  ASSERT_GT(old_pid, 0);

  ASSERT_EQ(kill(old_pid, SIGKILL), 0);
  const auto killed_at = std::chrono::steady_clock::now();

  // The supervisor notices at once (SIGCHLD) ...
  ASSERT_TRUE(
      eventually([&] { return service_status(status(), "victim")["state"] == "backoff"; }, 3s));
  const json launched = service_status(status(), "victim");
  EXPECT_EQ(launched["last_exit"], "exit 137 (signal 9: Killed)");
  const ToolRun table = run_cell({"status", "--json", "--timeout", "1"});
  EXPECT_EQ(table.exit.code, 1) << table.output;  // not every service is serving
  EXPECT_THAT(table.output, HasSubstr("\"launcher_state\": \"backoff\""));
  EXPECT_THAT(table.output, HasSubstr("signal 9"));

  // ... and the bus within the 3 s liveliness lease.
  ASSERT_TRUE(eventually(
      [&] {
        auto snap = directory.snapshot();
        if (!snap) {
          return false;
        }
        for (const auto& entry : *snap) {
          if (entry.service_id == "victim") {
            return entry.lost;
          }
        }
        return true;  // gone altogether also counts as noticed
      },
      6s));
  const double noticed_after_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - killed_at).count();
  EXPECT_LT(noticed_after_s, 4.5);

  // Then the launcher restarts it under the same id with a new pid.
  json restarted;
  ASSERT_TRUE(eventually(
      [&] {
        restarted = service_in(ping(), "victim");
        return restarted.is_object() && restarted["state"] == "serving" &&
               restarted["pid"].get<pid_t>() != old_pid;
      },
      20s))
      << read_file(run_dir_ + "/logs/cell.log");
  EXPECT_TRUE(process::pid_alive(restarted["pid"].get<pid_t>()));
  EXPECT_EQ(service_status(status(), "victim")["restarts"], 1);
  EXPECT_EQ(service_status(status(), "bystander")["restarts"], 0);
}

TEST_F(LauncherTest, CrashingServiceIsRestartedWithGrowingBackoff) {
  write_profile({{"crasher", echo_config("crasher", "crash_after_s: 0.3\n")}},
                "{backoff_initial_s: 0.2, backoff_max_s: 1.6, stable_after_s: 30}");
  const ToolRun up = run_cell({"up", "--detach"});
  ASSERT_EQ(up.exit.code, 0) << up.output;
  json crasher;
  ASSERT_TRUE(eventually(
      [&] {
        crasher = service_status(status(), "crasher");
        return crasher.is_object() && crasher["restarts"].get<int>() >= 3;
      },
      30s))
      << crasher.dump(2);
  const json& history = crasher["history"];
  ASSERT_GE(history.size(), 3U);
  EXPECT_DOUBLE_EQ(history[0]["backoff_s"].get<double>(), 0.2);
  EXPECT_DOUBLE_EQ(history[1]["backoff_s"].get<double>(), 0.4);
  EXPECT_DOUBLE_EQ(history[2]["backoff_s"].get<double>(), 0.8);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(history[i]["exit"], "exit 134 (signal 6: Aborted)");
    if (i > 0) {  // each wait really was longer than the one before
      const double gap_s = static_cast<double>(history[i]["ended_ns"].get<std::int64_t>() -
                                               history[i - 1]["ended_ns"].get<std::int64_t>()) *
                           1e-9;
      EXPECT_GE(gap_s, history[i - 1]["backoff_s"].get<double>());
    }
  }
  const std::string log = read_file(run_dir_ + "/logs/cell.log");
  EXPECT_THAT(log, HasSubstr("restart #1 in 0.20 s"));
  EXPECT_THAT(log, HasSubstr("restart #2 in 0.40 s"));
  EXPECT_THAT(log, HasSubstr("restart #3 in 0.80 s"));
  EXPECT_THAT(read_file(run_dir_ + "/logs/crasher.log"), HasSubstr("crashing on purpose"));
}

TEST_F(LauncherTest, ConfigErrorIsReportedFailedAndNotRestarted) {
  const std::string broken = echo_config("broken", "crash_after: 1\n");  // typo: unknown key
  write_profile({{"broken", broken}, {"healthy", echo_config("healthy")}});
  up_and_serving({"healthy"});
  json failed;
  ASSERT_TRUE(eventually(
      [&] {
        failed = service_status(status(), "broken");
        return failed.is_object() && failed["state"] == "failed";
      },
      10s));
  EXPECT_EQ(failed["last_exit"], "exit 2");
  EXPECT_EQ(failed["restarts"], 0);
  EXPECT_EQ(failed["pid"], 0);
  EXPECT_THAT(failed["reason"].get<std::string>(), HasSubstr("configuration error"));
  EXPECT_THAT(failed["last_lines"].dump(), HasSubstr(broken + ":4:1: unknown key 'crash_after'"));
  EXPECT_THAT(read_file(run_dir_ + "/logs/cell.log"), HasSubstr("its last lines"));

  // Absence of a restart can only be shown by waiting: several back-off periods (0.2 s).
  std::this_thread::sleep_for(1500ms);
  const json later = service_status(status(), "broken");
  EXPECT_EQ(later["state"], "failed");
  EXPECT_EQ(later["restarts"], 0);
  EXPECT_EQ(later["history"].size(), 1U);

  const ToolRun table = run_cell({"status", "--timeout", "1"});
  EXPECT_EQ(table.exit.code, 1);
  EXPECT_THAT(table.output, HasSubstr("missing"));
  EXPECT_THAT(table.output, HasSubstr("launcher: failed, last exit 2"));
}

TEST_F(LauncherTest, StalledServiceIsReportedDegraded) {
  write_profile({{"sleepy", echo_config("sleepy", "stall_after_s: 0.5\n")}});
  const ToolRun up = run_cell({"up", "--detach"});
  ASSERT_EQ(up.exit.code, 0) << up.output;
  json sleepy;
  ASSERT_TRUE(eventually(
      [&] {
        sleepy = service_in(ping(), "sleepy");
        return sleepy.is_object() && sleepy["state"] == "degraded";
      },
      20s))
      << sleepy.dump();
  EXPECT_THAT(sleepy["detail"].get<std::string>(), HasSubstr("stalled"));
  EXPECT_FALSE(sleepy["lost"].get<bool>());  // alive, only its main loop is stuck
  const ToolRun table = run_cell({"status"});
  EXPECT_EQ(table.exit.code, 1);
  EXPECT_THAT(table.output, HasSubstr("degraded"));
}

TEST_F(LauncherTest, DownStopsTheSupervisorAndEveryChild) {
  write_profile({{"one", echo_config("one")}, {"two", echo_config("two")}});
  up_and_serving({"one", "two"});
  const pid_t supervisor = supervisor_pid();
  const std::vector<pid_t> children = service_pids();
  ASSERT_EQ(children.size(), 2U);

  const ToolRun down = run_cell({"down"});
  EXPECT_EQ(down.exit.code, 0) << down.output;
  EXPECT_THAT(down.output, HasSubstr("stopped in"));
  EXPECT_TRUE(eventually([&] { return gone(supervisor); }, 5s));
  for (const pid_t pid : children) {
    EXPECT_TRUE(eventually([&] { return gone(pid); }, 5s)) << pid;
  }
  EXPECT_FALSE(std::filesystem::exists(run_dir_ + "/cell.pid"));
  const json final_status = status();
  EXPECT_EQ(final_status["state"], "stopped");
  for (const std::string name : {"one", "two"}) {
    EXPECT_EQ(service_status(final_status, name)["state"], "stopped");
    EXPECT_EQ(service_status(final_status, name)["last_exit"], "exit 0");
    EXPECT_THAT(read_file(run_dir_ + "/logs/" + name + ".log"), HasSubstr("stopped cleanly"));
  }
  const ToolRun again = run_cell({"down"});
  EXPECT_EQ(again.exit.code, 0);
  EXPECT_THAT(again.output, HasSubstr("nothing to stop"));
}

TEST_F(LauncherTest, BadProfileExitsTwoNamingFileLineAndKey) {
  struct Case {
    std::string yaml;
    std::string expected;
  };
  const std::string svc = "services:\n  - {name: a, exec: cell-echo}\n";
  const std::string run_dir = "run_dir: " + run_dir_ + "\n";
  const std::vector<Case> cases = {
      {run_dir + "profile: x\n" + svc + "stop_grace: 3\n", ":5:1: unknown key 'stop_grace'"},
      {"stop_grace_s: soon\n" + run_dir + svc,
       ":1:15: key 'stop_grace_s': expected a finite number"},
      {"profile: x\n" + run_dir, ":1:1: missing required list 'services'"},
      {run_dir + "services:\n  - {name: a, exec: no-such-cell-binary}\n",
       ":3:5: service 'a': executable 'no-such-cell-binary' not found"},
  };
  for (const auto& c : cases) {
    std::ofstream(profile_) << c.yaml;
    for (const std::string command : {"up", "status", "down"}) {
      if (command != "up" && c.expected.find("executable") != std::string::npos) {
        continue;  // resolving executables is up's business only
      }
      const ToolRun run = run_cell({command});
      EXPECT_EQ(run.exit.code, 2) << command << ": " << run.output;
      EXPECT_THAT(run.output, HasSubstr(profile_ + c.expected)) << command;
    }
  }
  EXPECT_FALSE(std::filesystem::exists(run_dir_)) << "nothing may start from a bad profile";
}

TEST_F(LauncherTest, SigtermedServiceExitsZeroLogsStoppedCleanlyAndComesBack) {
  write_profile({{"calm", echo_config("calm")}});
  up_and_serving({"calm"});
  const pid_t pid = service_status(status(), "calm")["pid"].get<pid_t>();
  ASSERT_GT(pid, 0);
  ASSERT_EQ(kill(pid, SIGTERM), 0);
  json calm;
  ASSERT_TRUE(eventually(
      [&] {
        calm = service_status(status(), "calm");
        return calm.is_object() && calm["history"].size() == 1;
      },
      10s));
  EXPECT_EQ(calm["history"][0]["exit"], "exit 0");
  EXPECT_THAT(read_file(run_dir_ + "/logs/calm.log"), HasSubstr("stopped cleanly"));
  // Nobody asked the launcher to stop it: it is restarted like any unexpected exit.
  EXPECT_TRUE(eventually(
      [&] {
        const json s = service_in(ping(), "calm");
        return s.is_object() && s["state"] == "serving" && s["pid"].get<pid_t>() != pid;
      },
      15s));
}

TEST_F(LauncherTest, ServiceIgnoringSigtermIsKilledAfterTheGracePeriod) {
  // A stubborn process: ignores SIGTERM (and so do the sleeps it starts), as a hung service.
  const std::string script = dir_ + "/stubborn.sh";
  std::ofstream(script) << "#!/bin/sh\ntrap '' TERM\necho stubborn up\n"
                           "while :; do sleep 0.1; done\n";
  std::filesystem::permissions(script, std::filesystem::perms::owner_all);
  stop_grace_s_ = 1.0;
  write_profile({{"stubborn", "", script}, {"polite", echo_config("polite")}});
  up_and_serving({"polite"});
  ASSERT_TRUE(eventually(
      [&] {
        return read_file(run_dir_ + "/logs/stubborn.log").find("stubborn up") != std::string::npos;
      },
      10s));
  const pid_t stubborn = service_status(status(), "stubborn")["pid"].get<pid_t>();

  const auto t0 = std::chrono::steady_clock::now();
  const ToolRun down = run_cell({"down"});
  const double took_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(down.exit.code, 0) << down.output;
  EXPECT_GE(took_s, 0.9);   // it waited the grace period for the stubborn one ...
  EXPECT_LT(took_s, 10.0);  // ... and not much longer
  EXPECT_TRUE(eventually([&] { return gone(stubborn); }, 5s));
  const json final_status = status();
  EXPECT_EQ(service_status(final_status, "stubborn")["last_exit"], "exit 137 (signal 9: Killed)");
  EXPECT_EQ(service_status(final_status, "polite")["last_exit"], "exit 0");
  EXPECT_THAT(read_file(run_dir_ + "/logs/cell.log"), HasSubstr("did not stop in time: SIGKILL"));
}

TEST_F(LauncherTest, ForegroundUpPrefixesOutputAndStopsOnCtrlC) {
  write_profile({{"fg", echo_config("fg")}});
  process::SpawnOptions options;
  options.executable = cell::testing::bin_path("cell");
  options.args = {"up", "--profile", profile_};
  options.env = env_;
  auto launcher = process::Child::spawn(options);
  ASSERT_THAT(launcher, IsOk());
  std::string output;
  ASSERT_TRUE(eventually(
      [&] {
        launcher->read_available(output);  // keep the pipe drained
        return service_in(ping(), "fg")["state"] == "serving";
      },
      30s))
      << output;
  const std::vector<pid_t> children = service_pids();
  ASSERT_EQ(children.size(), 1U);
  EXPECT_TRUE(std::filesystem::exists(run_dir_ + "/cell.pid"));

  launcher->signal(SIGINT);  // what Ctrl-C does to the foreground process group
  const auto exit = launcher->wait_for(15s);
  ASSERT_TRUE(exit.has_value());
  EXPECT_TRUE(exit->exited);
  EXPECT_EQ(exit->code, 0);
  output += launcher->output();
  EXPECT_THAT(output, HasSubstr("Ctrl-C"));
  EXPECT_THAT(output, HasSubstr("[fg] "));
  EXPECT_THAT(output, HasSubstr("msg=\"stopped cleanly\" id=fg"));
  EXPECT_FALSE(std::filesystem::exists(run_dir_ + "/cell.pid"));
  for (const pid_t pid : children) {
    EXPECT_TRUE(eventually([&] { return gone(pid); }, 5s));
  }
}

}  // namespace
}  // namespace cell
