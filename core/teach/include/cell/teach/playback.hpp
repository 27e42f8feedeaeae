#pragma once

#include <cstddef>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/motion/planner.hpp"
#include "cell/teach/task_file.hpp"

/// Playback of task files: line by line forward or backward, or continuously, off line (the
/// thesis's simulation, planned here with core/motion's Planner, the motion service's own
/// planner) or on the robot through a StepRunner (bus_runner.hpp). Digest 001 §5: "Playback
/// runs line by line (forward or backward) or continuously, off-line or with download to the
/// arm."
namespace cell::teach {

/// Which way a step is taken.
enum class Direction : std::uint8_t { kForward, kBackward };

/// What taking one step means for the robot.
struct Action {
  enum class Kind : std::uint8_t {
    kMove,     ///< move to `joints` (joint or line move)
    kGripper,  ///< open or close the gripper
    kWait,     ///< hold still `wait_s`
    kNone,     ///< nothing to do (stepping back over the first pose, or over a wait)
  };
  Kind kind = Kind::kNone;
  std::size_t step_index = 0;  ///< the step taken (0-based)
  std::string pose_name;       ///< kMove: the target pose's name
  MoveKind move = MoveKind::kJoint;
  kinematics::JointVector joints;  ///< kMove: target joints [rad, mm]
  Eigen::Isometry3d base_T_tool = Eigen::Isometry3d::Identity();  ///< kMove: FK of joints [mm]
  double speed_scale = 0.5;                                       ///< kMove, (0, 1]
  GripperAction gripper = GripperAction::kOpen;                   ///< kGripper
  double wait_s = 0.0;                                            ///< kWait

  /// "step 3: move (joint) to 'p2'", "step 4: gripper close", "step 2: nothing to undo".
  std::string describe() const;
};

/// The action of taking step `index` in `direction`. Forward: the step as recorded. Backward
/// (undo the step, so the cell returns to its state before it): over a pose step, move back
/// to the pose before it (kNone when it is the first pose); over a gripper step, the opposite
/// gripper action (relative steps, digest 001 §5); over a wait, kNone.
/// Errors: kOutOfRange for an index past the end; FK errors (kInvalidArgument) for a pose.
Result<Action> action_for(const Task& task, const kinematics::RobotModel& model, std::size_t index,
                          Direction direction);

/// A position between steps: 0 before the first, steps.size() after the last. Stepping
/// forward takes step position() and advances; stepping backward undoes step position() - 1
/// and retreats. Not thread-safe; a plain value.
class Cursor {
 public:
  explicit Cursor(std::size_t position = 0) : position_(position) {}
  std::size_t position() const noexcept { return position_; }
  /// The next action forward, or kOutOfRange at the end. Does not move the cursor: call
  /// advance() once the action succeeded.
  Result<Action> peek_forward(const Task& task, const kinematics::RobotModel& model) const;
  /// The next action backward, or kOutOfRange at the start. Does not move the cursor.
  Result<Action> peek_backward(const Task& task, const kinematics::RobotModel& model) const;
  void advance() noexcept { ++position_; }
  void retreat() noexcept {
    if (position_ > 0) {
      --position_;
    }
  }
  /// Clamps the cursor to [0, steps] after an edit.
  void clamp(const Task& task) noexcept;
  /// Jumps to `position`. Errors: kOutOfRange beyond steps.size().
  Status seek(const Task& task, std::size_t position);

 private:
  std::size_t position_ = 0;
};

/// What a runner reports for one action.
struct StepOutcome {
  double duration_s = 0.0;                     ///< planned (move) or waited duration
  std::optional<kinematics::JointVector> final_joints;  ///< where the arm ended (moves)
  std::vector<Eigen::Isometry3d> path;         ///< previews: sampled base_T_tool of the plan
};

/// Executes actions for one robot: on the bus (BusRunner) or in tests a fake.
class StepRunner {
 public:
  StepRunner() = default;
  StepRunner(const StepRunner&) = delete;
  StepRunner& operator=(const StepRunner&) = delete;
  virtual ~StepRunner() = default;
  /// Runs `action` to its end (a move until done, a gripper until acknowledged, a wait until
  /// over). Errors say which step failed and why (refused, failed, timeout, cancelled).
  virtual Result<StepOutcome> run(const Action& action) = 0;
};

/// Progress of a playback: called before each action with its index in the run (0-based) and
/// the number of actions of the run.
using PlaybackObserver = std::function<void(const Action& action, std::size_t done,
                                            std::size_t total)>;

/// How much of a task to play.
struct PlaybackOptions {
  std::size_t from = 0;                      ///< first step (0-based)
  std::optional<std::size_t> to;             ///< one past the last step; nullopt: the end
  Direction direction = Direction::kForward;  ///< backward: undo steps to-1 .. from
  double speed_override = 0.0;               ///< (0, 1] scales every pose's speed; 0: as recorded
};

/// What a playback did.
struct PlaybackReport {
  std::size_t steps_done = 0;    ///< actions completed
  std::size_t steps_total = 0;   ///< actions the run had
  double duration_s = 0.0;       ///< sum of the actions' durations
  std::optional<std::size_t> failed_step;  ///< the step (0-based) that failed, if any
  std::string message;           ///< "" or why it stopped
  std::optional<kinematics::JointVector> final_joints;  ///< of the last move done

  bool ok() const noexcept { return !failed_step.has_value() && message.empty(); }
  /// "7/7 steps in 12.3 s" or "stopped at step 4 (pose 'p3'): refused: ...".
  std::string brief() const;
};

/// Plays steps [from, to) through `runner`, stopping at the first failure (reported, never
/// thrown). Errors (before anything runs): kOutOfRange for a bad range, Task::validate's.
Result<PlaybackReport> play(const Task& task, const kinematics::RobotModel& model,
                            StepRunner& runner, const PlaybackOptions& options,
                            const PlaybackObserver& observer = {});

/// One step of an off-line run: the joints along the planned motion.
struct SimulatedStep {
  Action action;
  double start_s = 0.0;     ///< when the step starts, from the start of the run
  double duration_s = 0.0;  ///< planned duration (moves), the wait, or the gripper dwell
  /// Joints every `sample_period_s` along the move (first = start, last = target), or the
  /// held joints for gripper steps and waits (one sample).
  std::vector<kinematics::JointVector> samples;
  std::optional<GripperAction> gripper;  ///< the gripper after this step, if it changed
};

/// The off-line run (the thesis's simulation mode): plans every step from `q_start` with
/// core/motion's Planner (the same plans, limits and durations the motion service would
/// produce) without the bus. Errors: the first step that cannot be planned, e.g. "step 3
/// (pose 'p2'): <planner error>"; range and validate errors as play().
Result<std::vector<SimulatedStep>> simulate(const Task& task, const kinematics::RobotModel& model,
                                            const kinematics::JointVector& q_start,
                                            const PlaybackOptions& options,
                                            const motion::PlannerOptions& planner = {},
                                            double sample_period_s = 0.05);

}  // namespace cell::teach
