// The simulated cell's pick and place across processes: cell-sim-world (the thesis's table
// scene), cell-gateway with the ideal IBM 7545 and cell-motion, on a private DDS domain and
// partition, driven by cellctl like an operator would. The ideal robot picks an IC at its true
// grasp point (it attaches), 5 mm off another (it stays), and places the first on the thesis's
// place slot 0 (it lies there). Every wait is a condition with a deadline.

#include <fmt/format.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cell/process/child.hpp"
#include "cell/testing/env.hpp"

namespace cell {
namespace {

using ::cell::testing::eventually;
using ::cell::testing::ToolRun;
using nlohmann::json;
using namespace std::chrono_literals;

/// The 7545's base in the world (config/sim-world.yaml): world z - 981.51 = base z.
constexpr double kBaseZ = 981.51;
constexpr double kTableZ = 750.0;
constexpr double kTolMm = 0.05;

class SimWorldCellTest : public ::testing::Test {
 protected:
  SimWorldCellTest()
      : domain_(cell::testing::test_domain_id()), partition_(cell::testing::unique_partition()) {
    if (std::getenv("CYCLONEDDS_URI") == nullptr) {
      setenv("CYCLONEDDS_URI",
             ("file://" + cell::testing::source_dir() + "/config/dds/loopback.xml").c_str(), 1);
    }
    std::string pattern = "/tmp/cell-sim-world-XXXXXX";
    dir_ = mkdtemp(pattern.data()) != nullptr ? pattern : "/tmp/cell-sim-world-fallback";
    env_ = cell::testing::bus_env(domain_, partition_);
    env_.push_back("CELL_HOME=" + cell::testing::source_dir());
  }

