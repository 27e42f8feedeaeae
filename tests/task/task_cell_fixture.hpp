#pragma once
// The simulated cell for the task service's system tests: real processes on a private DDS
// domain and partition (sim-world, ideal gateways, motion, cameras, vision, calibration, task),
// driven by cellctl like an operator would. Ground truth comes from the world simulator
// (`cellctl world parts --json`). Every wait is a condition with a deadline.

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <fmt/format.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <opencv2/imgcodecs.hpp>

#include "cell/calibration/board.hpp"
#include "cell/calibration/camera_calibration.hpp"
#include "cell/calibration/store.hpp"
#include "cell/process/child.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/testing/env.hpp"
#include "sim_views.hpp"

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
          ADD_FAILURE() << name << " ended with " << exit.describe() << ":\n" << output_of(name);
        }
      }
    }
    if (HasFailure()) {
      std::printf("%s", logs().c_str());
    }
    // CELL_TEST_KEEP=1 keeps the test's directory: every child's log (<name>.log), the
    // journal, the configs.
    if (const char* keep = std::getenv("CELL_TEST_KEEP"); keep != nullptr && *keep == '1') {
      std::printf("kept %s\n", dir_.c_str());
      return;
    }
    std::error_code ec;
    std::filesystem::remove_all(dir_, ec);
  }

  std::string write(const std::string& name, const std::string& text) {
    std::string path = dir_ + "/" + name;
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
    // Each child's log in a file: a test of minutes (or task_bench's) never stalls a service
    // on a full output pipe.
    options.output_path = log_path(name);
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

  std::string log_path(const std::string& name) const { return dir_ + "/" + name + ".log"; }

  /// Everything child `name` printed so far ("" when there is no such child).
  std::string output_of(const std::string& name) {
    std::ifstream f(log_path(name));
    return std::string((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  }

  std::string logs() {
    std::string out;
    for (auto& entry : children_) {
      out += "---- " + entry.first + "\n" + output_of(entry.first);
    }
    return out;
  }

  std::uint32_t domain_;
  std::string partition_;
  std::string dir_;
  std::vector<std::string> env_;
  std::vector<std::pair<std::string, process::Child>> children_;
};

namespace cal = ::cell::calibration;

/// The table scene: the thesis's table, no parts; the test scatters them.
inline constexpr const char* kTableScene = R"(name: scatter_table
table: {height_mm: 750, x_mm: [-600, 600], y_mm: [-150, 750], reflectance: 0.9}
min_separation_mm: 5.7
scatter:
  - {count: 0, classes: [ic_7x30, ic_6x19, dip14, dip8], x_mm: [88, 182], y_mm: [452, 548],
     yaw_deg: [-180, 180], min_separation_mm: 6.0, seed: 1994}
)";

/// A stream of DIPs on belt1 (config/scenes/cell.yaml's belt), one every `period` seconds.
inline std::string belt_scene(double speed_mm_s, double period_s) {
  return fmt::format(R"(name: stream
table: {{height_mm: 750, x_mm: [-600, 600], y_mm: [-150, 750], reflectance: 0.9}}
belts:
  - {{id: belt1, origin_mm: [1350, 600, 760], direction_deg: -90, length_mm: 1500,
     width_mm: 300, speed_mm_s: {}, counts_per_rev: 1024, roller_diameter_mm: 50,
     quadrature: 4, encoder_sign: 1, photocell_at_mm: 300, reflectance: 0.3}}
feeders:
  - {{belt: belt1, classes: [dip14, dip16], period_s: {}, start_mm: 40, lateral_mm: 60,
     yaw_deg: [-90, 90], count: 1000, seed: 3}}
)",
                     speed_mm_s, period_s);
}

inline double wrap_deg(double d, double period) {
  d = std::fmod(d, period);
  if (d > period / 2) {
    d -= period;
  } else if (d < -period / 2) {
    d += period;
  }
  return d;
}

