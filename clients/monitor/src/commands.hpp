#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "cell/bus/idl_types.hpp"
#include "cell/common/result.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "codec.hpp"
#include "monitor_config.hpp"

/// The commands a signed-in operator sends from the page, parsed and checked before anything
/// is published. Pure functions over the request's JSON: every malformed or unsafe request
/// becomes a kInvalidArgument / kOutOfRange error naming the field and what was wrong (the
/// bridge answers it with 400 and the message); none throws.
namespace cell::monitor {

/// A MotionRequest to send (or preview).
struct MotionCommand {
  std::string robot_id;
  cell_motion_MotionKind kind = cell_motion_MOTION_MOVE_JOINTS;
  kinematics::JointVector joints;  ///< MOVE_JOINTS target [rad, mm]
  Eigen::Isometry3d target = Eigen::Isometry3d::Identity();  ///< base_T_tool [mm]
  double distance_mm = 0.0;  ///< APPROACH distance
  double speed_scale = 0.5;  ///< (0, 1]
  bool preview = false;      ///< plan only
  std::string what;          ///< for logs and replies: "jog j2 +5 deg", "pose ...", ...
};

/// Parses POST /api/motion. Body: {"robot": id, "speed": (0,1] (default 0.5), "preview": bool,
/// and exactly one of
///   "joints": [..] in display units (deg for revolute, mm for prismatic joints),
///   "jog": {"space": "joint", "joint": <name or index>, "delta": <deg|mm>},
///   "jog": {"space": "base"|"tool", "axis": "x"|"y"|"z"|"rx"|"ry"|"rz", "delta": <mm|deg>},
///   "pose": {"xyz_mm": [3], "rpy_deg": [3], "line": bool} (base_T_tool),
///   "stop": true}.
/// Jogs start from `latest` (the robot's newest RobotState): without one they are refused.
/// Joint targets are checked against the joint limits (kOutOfRange naming the joint).
Result<MotionCommand> parse_motion(const nlohmann::json& body, const kinematics::RobotModel& model,
                                   const RobotSample* latest);

/// Parses POST /api/robot/command: {"robot": id, "command": "home"|"open"|"close"|"stop"|
/// "reset"}. The robot must be one of `robots`.
struct RobotCommandSpec {
  std::string robot_id;
  cell_robot_RobotCommandKind kind = cell_robot_CMD_STOP;
  std::string name;  ///< the command word
};
Result<RobotCommandSpec> parse_robot_command(const nlohmann::json& body,
                                             const std::vector<std::string>& robots);

/// A JobRequest made from a template.
struct JobSpec {
  std::string job_id;
  cell_task_JobKind kind = cell_task_JOB_TABLE_PICK_PLACE;
  const JobTemplate* job_template = nullptr;  ///< points into the config's templates
};
/// Parses POST /api/job/submit: {"template": name, "job_id": optional [A-Za-z0-9_.-]{1,64}}
/// (default "<template>-<wall clock ms>").
Result<JobSpec> parse_job_submit(const nlohmann::json& body,
                                 const std::vector<JobTemplate>& templates,
                                 std::int64_t now_ms);
/// "table_pick_place" -> JOB_TABLE_PICK_PLACE, ... Errors: kInvalidArgument.
Result<cell_task_JobKind> job_kind_from_name(const std::string& name);

/// Parses POST /api/job/command: {"job_id": id, "command": "pause"|"resume"|"cancel"|"confirm"}.
struct JobCommandSpec {
  std::string job_id;
  cell_task_JobCommandKind kind = cell_task_JOB_CANCEL;
  std::string name;
};
Result<JobCommandSpec> parse_job_command(const nlohmann::json& body);

/// The tool pose (base frame) that grasps at `world_T_grasp`, for a robot standing at
/// `world_T_base`: base_T_tool = world_T_base^-1 * world_T_grasp, with the tool's z axis turned
/// to how the robot reaches (up for a SCARA, whose tool z is the base z; down into the part
/// for a 6-axis arm, Paul's approach vector). Errors: kInvalidArgument for a non-rigid pose.
Result<Eigen::Isometry3d> grasp_tool_pose(const kinematics::RobotModel& model,
                                          const Eigen::Isometry3d& world_T_base,
                                          const Eigen::Isometry3d& world_T_grasp);

/// Reads a required string field. Errors: kInvalidArgument "missing field 'robot'" or
/// "field 'robot' must be a string".
Result<std::string> string_field(const nlohmann::json& body, const char* key);

/// A finite number field that may be absent or null (then `fallback`), within [lo, hi].
/// Errors: kInvalidArgument "field 'speed' must be a number"; kOutOfRange "field 'speed' must be
/// in [0.01, 1], got 2" (with `unit` after the range when not empty).
Result<double> number_field(const nlohmann::json& body,
                            const char* key,
                            double fallback,
                            double lo,
                            double hi,
                            std::string_view unit);

/// [A-Za-z0-9_.-]{1,64}: ids and file names the bridge accepts from the page.
bool safe_name(const std::string& text) noexcept;

}  // namespace cell::monitor
