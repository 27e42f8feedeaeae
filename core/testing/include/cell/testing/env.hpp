#pragma once

#include <chrono>
#include <thread>
#include <cstdint>
#include <string>
#include <vector>

#include "cell/process/child.hpp"

namespace cell::testing {

/// DDS domain for this test process: $CELL_TEST_DOMAIN if set, else 100 + pid % 100. With the
/// loopback-only Cyclone config that ctest sets (config/dds/loopback.xml), nothing leaves
/// the host; a per-process partition (below) separates concurrent tests on one domain.
std::uint32_t test_domain_id();

/// A partition name unique to this process and call: "test-<pid>-<n>".
std::string unique_partition();

/// Absolute path of the source checkout ($CELL_SOURCE_DIR, set by ctest).
std::string source_dir();

/// Absolute path of a built executable: $CELL_BIN_DIR/<name>, or beside the running test
/// executable when the variable is unset (a test run by hand).
std::string bin_path(const std::string& name);

/// Environment entries that put a child process on this test's private bus:
/// CELL_DOMAIN_ID, CELL_PARTITION, CYCLONEDDS_URI.
std::vector<std::string> bus_env(std::uint32_t domain_id, const std::string& partition);

/// Runs a built tool to completion (cellctl, say) with `env` added; returns its exit info and
/// merged output. Fails the calling test (ADD_FAILURE) and kills the tool on timeout.
struct ToolRun {
  process::ExitInfo exit;
  std::string output;
};
ToolRun run_tool(const std::string& name, const std::vector<std::string>& args,
                 const std::vector<std::string>& env,
                 std::chrono::milliseconds timeout = std::chrono::seconds(30));

/// Polls `condition` every 20 ms until it holds or `timeout` passes; returns whether it held.
template <typename Fn>
bool eventually(Fn&& condition, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    if (condition()) {
      return true;
    }
    if (std::chrono::steady_clock::now() >= deadline) {
      return false;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

}  // namespace cell::testing
