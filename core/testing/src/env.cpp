#include "cell/testing/env.hpp"

#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>

#include <fmt/format.h>
#include <gtest/gtest.h>

namespace cell::testing {

std::uint32_t test_domain_id() {
  if (const char* env = std::getenv("CELL_TEST_DOMAIN"); env != nullptr) {
    return static_cast<std::uint32_t>(std::strtoul(env, nullptr, 10));
  }
  return 100U + static_cast<std::uint32_t>(getpid()) % 100U;
}

std::string unique_partition() {
  static std::atomic<int> counter{0};
  return fmt::format("test-{}-{}", getpid(), counter.fetch_add(1));
}

std::string source_dir() {
  const char* env = std::getenv("CELL_SOURCE_DIR");
  return env != nullptr ? env : ".";
}

std::string bin_path(const std::string& name) {
  if (const char* env = std::getenv("CELL_BIN_DIR"); env != nullptr && *env != '\0') {
    return fmt::format("{}/{}", env, name);
  }
  // Run by hand rather than by ctest: the test executables live beside the tools.
  std::error_code ec;
  const auto self = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? name : (self.parent_path() / name).string();
}

std::vector<std::string> bus_env(std::uint32_t domain_id, const std::string& partition) {
  return {fmt::format("CELL_DOMAIN_ID={}", domain_id), "CELL_PARTITION=" + partition,
          "CYCLONEDDS_URI=file://" + source_dir() + "/config/dds/loopback.xml"};
}

ToolRun run_tool(const std::string& name, const std::vector<std::string>& args,
                 const std::vector<std::string>& env, std::chrono::milliseconds timeout) {
  process::SpawnOptions options;
  options.executable = bin_path(name);
  options.args = args;
  options.env = env;
  auto child = process::Child::spawn(options);
  if (!child) {
    ADD_FAILURE() << child.error().message;
    return {};
  }
  auto info = child->wait_for(timeout);
  if (!info) {
    ADD_FAILURE() << name << " did not finish within " << timeout.count() << " ms";
    info = child->stop(std::chrono::milliseconds(500));
  }
  return ToolRun{*info, child->output()};
}

}  // namespace cell::testing
