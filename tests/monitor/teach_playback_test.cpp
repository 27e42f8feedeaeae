// Teach and playback on the simulated Excalibur, end to end: cell-sim-excalibur (the RSI
// controller on a pseudo-terminal, 9600 baud paced, its own accuracy and settling),
// cell-gateway with the excalibur serial driver (the shipped config: position check with
// tolerance 1.0 deg) and cell-motion, as processes on a private bus. An operator moves the arm
// with cellctl, records poses and a gripper step with `cellctl task record`, moves away, then
// `cellctl task play` plays the file back. The simulator's TRUE joints (RobotState
// "excalibur.sim") must pass through every recorded pose and end on the last, each within the
// gateway's tolerance. Every wait is a condition with a deadline.
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <mutex>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/view.hpp"
#include "cell/process/child.hpp"
#include "cell/teach/task_file.hpp"
#include "cell/testing/env.hpp"

namespace cell {
namespace {

using ::cell::testing::eventually;
using ::cell::testing::ToolRun;
using ::testing::HasSubstr;
using nlohmann::json;
using namespace std::chrono_literals;

constexpr double kPi = 3.14159265358979323846;

std::string read_text(const std::string& path) {
  std::ifstream in(path);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// The gateway's position-check tolerance from its shipped config (driver.tolerance_deg).
double shipped_tolerance_deg() {
  const std::string text =
      read_text(cell::testing::source_dir() + "/config/gateway-excalibur-serial.yaml");
  std::smatch m;
  if (std::regex_search(text, m, std::regex(R"(tolerance_deg:\s*([0-9.]+))"))) {
    return std::stod(m[1]);
  }
  ADD_FAILURE() << "no driver.tolerance_deg in config/gateway-excalibur-serial.yaml";
  return 1.0;
}

class TeachPlaybackTest : public ::testing::Test {
 protected:
  TeachPlaybackTest()
      : domain_(cell::testing::test_domain_id()), partition_(cell::testing::unique_partition()) {
    if (std::getenv("CYCLONEDDS_URI") == nullptr) {
      setenv("CYCLONEDDS_URI",
             ("file://" + cell::testing::source_dir() + "/config/dds/loopback.xml").c_str(), 1);
    }
    std::string pattern = "/tmp/cell-teach-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp/cell-teach-fallback";
    env_ = cell::testing::bus_env(domain_, partition_);
    env_.push_back("CELL_HOME=" + cell::testing::source_dir());
  }

  ~TeachPlaybackTest() override {
    for (auto& [name, child] : children_) {
      if (child.running()) {
        (void)child.stop(5s);
      }
    }
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  std::string write(const std::string& name, const std::string& text) {
    std::string path = dir_ + "/" + name;
    std::ofstream(path) << text;
    return path;
  }

  void start(const std::string& name, const std::string& exec, const std::string& config) {
    process::SpawnOptions options;
    options.executable = cell::testing::bin_path(exec);
    options.args = {"--config", config};
    options.env = env_;
    auto child = process::Child::spawn(options);
    ASSERT_TRUE(child) << child.error().message;
    children_.emplace_back(name, std::move(*child));
  }

  void SetUp() override {
    const std::string src = cell::testing::source_dir();
    const std::string pty = dir_ + "/excalibur.pty";
    // The shipped simulator and gateway, on this test's own pseudo-terminal.
    std::string sim = read_text(src + "/config/sim-excalibur.yaml");
    sim = std::regex_replace(sim, std::regex(R"(link_path: \S+)"), "link_path: " + pty);
    sim = std::regex_replace(sim, std::regex(R"(control_file: \S+)"),
                             "control_file: " + dir_ + "/noise.yaml");
    start("sim-excalibur", "cell-sim-excalibur", write("sim.yaml", sim));
    std::string gateway = read_text(src + "/config/gateway-excalibur-serial.yaml");
    gateway = std::regex_replace(gateway, std::regex(R"(device: \S+)"), "device: " + pty);
    start("gateway", "cell-gateway", write("gateway.yaml", gateway));
    start("motion", "cell-motion",
          write("motion.yaml", "service: {id: motion}\n"
                               "robots:\n"
                               "  - {id: excalibur, config: config/robots/excalibur.yaml}\n"
                               "planner: {gripper_dwell_s: 0.3}\n"));
    ASSERT_TRUE(eventually(
        [&] { return cellctl({"robot", "state", "--robot", "excalibur"}).exit.code == 0; }, 60s))
        << logs();
    const json s = state();
    if (!s.value("homed", false)) {
      ASSERT_EQ(cellctl({"robot", "home", "--robot", "excalibur"}, 120s).exit.code, 0) << logs();
    }
  }

  ToolRun cellctl(std::vector<std::string> args, std::chrono::milliseconds timeout = 120s) {
    args.insert(args.begin(), {"--timeout", "10"});
    return cell::testing::run_tool("cellctl", args, env_, timeout);
  }

  json state() {
    const ToolRun r = cellctl({"--json", "robot", "state", "--robot", "excalibur"});
    const auto begin = r.output.find('{');
    return begin == std::string::npos ? json()
                                      : json::parse(r.output.substr(begin), nullptr, false);
  }

  void move_to(const std::vector<double>& deg) {
    std::string joints;
    for (const double d : deg) {
      joints += fmt::format("{}{}", joints.empty() ? "" : ",", d);
    }
    const ToolRun r = cellctl({"move", "joints", "--robot", "excalibur", "--joints", joints,
                               "--wait", "120"},
                              180s);
    ASSERT_EQ(r.exit.code, 0) << r.output << logs();
  }

  std::string logs() {
    std::string out;
    for (auto& [name, child] : children_) {
      std::string text;
      child.read_available(text);
      const std::string all = child.output() + text;
      out += "---- " + name + "\n" + all.substr(all.size() > 3000 ? all.size() - 3000 : 0);
    }
    return out;
  }

  std::uint32_t domain_;
  std::string partition_;
  std::string dir_;
  std::vector<std::string> env_;
  std::vector<std::pair<std::string, process::Child>> children_;
};

TEST_F(TeachPlaybackTest, ARecordedTaskPlaysBackOnTheSimulatedArmToTheRecordedPoses) {
  const double tol_deg = shipped_tolerance_deg();
  const std::string file = dir_ + "/teach.yaml";
  const std::vector<std::vector<double>> poses = {
      {10, 40, -120, 10, -30, 20}, {-20, 55, -100, -15, -45, 60}, {25, 35, -135, 30, -20, -40}};
  const char* names[] = {"a", "b", "c"};
  for (std::size_t i = 0; i < poses.size(); ++i) {
    move_to(poses[i]);
    const ToolRun r = cellctl({"task", "record", file, "--robot", "excalibur", "--name", names[i]});
    ASSERT_EQ(r.exit.code, 0) << r.output;
    if (i == 1) {
      ASSERT_EQ(cellctl({"task", "record", file, "--gripper", "close"}).exit.code, 0);
    }
  }
  // What was recorded is the arm's reported pose, within the tolerance of where it was sent.
  auto task = teach::load_task(file);
  ASSERT_TRUE(task) << task.error().message;
  ASSERT_EQ(task->steps.size(), 4U);
  std::vector<kinematics::JointVector> recorded;
  for (const auto& step : task->steps) {
    if (const auto* p = std::get_if<teach::PoseStep>(&step)) {
      recorded.push_back(p->joints);
    }
  }
  ASSERT_EQ(recorded.size(), 3U);
  for (std::size_t i = 0; i < 3; ++i) {
    for (int j = 0; j < 6; ++j) {
      EXPECT_NEAR(recorded[i][j] * 180 / kPi, poses[i][static_cast<std::size_t>(j)], tol_deg)
          << "pose " << names[i] << " joint " << j + 1;
    }
  }

  // Somewhere else, then play it back while watching the simulator's true joints.
  move_to({-40, 70, -90, 0, 0, 0});
  bus::Participant client(domain_, partition_);
  bus::Topic<cell_robot_RobotState> topic(client, bus::topics::kRobotState);
  bus::Reader<cell_robot_RobotState> truth(client, topic, bus::topics::kRobotState);
  ASSERT_TRUE(truth.wait_for_writers(2, 10s));
  std::mutex mutex;
  std::vector<std::vector<double>> seen;  // true joints [rad] during the playback
  std::atomic<bool> done{false};
  std::thread watcher([&] {
    while (!done) {
      (void)truth.wait_for_data(50ms);
      (void)truth.take_each([&](const cell_robot_RobotState& s, const dds_sample_info_t&) {
        if (bus::str(s.robot_id) == "excalibur.sim") {
          std::lock_guard lock(mutex);
          seen.push_back(bus::to_vector(s.position_rad_or_mm));
        }
      });
    }
  });
  const ToolRun play = cellctl({"--json", "task", "play", file}, 300s);
  std::this_thread::sleep_for(500ms);  // the last true states after the arm settled
  done = true;
  watcher.join();
  ASSERT_EQ(play.exit.code, 0) << play.output << logs();
  const json report = json::parse(play.output.substr(play.output.find('{')), nullptr, false);
  EXPECT_TRUE(report.value("ok", false)) << play.output;
  EXPECT_EQ(report.value("steps_done", 0), 4);

  std::lock_guard lock(mutex);
  ASSERT_GT(seen.size(), 20U);
  // Every recorded pose was reached: some true state within the tolerance on every joint.
  for (std::size_t i = 0; i < 3; ++i) {
    double best = 1e9;
    for (const auto& q : seen) {
      double worst_joint = 0.0;
      for (int j = 0; j < 6; ++j) {
        worst_joint = std::max(worst_joint, std::abs(q[static_cast<std::size_t>(j)] - recorded[i][j]));
      }
      best = std::min(best, worst_joint);
    }
    EXPECT_LE(best * 180 / kPi, tol_deg) << "pose " << names[i] << " was never reached";
    std::cout << fmt::format("pose {}: closest true state {:.3f} deg (tolerance {:.1f} deg)\n",
                             names[i], best * 180 / kPi, tol_deg);
  }
  // And the arm rests on the last one, the gripper closed by the task's gripper step.
  for (int j = 0; j < 6; ++j) {
    EXPECT_NEAR(seen.back()[static_cast<std::size_t>(j)] * 180 / kPi, recorded[2][j] * 180 / kPi,
                tol_deg)
        << "joint " << j + 1;
  }
  EXPECT_EQ(state().value("gripper", ""), "closed");
}

}  // namespace
}  // namespace cell