/// The cell with its helpers: start it, calibrate, submit, read jobs and the truth.
class TaskCellTest : public TaskCell {
 protected:
  /// Starts the cell. `calibration`: the shipped config with its store in the test's dir.
  void start_cell(const std::string& scene_file) {
    start("sim-world", "cell-sim-world",
          write("sim-world.yaml",
                fmt::format("service: {{id: sim-world}}\nscene: {}\n"
                            "robots:\n  - {{id: ibm7545, xyz_mm: [0, 0, {}]}}\n"
                            "  - {{id: scara_picker, xyz_mm: [{}, 0, {}]}}\n",
                            scene_file, k7545BaseZ, kPickerBaseX, kPickerBaseZ)));
    start("gateway", "cell-gateway",
          write("gateway.yaml", "service: {id: gateway.ibm7545}\n"
                                "robot_config: config/robots/ibm7545.yaml\n"
                                "driver: {kind: ideal, initial_joints: [45, 105, 0, 0], "
                                "gripper_time_s: 0.2}\n"));
    start("gateway-picker", "cell-gateway", "config/gateway-picker.yaml");
    start("motion", "cell-motion", "config/motion.yaml");
    start("camera", "cell-camera", "config/camera-ibm7545.yaml");
    start("belt-camera", "cell-camera", "config/camera-belt.yaml");
    start("vision", "cell-vision", "config/vision.yaml");
    start("calibration", "cell-calibration", calibration_config());
    start_task();
    ASSERT_TRUE(eventually([&] { return cellctl({"jobs"}).exit.code == 0; }, 30s)) << logs();
    ASSERT_TRUE(eventually([&] { return cellctl({"calibration", "list"}).exit.code == 0; }, 30s))
        << logs();
  }

  std::string calibration_config() {
    std::ifstream f(cell::testing::source_dir() + "/config/calibration.yaml");
    std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    const std::string key = "store_dir: run/calibrations";
    const auto at = text.find(key);
    EXPECT_NE(at, std::string::npos);
    if (at != std::string::npos) {
      text.replace(at, key.size(), "store_dir: " + dir_ + "/store");
    }
    return write("calibration.yaml", text);
  }

  void start_task() {
    std::ifstream f(cell::testing::source_dir() + "/config/task.yaml");
    std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    const std::string key = "journal: run/task/journal.sqlite";
    const auto at = text.find(key);
    ASSERT_NE(at, std::string::npos);
    text.replace(at, key.size(), "journal: " + dir_ + "/journal.sqlite");
    const std::string path = write("task.yaml", text);
    start("task", "cell-task", path);
  }

  /// The simulator's truth as the camera's calibration, in the calibration service's store
  /// (for tests whose subject is not calibration); the service is restarted to publish it.
  void store_truth_calibration(const std::string& camera_id, const std::string& robot_id,
                               const Eigen::Isometry3d& world_T_base, double plane_z) {
    auto camera = render::load_camera(cell::testing::source_dir() + "/config/cameras/" +
                                      camera_id + ".yaml");
    ASSERT_TRUE(camera) << camera.error().message;
    render::CameraDescription truth = *camera;
    truth.nominal = camera->truth;
    auto c = cal::nominal_calibration(truth, robot_id, world_T_base, plane_z);
    ASSERT_TRUE(c) << c.error().message;
    c->source = "the simulator's truth (test)";
    cal::CalibrationStore store(dir_ + "/store");
    auto stored = store.add_camera(*c);
    ASSERT_TRUE(stored) << stored.error().message;
  }

  /// Board images through the camera's TRUE model, then intrinsics and the guided hand-eye.
  void calibrate_7545_camera_from_scratch() {
    cal::BoardSpec board;
    board.columns = 17;
    board.rows = 12;
    board.square_mm = 6.0;
    const render::CameraDescription camera = cal::testing::camera_file("ibm7545_eye.yaml");
    const std::vector<cv::Mat> images = cal::testing::intrinsics_images(camera, board, 420.0);
    std::filesystem::create_directories(dir_ + "/board");
    for (std::size_t i = 0; i < images.size(); ++i) {
      cv::imwrite(fmt::format("{}/board/view{:02d}.png", dir_, i), images[i]);
    }
    ToolRun r = cellctl({"calibrate", "intrinsics", "--camera", "ibm7545_eye", "--images",
                         dir_ + "/board", "--board", "17x12", "--square", "6"},
                        180s);
    ASSERT_EQ(r.exit.code, 0) << r.output;
    ASSERT_TRUE(eventually(
        [&] { return cellctl({"robot", "home", "--robot", "ibm7545"}).exit.code == 0; }, 30s));
    r = cellctl({"--json", "calibrate", "hand-eye", "--camera", "ibm7545_eye", "--wait", "600"},
                700s);
    ASSERT_EQ(r.exit.code, 0) << r.output;
    std::printf("hand-eye from scratch: %s\n", r.output.substr(0, 400).c_str());
  }

  ToolRun submit(const std::string& file, const std::string& id) {
    return cellctl({"submit", file, "--id", id}, 30s);
  }

  /// The job's status, or an empty object while cellctl cannot get one (the task service
  /// restarting after a kill, a status that did not parse).
  json job(const std::string& id) {
    json j = parsed(cellctl({"--json", "job", id}));
    return j.is_object() ? j : json::object();
  }

  /// Waits for the job's end; returns its last status.
  json wait_end(const std::string& id, std::chrono::seconds limit) {
    json last;
    (void)eventually(
        [&] {
          last = job(id);
          const std::string state = last.value("state", "");
          return state == "succeeded" || state == "failed" || state == "cancelled";
        },
        limit);
    return last;
  }

