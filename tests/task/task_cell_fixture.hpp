#pragma once
// The simulated cell for the task service's system tests: real processes on a private DDS
// domain and partition (sim-world, ideal gateways, motion, cameras, vision, calibration, task),
// driven by cellctl like an operator would. Ground truth comes from the world simulator
// (`cellctl world parts --json`). Every wait is a condition with a deadline.

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cell/process/child.hpp"
#include "cell/testing/env.hpp"

namespace cell::task_test {

using ::cell::testing::eventually;
using ::cell::testing::ToolRun;
using nlohmann::json;
using namespace std::chrono_literals;

/// config/sim-world.yaml's robot placements (the base frames in the world).
constexpr double k7545BaseZ = 981.51;
constexpr double kPickerBaseX = 1000.0;
constexpr double kPickerBaseZ = 960.0;

class TaskCell : public ::testing::Test {
 protected:
  TaskCell()
      : domain_(cell::testing::test_domain_id()), partition_(cell::testing::unique_partition()) {
    std::string pattern = "/tmp/cell-task-test-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp/cell-task-test-fallback";
    env_ = cell::testing::bus_env(domain_, partition_);
    env_.push_back("CELL_HOME=" + cell::testing::source_dir());
  }

  ~TaskCell() override {
    for (auto it = children_.rbegin(); it != children_.rend(); ++it) {
      auto& [name, child] = *it;
      if (child.running()) {
        const auto exit = child.stop(10s);
        if (!exit.exited || exit.code != 0) {
          ADD_FAILURE() << name << " ended with " << exit.describe() << ":\n" << child.output();
        }
      }
    }
    if (HasFailure()) {
      std::printf("%s", logs().c_str());
    }
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  std::string write(const std::string& name, const std::string& text) {
    const std::string path = dir_ + "/" + name;
    std::ofstream(path) << text;
    return path;
  }

  /// A shipped config with its `service:` line replaced and extra lines appended.
  std::string shipped(const std::string& config, const std::string& name,
                      const std::string& extra = {}) {
    std::ifstream f(cell::testing::source_dir() + "/" + config);
    std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    return write(name, text + "\n" + extra);
  }

  process::Child& start(const std::string& name, const std::string& exec,
                        const std::string& config) {
    process::SpawnOptions options;
    options.executable = cell::testing::bin_path(exec);
    options.args = {"--config", config};
    options.env = env_;
    auto child = process::Child::spawn(options);
    EXPECT_TRUE(child) << child.error().message;
    children_.emplace_back(name, child ? std::move(*child) : process::Child());
    return children_.back().second;
  }

  process::Child* child(const std::string& name) {
    for (auto& [n, c] : children_) {
      if (n == name) {
        return &c;
      }
    }
    return nullptr;
  }

  ToolRun cellctl(std::vector<std::string> args, std::chrono::milliseconds timeout = 30s) {
    args.insert(args.begin(), {"--timeout", "5"});
    return cell::testing::run_tool("cellctl", args, env_, timeout);
  }

  /// JSON printed by a cellctl --json run (stdout and stderr merged: from the first '{' or '[').
  static json parsed(const ToolRun& run) {
    const auto begin = run.output.find_first_of("{[");
    return begin == std::string::npos ? json()
                                      : json::parse(run.output.substr(begin), nullptr, false);
  }

  json world_parts() {
    const ToolRun run = cellctl({"--json", "world", "parts"});
    EXPECT_EQ(run.exit.code, 0) << run.output;
    const json doc = parsed(run);
    return doc.contains("parts") ? doc["parts"] : json::array();
  }

  std::string logs() {
    std::string out;
    for (auto& [name, c] : children_) {
      std::string text;
      (void)c.read_available(text);
      out += "---- " + name + "\n" + c.output() + text;
    }
    return out;
  }

  std::uint32_t domain_;
  std::string partition_;
  std::string dir_;
  std::vector<std::string> env_;
  std::vector<std::pair<std::string, process::Child>> children_;
};

}  // namespace cell::task_test
