#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "cell/bus/idl_types.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/render/camera_file.hpp"

/// JSON for the browser: the bus's messages and the cell's models, in the units of the IDL
/// (mm, rad, s; keys carry their unit) so the page converts for display only. Pure functions:
/// malformed samples (non-finite numbers, bad quaternions) become nulls, never exceptions.
namespace cell::monitor {

using nlohmann::json;

/// {"p": [x, y, z] (mm), "q": [w, x, y, z]}.
json pose_json(const Eigen::Isometry3d& pose);
/// The same from an IDL pose (normalised); null when it is not a pose.
json pose_json(const cell_common_Pose& pose);

/// A robot's geometry for the page's 3-D model and forward kinematics (the JS FK implements
/// the same equations as core/kinematics from these numbers): id, kind, joints (name, type,
/// lower, upper [rad|mm], max_speed), the kind's parameters (scara: link1_mm, link2_mm,
/// z_down, z_at_zero_mm, roll_world, roll_clockwise; excalibur: d1_mm, a2_mm, d4_mm, d6_mm,
/// controller_offset_rad), flange_T_tool, branch names, and world_T_base.
json robot_model_json(const kinematics::RobotModel& model, const Eigen::Isometry3d& world_T_base);

/// A camera for the page's frustums and overlays: id, mount (fixed | eye_in_hand, robot,
/// frame), the nominal intrinsics (fx_px, fy_px, cx_px, cy_px, width_px, height_px) and pose
/// (world_T_camera or mount_T_camera), world_T_base of the carrying robot.
json camera_json(const render::CameraDescription& camera);

/// One robot's latest state, as the browser sees it (coalesced to its frame rate).
struct RobotSample {
  std::string robot_id;
  std::int64_t stamp_ns = 0;     ///< header stamp: when the joints were read (wall clock)
  std::int64_t received_ns = 0;  ///< when the bridge took it (wall clock)
  std::vector<double> q;         ///< rad / mm
  std::vector<double> setpoint;  ///< rad / mm
  Eigen::Isometry3d base_T_tool = Eigen::Isometry3d::Identity();
  bool pose_valid = false;
  int mode = 0;
  int gripper = 0;
  bool homed = false;
  bool moving = false;
  bool tracking = false;
  double progress = 0.0;
  std::string trajectory_id;
  std::string fault_text;
  double jitter_max_us = 0.0;
  std::uint64_t overruns = 0;
  std::uint64_t seq = 0;  ///< header seq
};

/// Copies what the page needs out of a (loaned) RobotState.
RobotSample to_sample(const cell_robot_RobotState& state, std::int64_t received_ns);

/// {"id", "stamp_ns", "received_ns", "seq", "q", "setpoint", "base_T_tool", "mode", "gripper",
/// "homed", "moving", "tracking", "progress", "trajectory_id", "fault", "jitter_max_us",
/// "overruns"}; mode and gripper as names ("idle", "open", ...).
json sample_json(const RobotSample& sample);

/// "idle", "moving", ...; "open", "closed", ...; "serving", ...; "info", "warning", ...
std::string_view mode_name(int mode) noexcept;
std::string_view gripper_name(int gripper) noexcept;
std::string_view health_name(int state) noexcept;
std::string_view severity_name(int severity) noexcept;
std::string_view motion_state_name(int state) noexcept;
std::string_view job_state_name(int state) noexcept;
std::string_view job_kind_name(int kind) noexcept;
std::string_view part_outcome_name(int outcome) noexcept;

json heartbeat_json(const cell_health_ServiceHeartbeat& hb);
json event_json(const cell_health_CellEvent& event);
/// MotionStatus without its path (the path goes only to the one who asked for a preview).
json motion_status_json(const cell_motion_MotionStatus& status);
json job_status_json(const cell_task_JobStatus& status);
/// Parts (id, class, shape name, sizes, pins, pose, grasp pose in the world, support, mesh for
/// polyhedra) and belts (id, travel, speed, origin, direction, sizes, photocell).
json world_json(const cell_world_WorldState& world);
json detections_json(const cell_vision_Detections& detections);
json camera_calibration_json(const cell_calibration_CameraCalibration& c);
json belt_calibration_json(const cell_calibration_BeltCalibration& c);

/// A finite number or null (JSON has no NaN).
json number(double value);

/// One line of JSON. Text from the bus that is not valid UTF-8 is replaced (U+FFFD), never
/// thrown on: a bad string in a sample must not take the bridge down.
std::string to_text(const json& value);

/// A RAPT LOOK's edge measurement (EdgeResult) for the image overlay: the search window the
/// suggester proposed (p1 -> p2 across the edge, p1 -> p3 along it), the edge found, residual.
json edge_result_json(const cell_vision_EdgeResult& result);

/// "dip", "rectangle", ... of a WorldPart shape.
std::string_view shape_name(int shape) noexcept;

}  // namespace cell::monitor
