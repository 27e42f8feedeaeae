#pragma once

#include <array>
#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/protocols/excalibur/simulated_controller.hpp"
#include "cell/service/runtime.hpp"

namespace cell::sim_excalibur {

/// config/sim-excalibur.yaml (every key is described in the shipped file and the README).
/// Angles in the file are DH angles in degrees (the robot's own convention); the simulator
/// converts them to the controller's angles (theta2* = theta2 - 30, theta3* = theta3 + 150).
struct SimExcaliburConfig {
  service::CommonConfig common;
  std::string robot_config = "config/robots/excalibur.yaml";
  std::string dialect = "config/controllers/excalibur.yaml";
  std::string link_path = "run/excalibur.pty";  ///< the pty's slave is published here
  int baud = 9600;                              ///< emulated line speed of the output
  bool emulate_baud = true;
  /// SCHED_FIFO priority of the controller's thread (0: normal scheduling; refused without
  /// root, with a warning). It stands for a controller that owns its processor.
  int realtime_priority = 0;
  std::string robot_id = "excalibur.sim";  ///< RobotState id of the true angles
  double state_rate_hz = 20.0;

  // controller:
  std::optional<std::array<double, 6>> initial_deg;  ///< DH; default: controller zero q* = 0
  std::optional<std::array<double, 6>> master_deg;   ///< DH; default: the initial angles
  /// Per joint [lower, upper] DH degrees, overriding the robot's limits as the controller's
  /// own (a controller stricter than the model makes "move not achieved (limits)").
  std::array<std::optional<std::array<double, 2>>, 6> limits_deg{};
  double speed_scale = 1.0;  ///< x the robot's max_speed_deg_s: a faster arm for tests
  double accuracy_deg = 0.3;
  std::array<double, 6> bias_deg{};
  bool own_check = true;
  double min_char_interval_ms = 1.2;
  double busy_after_line_ms = 8.0;
  double reply_delay_ms = 2.0;
  double gripper_time_s = 0.5;
  protocols::excalibur::Mode power_up_mode = protocols::excalibur::Mode::kHost;
  std::uint64_t seed = 1;

  // noise:
  protocols::excalibur::NoiseSettings noise;
  double move_not_achieved_probability = 0.0;
  /// Run-time trigger: a YAML file with probability_per_line, probability_per_byte and
  /// move_not_achieved_probability; its values replace the config's while it exists (checked
  /// every 0.2 s). Empty: no trigger.
  std::string control_file = "run/excalibur-noise.yaml";
};

/// Parses and validates the config; relative paths are resolved against CELL_HOME.
/// Errors: kConfig, "file:line:col: key 'a.b': ...".
Result<SimExcaliburConfig> load_config(const config::Document& doc);

/// The run-time noise settings in a control file. Errors: kConfig with file:line:col.
struct NoiseControl {
  protocols::excalibur::NoiseSettings noise;
  double move_not_achieved_probability = 0.0;
};
Result<NoiseControl> load_noise_control(const std::string& path);

/// The controller settings the config describes for `model` (controller angles).
Result<protocols::excalibur::ControllerSettings> controller_settings(
    const SimExcaliburConfig& config, const kinematics::RobotModel& model);

/// The Excalibur controller simulator: a SimulatedController on a pseudo-terminal whose slave
/// is published at link_path, plus the true joint angles on the bus (cell/robot/state, and
/// cell/robot/state_latest at 2 Hz, robot_id `robot_id`). Throws std::runtime_error when the
/// robot, the dialect or the pty cannot be set up.
class SimExcaliburService {
 public:
  SimExcaliburService(service::Context& ctx, const SimExcaliburConfig& config);
  void run(service::Context& ctx);

  /// The running controller (tests read its status).
  protocols::excalibur::SimulatedController& controller() { return *sim_; }

 private:
  void publish(const bus::Writer<cell_robot_RobotState>& writer);
  void check_control_file();
  void apply(const protocols::excalibur::NoiseSettings& noise,
             double not_achieved,
             const char* source);

  SimExcaliburConfig config_;
  kinematics::RobotModel model_;
  std::unique_ptr<protocols::excalibur::SimulatedController> sim_;
  bus::Topic<cell_robot_RobotState> state_topic_;
  bus::Topic<cell_robot_RobotState> latest_topic_;
  bus::Writer<cell_robot_RobotState> state_writer_;
  bus::Writer<cell_robot_RobotState> latest_writer_;
  std::uint64_t seq_ = 0;
  std::optional<std::filesystem::file_time_type> control_mtime_;
  std::chrono::steady_clock::time_point next_control_check_{};
};

}  // namespace cell::sim_excalibur