  ~SimWorldCellTest() override {
    for (auto& [name, child] : children_) {
      if (child.running()) {
        const auto exit = child.stop(5s);
        if (!exit.exited || exit.code != 0) {
          ADD_FAILURE() << name << " ended with " << exit.describe() << ":\n" << child.output();
        }
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
    start("sim-world", "cell-sim-world",
          write("sim-world.yaml",
                "service: {id: sim-world}\n"
                "scene: config/scenes/table_ics.yaml\n"
                "robots:\n"
                "  - {id: ibm7545, xyz_mm: [0, 0, 981.51]}\n"));
    start("gateway", "cell-gateway",
          write("gateway.yaml",
                "service: {id: gateway.ibm7545}\n"
                "robot_config: config/robots/ibm7545.yaml\n"
                "driver: {kind: ideal, initial_joints: [45, 105, 0, 0], gripper_time_s: 0.1}\n"));
    start("motion", "cell-motion",
          write("motion.yaml",
                "service: {id: motion}\n"
                "robots:\n"
                "  - {id: ibm7545, config: config/robots/ibm7545.yaml}\n"
                "planner: {gripper_dwell_s: 0.3, linear_speed_mm_s: 400}\n"));
    ASSERT_TRUE(eventually(
        [&] {
          return cellctl({"world", "parts"}).exit.code == 0;
        },
        30s))
        << logs();
    ASSERT_TRUE(eventually(
        [&] {
          return cellctl({"robot", "home", "--robot", "ibm7545"}).exit.code == 0;
        },
        30s))
        << logs();
  }

  ToolRun cellctl(std::vector<std::string> args, std::chrono::milliseconds timeout = 30s) {
    args.insert(args.begin(), {"--timeout", "5"});
    return cell::testing::run_tool("cellctl", args, env_, timeout);
  }

  /// JSON printed by a cellctl --json run (stdout and stderr are merged: skip to the '{').
  static json parsed(const ToolRun& run) {
    const auto begin = run.output.find('{');
    return begin == std::string::npos ? json()
                                      : json::parse(run.output.substr(begin), nullptr, false);
  }

  json part(const std::string& id) {
    const ToolRun run = cellctl({"--json", "world", "parts"});
    EXPECT_EQ(run.exit.code, 0) << run.output;
    const json doc = parsed(run);  // named: a range over a temporary's member would dangle
    for (const auto& p : doc["parts"]) {
      if (p["id"] == id) {
        return p;
      }
    }
    ADD_FAILURE() << "no part " << id << " in " << run.output;
    return json();
  }

  /// "x,y,z,roll,pitch,yaw" of a world pose (from `cellctl world parts`) in the 7545's base
  /// frame, moved by (dx, dy) mm in the world.
  static std::string base_pose(const json& world_pose, double dx = 0.0, double dy = 0.0) {
    return fmt::format("{:.4f},{:.4f},{:.4f},0,0,{:.4f}", world_pose["x_mm"].get<double>() + dx,
                       world_pose["y_mm"].get<double>() + dy,
                       world_pose["z_mm"].get<double>() - kBaseZ,
                       world_pose["yaw_deg"].get<double>());
  }

  std::string logs() {
    std::string out;
    for (auto& [name, child] : children_) {
      std::string text;
      child.read_available(text);
      out += fmt::format("---- {}\n{}{}", name, child.output(), text);
    }
    return out;
  }

  std::uint32_t domain_;
  std::string partition_;
  std::string dir_;
  std::vector<std::string> env_;
  std::vector<std::pair<std::string, process::Child>> children_;
};

TEST_F(SimWorldCellTest, TheIdealRobotPicksAtTheGraspPointMissesFiveMillimetresOffAndPlaces) {
  // 5 mm off ic7's grasp point: the gripper closes on nothing, ic7 stays on the table.
  const json ic7 = part("ic7");
  ASSERT_TRUE(ic7.is_object());
  ToolRun run = cellctl({"move", "pick", "--robot", "ibm7545", "--pose",
                         base_pose(ic7["grasp"], 5.0, 0.0), "--wait", "60"},
                        90s);
  ASSERT_EQ(run.exit.code, 0) << run.output << logs();
  json after = part("ic7");
  EXPECT_EQ(after["support"], "table");
  EXPECT_EQ(after["pose"], ic7["pose"]);
  ASSERT_EQ(cellctl({"robot", "open", "--robot", "ibm7545"}).exit.code, 0);
  ASSERT_TRUE(eventually(
      [&] {
        return parsed(cellctl({"--json", "robot", "state", "--robot", "ibm7545"}))["gripper"] ==
               "open";
      },
      10s));

  // At ic8's true grasp point: it attaches and leaves the table with the tool.
  const json ic8 = part("ic8");
  ASSERT_TRUE(ic8.is_object());
  run = cellctl(
      {"move", "pick", "--robot", "ibm7545", "--pose", base_pose(ic8["grasp"]), "--wait", "60"},
      90s);
  ASSERT_EQ(run.exit.code, 0) << run.output << logs();
  after = part("ic8");
  EXPECT_EQ(after["support"], "robot/ibm7545");
  EXPECT_GT(after["pose"]["z_mm"].get<double>(), kTableZ + 20.0);  // departed upward with it

  // Placed on the thesis's place slot 0 (digest 000 §6: X = -250, Y = 250 mm, R = 0).
  const json slot = {{"x_mm", -250.0}, {"y_mm", 250.0}, {"z_mm", kTableZ + 3.81}, {"yaw_deg", 0.0}};
  run = cellctl({"move", "place", "--robot", "ibm7545", "--pose", base_pose(slot), "--wait", "60"},
                90s);
  ASSERT_EQ(run.exit.code, 0) << run.output << logs();
  after = part("ic8");
  EXPECT_EQ(after["support"], "table");
  EXPECT_NEAR(after["pose"]["x_mm"].get<double>(), -250.0, kTolMm);
  EXPECT_NEAR(after["pose"]["y_mm"].get<double>(), 250.0, kTolMm);
  EXPECT_NEAR(after["pose"]["z_mm"].get<double>(), kTableZ, 1e-9);
  EXPECT_NEAR(std::remainder(after["pose"]["yaw_deg"].get<double>(), 180.0), 0.0, 0.05);
  // The others never moved.
  EXPECT_EQ(part("ic7")["pose"], ic7["pose"]);
}

}  // namespace
}  // namespace cell
