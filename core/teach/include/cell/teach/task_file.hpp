#pragma once

#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/config/yaml.hpp"
#include "cell/kinematics/robot_model.hpp"

/// Task files: the EXCAL thesis's teach and playback (digest 001 §5, §8.1 "Task service"): a
/// sequence of recorded arm poses and gripper steps, edited (insert, delete, reorder), stepped
/// through forward and back or run, off line (preview) or on the robot. The file is YAML that
/// a person can read and edit (config/tasks/*.yaml, keys in core/teach/README.md):
///
///   task: pick_ic8               # a name
///   robot: ibm7545               # config/robots/<robot>.yaml: joint names and units
///   speed_scale: 0.5             # default fraction of the robot's speed limits, (0, 1]
///   steps:
///     - pose: above_ic8          # a recorded pose: joints in display units (deg, mm)
///       joints: {j1_deg: 41.2, j2_deg: 98.7, z_mm: 200.0, r_deg: 116.0}
///       tool: {xyz_mm: [134.4, 501.3, -200.0], rpy_deg: [0.0, 0.0, -116.0]}   # FK, informative
///       move: joint              # joint (default) or line (straight tool line)
///       speed_scale: 0.3         # optional, overrides the task's
///     - gripper: close           # a relative gripper step (EXCAL's own files, digest 001 §5)
///     - wait_s: 0.5              # a pause
///
/// Units: joints are rad/mm inside (kinematics::JointVector), degrees/mm in the file with the
/// unit in each key (`<joint>_deg` for revolute, `<joint>_mm` for prismatic joints).
/// Frames: `tool` is base_T_tool in the robot's base frame (mm, URDF rpy in deg), recomputed by
/// FK from the joints on every save; on load it is checked against the joints' FK.
namespace cell::teach {

/// How a pose step is reached from the pose before it.
enum class MoveKind : std::uint8_t {
  kJoint,  ///< "joint": joint-interpolated (MotionKind MOVE_JOINTS)
  kLine,   ///< "line": straight line of the tool point (MOVE_LINEAR) to the step's tool pose
};

/// A gripper step. Relative (open or close from whatever it is), as EXCAL's own task files
/// stored it (digest 001 §5), not the controller teach files' absolute state.
enum class GripperAction : std::uint8_t { kOpen, kClose };

/// "joint" / "line"; "open" / "close".
std::string_view to_string(MoveKind kind) noexcept;
std::string_view to_string(GripperAction action) noexcept;

/// A recorded arm pose.
struct PoseStep {
  std::string name;                ///< unique within the task ("p1", "above_ic8")
  kinematics::JointVector joints;  ///< rad / mm, the robot's joint order
  MoveKind move = MoveKind::kJoint;
  double speed_scale = 0.0;  ///< (0, 1]; 0: the task's speed_scale
};

/// Open or close the gripper.
struct GripperStep {
  GripperAction action = GripperAction::kOpen;
};

/// Hold still for a while.
struct WaitStep {
  double duration_s = 0.0;  ///< >= 0
};

/// One line of a task.
using Step = std::variant<PoseStep, GripperStep, WaitStep>;

/// "pose 'p1' (joint)", "gripper close", "wait 0.50 s": a step for people.
std::string describe(const Step& step);

/// A task: its robot and its steps. A plain value; the robot model it was checked against is
/// not kept (load it again from `robot_id`).
struct Task {
  std::string name;          ///< `task:`
  std::string robot_id;      ///< `robot:`, e.g. "ibm7545"
  std::string description;   ///< `description:` (optional free text)
  double speed_scale = 0.5;  ///< `speed_scale:` default for pose steps, (0, 1]
  std::vector<Step> steps;

  /// Inserts `step` before index `at` (at == steps.size() appends). Errors: kOutOfRange naming
  /// the index and the valid range; kInvalidArgument when a pose step's name is empty or used.
  Status insert(std::size_t at, Step step);
  /// Appends `step` (as insert(steps.size(), step)).
  Status append(Step step);
  /// Removes step `at`. Errors: kOutOfRange naming the index and the number of steps.
  Status remove(std::size_t at);
  /// Moves step `from` to index `to` (the others shift). Errors: kOutOfRange.
  Status move(std::size_t from, std::size_t to);
  /// Renames pose step `at`. Errors: kOutOfRange, kInvalidArgument (not a pose, name taken).
  Status rename(std::size_t at, const std::string& new_name);
  /// Index of the pose step called `name`, or nullopt.
  std::optional<std::size_t> find(const std::string& pose_name) const;
  /// A pose name not used yet: "p<n>" with the smallest n >= number of pose steps + 1.
  std::string next_pose_name() const;
  /// Number of pose steps.
  std::size_t pose_count() const;

  /// Ok when every pose has the robot's dof, finite joints within their limits, a unique
  /// non-empty name and a speed scale in [0, 1]; the task's speed_scale is in (0, 1]; waits are
  /// finite and >= 0. Errors: kInvalidArgument or kOutOfRange naming the step (1-based, as
  /// people count lines: "step 3 (pose 'p2'): joint 'j2' = 137.200 deg is outside ...").
  Status validate(const kinematics::RobotModel& model) const;
};

/// Loads a robot model by id ("ibm7545" -> config/robots/ibm7545.yaml).
using RobotLookup = std::function<Result<kinematics::RobotModel>(const std::string& robot_id)>;

/// The default lookup: kinematics::load_robot(service::resolve_path("config/robots/<id>.yaml")).
/// Errors: kInvalidArgument for an id with '/', '.' or empty; the loader's kConfig errors.
Result<kinematics::RobotModel> load_robot_by_id(const std::string& robot_id);

/// Parses a task document (strict: unknown keys, a missing key, a joint missing or unknown for
/// the robot, a wrong unit suffix ("j1_mm" on a revolute joint), a tool pose that disagrees
/// with the joints' FK by more than 0.1 mm / 0.01 deg, and every rule of Task::validate are
/// errors). Errors: kConfig with every problem, one per line, "file:line:col: key
/// 'steps[2].joints.j1_deg': what". `lookup` resolves `robot:`; its error is reported at the
/// robot key. `model_out`, when given, receives the robot model.
Result<Task> parse_task(const config::Document& doc, const RobotLookup& lookup = load_robot_by_id,
                        kinematics::RobotModel* model_out = nullptr);

/// Reads and parses a task file (config::load_file + parse_task).
Result<Task> load_task(const std::string& path, const RobotLookup& lookup = load_robot_by_id,
                       kinematics::RobotModel* model_out = nullptr);

/// The task as YAML (the format above, with a header comment). Errors: Task::validate's.
Result<std::string> to_yaml(const Task& task, const kinematics::RobotModel& model);

/// Writes to_yaml(task) to `path` atomically (a temporary file beside it, then rename), so a
/// crash never leaves half a task. Errors: validate's, kIo naming the path and errno.
Status save_task(const std::string& path, const Task& task, const kinematics::RobotModel& model);

/// A pose step recording the robot at joints `q` (rad/mm) under `name` ("" picks
/// task.next_pose_name()). Errors: kInvalidArgument for a wrong-sized or non-finite q;
/// kOutOfRange when q is outside the joint limits (a robot outside its limits cannot be
/// taught there).
Result<PoseStep> record_pose(const Task& task, const kinematics::RobotModel& model,
                             const kinematics::JointVector& q, const std::string& name = {},
                             MoveKind move = MoveKind::kJoint);

}  // namespace cell::teach