  /// The table job's slots (the shipped example's grid), in the world frame.
  static std::vector<Eigen::Vector2d> table_slots() {
    std::vector<Eigen::Vector2d> out;
    for (int row = 0; row < 5; ++row) {
      for (int col = 0; col < 3; ++col) {
        out.emplace_back(-310.0 + 30.0 * col, 250.0 + 30.0 * row);
      }
    }
    return out;
  }

  /// Every part in a slot (one part per slot) within 0.5 mm and 1 degree (ICs are symmetric
  /// under a half turn: yaw 90 and -90 are the same placement).
  void expect_all_in_slots(std::size_t count) {
    const json parts = world_parts();
    ASSERT_EQ(parts.size(), count);
    std::set<std::size_t> used;
    double worst_mm = 0, worst_deg = 0;
    for (const json& p : parts) {
      const Eigen::Vector2d at(p["pose"]["x_mm"].get<double>(), p["pose"]["y_mm"].get<double>());
      const auto slots = table_slots();
      std::size_t best = slots.size();
      double best_d = 1e9;
      for (std::size_t i = 0; i < slots.size(); ++i) {
        const double d = (slots[i] - at).norm();
        if (d < best_d) {
          best_d = d;
          best = i;
        }
      }
      EXPECT_LT(best_d, 0.5) << p.dump();
      EXPECT_TRUE(used.insert(best).second) << "two parts in slot " << best << ": " << p.dump();
      const double yaw_err = std::abs(wrap_deg(p["pose"]["yaw_deg"].get<double>() - 90.0, 180.0));
      EXPECT_LT(yaw_err, 1.0) << p.dump();
      EXPECT_EQ(p["support"], "table");
      worst_mm = std::max(worst_mm, best_d);
      worst_deg = std::max(worst_deg, yaw_err);
    }
    std::printf("parts in their slots: worst %.3f mm, %.3f deg (bounds 0.5 mm, 1 deg)\n",
                worst_mm, worst_deg);
  }

  /// Kills cell-task (SIGKILL) up to `max_kills` times while job `id` runs, each after a
  /// random pause of `min_ms`..`max_ms` (seeded: the same moments every run), and starts it
  /// again each time. Returns how many kills there were.
  int kill_task_during(const std::string& id, int max_kills, unsigned seed, int min_ms,
                       int max_ms) {
    std::mt19937 rng(seed);
    std::uniform_int_distribution<int> pause_ms(min_ms, max_ms);
    int kills = 0;
    for (; kills < max_kills; ++kills) {
      std::this_thread::sleep_for(std::chrono::milliseconds(pause_ms(rng)));
      const std::string state = job(id).value("state", "");
      if (state == "succeeded" || state == "failed") {
        break;
      }
      process::Child* task = child(kills == 0 ? "task" : fmt::format("task{}", kills));
      if (task == nullptr) {
        ADD_FAILURE() << "no task process to kill";
        break;
      }
      EXPECT_EQ(::kill(task->pid(), SIGKILL), 0);
      (void)task->wait_for(5s);
      start(fmt::format("task{}", kills + 1), "cell-task", dir_ + "/task.yaml");
    }
    std::printf("killed cell-task %d times during job %s\n", kills, id.c_str());
    return kills;
  }

  /// How many times sim-world attached a part to a gripper (every grasp that took a part).
  std::size_t grasps_in_world_log() { return grasps_seen_by_the_world().taken.size(); }

  /// Every closing of a gripper as sim-world saw it: for each part taken, and for each grasp
  /// on nothing, the nearest grasp point seen from the tool (world frame, mm).
  struct GraspsSeen {
    std::vector<Eigen::Vector3d> taken;
    std::vector<Eigen::Vector3d> missed;
  };
  GraspsSeen grasps_seen_by_the_world() {
    const std::string all = output_of("sim-world");
    GraspsSeen out;
    std::istringstream lines(all);
    for (std::string line; std::getline(lines, line);) {
      const bool taken = line.find("event=attached") != std::string::npos;
      const bool missed = line.find("code=world.pick_missed") != std::string::npos;
      if (!taken && !missed) {
        continue;
      }
      Eigen::Vector3d d = Eigen::Vector3d::Constant(std::nan(""));
      const auto at = line.find("from the tool: ");
      if (at != std::string::npos) {
        (void)std::sscanf(line.c_str() + at, "from the tool: %lf, %lf, %lf", &d.x(), &d.y(),
                          &d.z());
      }
      (taken ? out.taken : out.missed).push_back(d);
    }
    return out;
  }
};

}  // namespace cell::task_test
