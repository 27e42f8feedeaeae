#include "cell/process/child.hpp"

#include <signal.h>

#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/testing/matchers.hpp"

namespace cell::process {
namespace {

using ::cell::testing::IsErrWith;
using ::testing::HasSubstr;

TEST(Child, CapturesOutputAndExitCode) {
  auto child = Child::spawn({.executable = "sh", .args = {"-c", "echo out; echo err >&2; exit 3"}});
  ASSERT_TRUE(child) << child.error().message;
  const auto info = child->wait_for(std::chrono::seconds(10));
  ASSERT_TRUE(info.has_value());
  EXPECT_TRUE(info->exited);
  EXPECT_EQ(info->code, 3);
  EXPECT_THAT(child->output(), HasSubstr("out\n"));
  EXPECT_THAT(child->output(), HasSubstr("err\n"));
}

TEST(Child, ReportsAMissingExecutableAtSpawn) {
  auto child = Child::spawn({.executable = "/nonexistent/cell-nothing"});
  EXPECT_THAT(child, IsErrWith(Errc::kIo, "No such file"));
}

TEST(Child, PassesExtraEnvironment) {
  auto child = Child::spawn({.executable = "sh", .args = {"-c", "echo $CELL_X"},
                             .env = {"CELL_X=hello"}});
  ASSERT_TRUE(child);
  ASSERT_TRUE(child->wait_for(std::chrono::seconds(10)));
  EXPECT_EQ(child->output(), "hello\n");
}

TEST(Child, ALaterEnvironmentEntryReplacesAnEarlierOne) {
  setenv("CELL_Y", "parent", 1);
  auto child = Child::spawn({.executable = "sh",
                             .args = {"-c", "env | grep -c '^CELL_Y=' ; echo $CELL_Y"},
                             .env = {"CELL_Y=default", "CELL_Z=z", "CELL_Y=mine"}});
  unsetenv("CELL_Y");
  ASSERT_TRUE(child);
  ASSERT_TRUE(child->wait_for(std::chrono::seconds(10)));
  EXPECT_EQ(child->output(), "1\nmine\n");
}

TEST(Child, StopEscalatesToKillWhenTermIsIgnored) {
  auto child =
      Child::spawn({.executable = "sh", .args = {"-c", "trap '' TERM; echo ready; sleep 30"}});
  ASSERT_TRUE(child);
  const pid_t pid = child->pid();
  // Signal only once the trap is in place (else SIGTERM may win the race and end the shell).
  std::string out;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (out.find("ready") == std::string::npos && std::chrono::steady_clock::now() < deadline) {
    child->read_available(out);
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_NE(out.find("ready"), std::string::npos);
  const auto info = child->stop(std::chrono::milliseconds(300));
  EXPECT_FALSE(info.exited);
  EXPECT_EQ(info.signal, SIGKILL);
  EXPECT_FALSE(pid_alive(pid));
}

TEST(Child, DestructorKillsTheWholeGroup) {
  pid_t pid = 0;
  {
    auto child = Child::spawn({.executable = "sh", .args = {"-c", "sleep 30 & wait"}});
    ASSERT_TRUE(child);
    pid = child->pid();
    EXPECT_TRUE(pid_alive(pid));
  }
  EXPECT_FALSE(pid_alive(pid));
}

}  // namespace
}  // namespace cell::process
