#include "run_dir.hpp"

#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <cstdlib>
#include <filesystem>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/env.hpp"
#include "cell/testing/matchers.hpp"
#include "supervisor.hpp"
#include "temp_dir.hpp"

namespace cell::launcher {
namespace {

using ::cell::launcher::testing::TempDir;
using ::cell::testing::eventually;
using ::cell::testing::IsErrWith;
using ::cell::testing::IsOk;
using ::testing::Contains;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using namespace std::chrono_literals;

TEST(Backoff, DoublesPerQuickCrashUpToTheMaximumAndResetsAfterAStableRun) {
  Backoff backoff(
      RestartPolicy{.backoff_initial_s = 0.5, .backoff_max_s = 3.0, .stable_after_s = 10.0});
  EXPECT_DOUBLE_EQ(backoff.next_delay_s(0.1), 0.5);
  EXPECT_DOUBLE_EQ(backoff.next_delay_s(0.1), 1.0);
  EXPECT_DOUBLE_EQ(backoff.next_delay_s(9.9), 2.0);
  EXPECT_DOUBLE_EQ(backoff.next_delay_s(0.1), 3.0);
  EXPECT_DOUBLE_EQ(backoff.next_delay_s(0.1), 3.0);
  EXPECT_DOUBLE_EQ(backoff.next_delay_s(10.0), 0.5);  // it ran long enough: start over
  EXPECT_DOUBLE_EQ(backoff.next_delay_s(0.1), 1.0);
}

TEST(DescribeExit, NamesCodeOrSignalTheWayAShellDoes) {
  EXPECT_EQ(describe_exit(process::ExitInfo{.exited = true, .code = 0}), "exit 0");
  EXPECT_EQ(describe_exit(process::ExitInfo{.exited = true, .code = 2}), "exit 2");
  EXPECT_EQ(describe_exit(process::ExitInfo{.exited = false, .signal = SIGABRT}),
            "exit 134 (signal 6: Aborted)");
  EXPECT_EQ(describe_exit(process::ExitInfo{.exited = false, .signal = SIGKILL}),
            "exit 137 (signal 9: Killed)");
}

class PlanTest : public ::testing::Test {
 protected:
  PlanTest() {
    setenv("CELL_HOME", home_.path().c_str(), 1);
    std::filesystem::create_directories(home_.path() + "/bin");
    std::filesystem::create_directories(home_.path() + "/config/dds");
    home_.write("config/dds/loopback.xml", "<CycloneDDS/>\n");
    home_.write("config/svc.yaml", "service: {}\n");
    const std::string exe = home_.write("bin/fake-svc", "#!/bin/sh\nexit 0\n");
    chmod(exe.c_str(), 0755);
  }
  ~PlanTest() override { unsetenv("CELL_HOME"); }

  Profile profile(const std::string& yaml) {
    auto loaded = load_profile(home_.write("p.yaml", yaml));
    EXPECT_THAT(loaded, IsOk());
    return loaded ? *loaded : Profile{};
  }

