#include "cell/process/child.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <csignal>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <optional>
#include <thread>

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

// A child that writes far more than a pipe holds (64 KiB) while nobody reads: with an output
// file it runs to its end; the file has every byte, appended after what was there.
TEST(Child, AnOutputFileNeverBlocksAChattyChild) {
  const std::string path = ::testing::TempDir() + "/cell-child-output.log";
  std::remove(path.c_str());
  {
    std::ofstream(path) << "before\n";
  }
  auto child = Child::spawn({.executable = "sh",
                             .args = {"-c", "head -c 2000000 /dev/zero | tr '\\0' x; echo; "
                                            "echo err >&2"},
                             .output_path = path});
  ASSERT_TRUE(child) << child.error().message;
  EXPECT_EQ(child->output_fd(), -1);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  std::optional<ExitInfo> info;
  while (!(info = child->poll()) && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));  // not reading anything
  }
  ASSERT_TRUE(info.has_value()) << "the child blocked on its output";
  EXPECT_EQ(info->code, 0);
  std::ifstream in(path);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(text.size(), 7U + 2000000U + 1U + 4U);
  EXPECT_EQ(text.substr(0, 7), "before\n");
  EXPECT_THAT(text, HasSubstr("err\n"));
  EXPECT_TRUE(child->output().empty());
  // A file that cannot be opened is refused at spawn, naming it.
  EXPECT_THAT(Child::spawn({.executable = "true", .output_path = "/nonexistent/dir/out.log"}),
              IsErrWith(Errc::kIo, "/nonexistent/dir/out.log"));
  std::remove(path.c_str());
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
