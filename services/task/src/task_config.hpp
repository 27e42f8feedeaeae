#pragma once

#include <chrono>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/config/yaml.hpp"
#include "cell/service/common_config.hpp"

namespace cell::task_service {

struct RobotEntry {
  std::string id;
  std::string config;  ///< config/robots/<id>.yaml, resolved
  std::string gateway;  ///< service id of its gateway (heartbeat watched); default gateway.<id>
};

/// A camera the task service uses: which robot picks what it sees and the plane the parts lie
/// on (in that robot's base frame), for the grasp heights.
struct CameraEntry {
  std::string id;
  std::string robot;
  double working_plane_z_mm = 0.0;
  std::string service;  ///< service id of the camera (heartbeat watched); default camera.<id>
};

/// A belt's NOMINAL geometry in a robot's base frame, used until the calibration service
/// publishes a BeltCalibration for it (then that one is used, and re-read when it changes).
struct BeltEntry {
  std::string id;
  std::string robot;
  double mm_per_count = 0.0;                             ///< > 0
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();  ///< travel for increasing counts, unit
  /// The point of the belt's centre line nearest the robot base, at the surface [mm]: the
  /// conveyor belt window is measured along `direction` from it.
  Eigen::Vector3d nearest_mm = Eigen::Vector3d::Zero();
};

/// config/task.yaml (services/task/README.md lists every key).
struct TaskConfig {
  service::CommonConfig common;
  std::string journal = "run/task/journal.sqlite";  ///< resolved against CELL_HOME
  std::vector<RobotEntry> robots;
  std::vector<CameraEntry> cameras;
  std::vector<BeltEntry> belts;
  /// Scene files whose own part classes the task must know (besides the built-in catalogue),
  /// e.g. the conveyor scene's `la_part`; resolved.
  std::vector<std::string> scenes;
  double motion_timeout_s = 120.0;   ///< a motion that does not end in this long fails
  double locate_timeout_s = 5.0;     ///< an image + its detections must come in this long
  double photocell_timeout_s = 30.0; ///< conveyor: no part arriving for this long ends a wait
  double robot_state_timeout_s = 5.0;
  /// Service ids the jobs need besides each robot's gateway and each camera (`services:`):
  /// their heartbeats are watched, and a job pauses while one is lost or absent.
  std::string motion_service = "motion";
  std::string vision_service = "vision";
  double status_period_s = 0.5;      ///< JobStatus of running jobs at least this often
  int keep_finished = 200;           ///< finished jobs kept on the status topic
};

/// Parses and validates config/task.yaml. Errors: kConfig, "file:line:col: key ...".
Result<TaskConfig> load_config(const config::Document& doc);

}  // namespace cell::task_service