  TempDir home_;
};

TEST_F(PlanTest, ResolvesExecutablesConfigsArgsAndEnvironment) {
  const Profile p = profile(
      "bus: {domain_id: 7, partition: lab}\n"
      "services:\n"
      "  - {name: one, exec: fake-svc, config: config/svc.yaml, args: [--x], env: {A: b}}\n"
      "  - {name: two, exec: bin/fake-svc, env: {CELL_PARTITION: mine}}\n"
      "  - {name: far, exec: not-needed-here, host: some-other-host}\n");
  auto plan = make_plan(p, {}, home_.path() + "/bin");
  ASSERT_THAT(plan, IsOk());
  EXPECT_EQ(plan->paths.dir, home_.path() + "/run");
  EXPECT_EQ(plan->cyclonedds_uri, "file://" + home_.path() + "/config/dds/loopback.xml");
  ASSERT_EQ(plan->services.size(), 2U);
  const LaunchSpec& one = plan->services[0];
  EXPECT_EQ(one.executable, home_.path() + "/bin/fake-svc");
  EXPECT_THAT(one.args,
              ElementsAre("--config", home_.path() + "/config/svc.yaml", "--id", "one", "--x"));
  EXPECT_THAT(one.env, Contains("CELL_DOMAIN_ID=7"));
  EXPECT_THAT(one.env, Contains("CELL_PARTITION=lab"));
  EXPECT_THAT(one.env, Contains("CELL_HOME=" + home_.path()));
  EXPECT_THAT(one.env, Contains("CYCLONEDDS_URI=" + plan->cyclonedds_uri));
  EXPECT_THAT(one.env, Contains("A=b"));
  EXPECT_EQ(one.log_file, home_.path() + "/run/logs/one.log");
  const LaunchSpec& two = plan->services[1];
  EXPECT_EQ(two.executable, home_.path() + "/bin/fake-svc");
  EXPECT_THAT(two.args, ElementsAre("--id", "two"));
  EXPECT_THAT(two.env, Contains("CELL_PARTITION=mine"));  // the profile's env wins
  EXPECT_THAT(two.env, ::testing::Not(Contains("CELL_PARTITION=lab")));
  EXPECT_THAT(plan->not_here, ElementsAre("far (host some-other-host)"));
}

TEST_F(PlanTest, OnlyRestrictsAndRejectsUnknownNames) {
  const Profile p = profile(
      "services:\n  - {name: one, exec: fake-svc}\n"
      "  - {name: two, exec: fake-svc}\n");
  auto plan = make_plan(p, {"two"}, home_.path() + "/bin");
  ASSERT_THAT(plan, IsOk());
  ASSERT_EQ(plan->services.size(), 1U);
  EXPECT_EQ(plan->services[0].name, "two");
  EXPECT_THAT(make_plan(p, {"three"}, home_.path() + "/bin"),
              IsErrWith(Errc::kConfig,
                        "--only three: no such service in the profile (it has: "
                        "one, two)"));
}

TEST_F(PlanTest, MissingExecutableOrConfigNamesTheProfileEntry) {
  const Profile p = profile(
      "services:\n"
      "  - {name: one, exec: no-such-cell-binary}\n"
      "  - {name: two, exec: fake-svc, config: config/nope.yaml}\n");
  const auto plan = make_plan(p, {}, home_.path() + "/bin");
  ASSERT_FALSE(plan.has_value());
  EXPECT_THAT(
      plan.error().message,
      HasSubstr("p.yaml:2:5: service 'one': executable 'no-such-cell-binary' not found in " +
                home_.path() + "/bin nor in PATH"));
  EXPECT_THAT(plan.error().message, HasSubstr("p.yaml:3:5: service 'two': cannot read config '" +
                                              home_.path() + "/config/nope.yaml'"));
}

TEST(PidFileLock, OneOwnerAtATimeAndTheFileGoesWithIt) {
  TempDir dir;
  const std::string pid_file = dir.path() + "/cell.pid";
  EXPECT_FALSE(live_supervisor(pid_file).has_value());
  auto lock = PidFileLock::acquire(pid_file);
  ASSERT_THAT(lock, IsOk());
  EXPECT_EQ(live_supervisor(pid_file), getpid());
  // A second claim (another open file description, as another process would have) is refused.
  EXPECT_THAT(PidFileLock::acquire(pid_file),
              IsErrWith(Errc::kNotReady, fmt::format("a supervisor (pid {}) already owns run "
                                                     "directory '{}'",
                                                     getpid(), dir.path())));
  lock->release();
  EXPECT_FALSE(std::filesystem::exists(pid_file));
  EXPECT_FALSE(live_supervisor(pid_file).has_value());
}

TEST(PidFileLock, AStalePidFileIsNotALiveSupervisorAndIsTakenOver) {
  TempDir dir;
  const std::string pid_file = dir.write("cell.pid", "999999\n");  // a killed supervisor's
  EXPECT_FALSE(live_supervisor(pid_file).has_value());
  auto lock = PidFileLock::acquire(pid_file);
  ASSERT_THAT(lock, IsOk());
  EXPECT_EQ(live_supervisor(pid_file), getpid());
}

TEST(StatusFile, RoundTripsThroughJson) {
  TempDir dir;
  StatusFile status;
  status.profile = "local";
  status.profile_path = "/x/local.yaml";
  status.supervisor_pid = 321;
  status.state = "running";
  status.started_ns = 1;
  status.updated_ns = 2;
  status.domain_id = 9;
  status.partition = "p";
  ServiceStatus s;
  s.name = "echo";
  s.host = "h";
  s.exec = "/bin/cell-echo";
  s.log = "/run/logs/echo.log";
  s.pid = 77;
  s.state = "backoff";
  s.restarts = 3;
  s.last_exit = "exit 134 (signal 6: Aborted)";
  s.backoff_s = 0.8;
  s.next_start_ns = 5;
  s.history = {ExitRecord{10, "exit 1", 0.3, 0.4}};
  s.last_lines = {"a", "b"};
  status.services.push_back(s);
  const std::string path = dir.path() + "/status.json";
  ASSERT_THAT(write_status(path, status), IsOk());
  auto back = read_status(path);
  ASSERT_THAT(back, IsOk());
  EXPECT_EQ(back->supervisor_pid, 321);
  EXPECT_EQ(back->domain_id, 9U);
  ASSERT_NE(back->find("echo"), nullptr);
  EXPECT_EQ(back->find("echo")->restarts, 3);
  EXPECT_EQ(back->find("echo")->last_exit, "exit 134 (signal 6: Aborted)");
  EXPECT_DOUBLE_EQ(back->find("echo")->backoff_s, 0.8);
  ASSERT_EQ(back->find("echo")->history.size(), 1U);
  EXPECT_DOUBLE_EQ(back->find("echo")->history[0].backoff_s, 0.4);
  EXPECT_THAT(back->find("echo")->last_lines, ElementsAre("a", "b"));
  EXPECT_EQ(back->find("nope"), nullptr);
  EXPECT_FALSE(std::filesystem::exists(path + ".tmp"));

  EXPECT_THAT(read_status(dir.write("bad.json", "{\"profile\": 3}")),
              IsErrWith(Errc::kInvalidArgument, "is not a cell status file"));
  EXPECT_THAT(read_status(dir.path() + "/none.json"), IsErrWith(Errc::kIo, "cannot read"));
}

TEST(Processes, ZombiesAreNotRunningAndExitsAreSeen) {
  EXPECT_TRUE(process_running(getpid()));
  EXPECT_TRUE(process_is(getpid(), std::filesystem::read_symlink("/proc/self/exe").string()));
  EXPECT_FALSE(process_is(getpid(), "/bin/true"));
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    pause();
    _exit(0);
  }
  EXPECT_TRUE(process_running(child));
  EXPECT_FALSE(wait_process_exit(child, 50));
  kill(child, SIGKILL);
  EXPECT_TRUE(wait_process_exit(child, 5000));  // exited, not yet reaped: a zombie
  EXPECT_FALSE(process_running(child));
  int status = 0;
  waitpid(child, &status, 0);
  EXPECT_FALSE(process_running(child));
}

}  // namespace
}  // namespace cell::launcher
