#pragma once

#include <numbers>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/motion/wire.hpp"
#include "cell/trajectory/planners.hpp"

namespace cell::motion {

/// A target moving at constant velocity (a part riding a belt) for Planner::intercept. Base
/// frame, mm, s. Times count from the target's stamp: the instant it was at `at_stamp` (a belt
/// camera's exposure).
struct MovingTarget {
  Eigen::Isometry3d at_stamp = Eigen::Isometry3d::Identity();  ///< base_T_tool to reach then
  Eigen::Vector3d velocity_mm_s = Eigen::Vector3d::Zero();     ///< non-zero, finite
  double start_s = 0.0;   ///< when the robot starts moving, from the stamp (>= 0)
  double margin_s = 0.0;  ///< the robot is at the meeting point this long before the target
  /// The meeting point lies between these travels from at_stamp along the velocity [mm] (a
  /// belt window), and so does the end of its meeting ramp, where the robot is on the target
  /// (the caller keeps room past max_travel_mm for what follows: the grip);
  /// max_travel_mm <= 0: no limit but the robot's reach (and 5 s of travel).
  double min_travel_mm = 0.0;
  double max_travel_mm = 0.0;
  bool joint_interpolated = false;  ///< joint move to the meeting point, else a straight line
  /// How long the robot must follow the target once on it (the gripper's closing and dwell),
  /// within its reach and the joints' speed and acceleration limits [s].
  double follow_s = 0.2;
};

/// Where and when the robot meets a MovingTarget, and the plan that takes it there.
/// The robot waits at rest at the meeting point (`meet`, the plan's end) and takes up the
/// target's pace along the meeting ramp (trajectory::MeetingRamp, `ramp_mm`): the ALTER
/// corrections displace it by f(d) for the target's travel d past `meet`; it is on the target
/// from d = ramp_mm on, and can follow it for MovingTarget::follow_s from there within the
/// joints' limits and the window.
struct Intercept {
  Plan plan;                    ///< to the meeting point, ALTER enabled
  Eigen::Isometry3d meet;       ///< base_T_tool at the meeting point (where the robot waits)
  double meet_s = 0.0;          ///< when the target reaches it, from its stamp
  double travel_mm = 0.0;       ///< from at_stamp along the velocity
  double ramp_mm = 0.0;         ///< the meeting ramp's length D
  int candidates = 0;           ///< meeting points planned to find it (its cost)
};

/// Planner settings (config/motion.yaml `planner:` section).
struct PlannerOptions {
  trajectory::LinearMoveOptions linear;  ///< straight-line limits (speed_scale is per request)
  double gripper_dwell_s = 0.5;          ///< hold after a gripper action (thesis: 0.5 s)
  double default_approach_mm = 30.0;     ///< approach/depart distance when a request gives 0
  /// Settle time added to each via-point segment (thesis: 0.2 s).
  double via_settle_s = 0.2;
  /// A measured start this little beyond a joint limit is planned from the limit (MoveIt's
  /// start_state_max_bounds_error): an arm left at a limit reads past it by its sensors'
  /// accuracy (the Excalibur's potentiometers: +-0.3 deg), and a start refused for that could
  /// never move again. The gateways take a path that starts within their start tolerance of
  /// the arm (0.5 deg, 0.5 mm as shipped): these must not exceed it.
  double start_bounds_tolerance_rad = 0.5 * std::numbers::pi / 180.0;
  double start_bounds_tolerance_mm = 0.5;
};

/// Plans every motion the motion service offers for one robot: from the current joints to a
/// Plan (trajectory + gripper events + ALTER flags), checked against the robot's joint,
/// speed and Cartesian limits before anything moves. Errors name the offending step, segment
/// and joint. Immutable; thread-compatible.
///
/// "Above" for approach and depart: a SCARA approaches along the base +z (its tool axis is
/// vertical); a 6-axis arm along the tool's -z (the approach vector a points into the part,
/// Paul's n, o, a convention).
class Planner {
 public:
  Planner(kinematics::RobotModel model, PlannerOptions options);

  /// The measured joints `q` as a start to plan from: a joint beyond its limit by no more
  /// than the start bounds tolerance (PlannerOptions) is put on the limit; any other stays as
  /// it is (and a plan from it is refused with the joint and its limit).
  trajectory::JointVector start_within_limits(const trajectory::JointVector& q) const;

  /// Joint-interpolated move to joints q1.
  Result<Plan> move_joints(const trajectory::JointVector& q0, const trajectory::JointVector& q1,
                           double speed_scale) const;
  /// Joint-interpolated move to a tool pose: IK on `branch` ("" = nearest to q0).
  Result<Plan> move_pose(const trajectory::JointVector& q0, const Eigen::Isometry3d& base_T_tool,
                         const std::string& branch, double speed_scale) const;
  /// Straight line of the tool point (V+ MOVES).
  Result<Plan> move_linear(const trajectory::JointVector& q0,
                           const Eigen::Isometry3d& base_T_tool, double speed_scale) const;
  /// Cubic via-point path (7545 thesis) through the poses in `via` then `target`.
  Result<Plan> via_path(const trajectory::JointVector& q0,
                        const std::vector<Eigen::Isometry3d>& via,
                        const Eigen::Isometry3d& target, double speed_scale) const;
  /// Joint move to `distance_mm` above `target`.
  Result<Plan> approach(const trajectory::JointVector& q0, const Eigen::Isometry3d& target,
                        double distance_mm, double speed_scale) const;
  /// Straight line `distance_mm` up from the current tool pose.
  Result<Plan> depart(const trajectory::JointVector& q0, double distance_mm,
                      double speed_scale) const;
  /// Approach above `target`, straight down to it, close (pick) or open (place) the gripper
  /// and dwell, straight back up. One trajectory with the gripper event at the bottom.
  Result<Plan> pick_or_place(const trajectory::JointVector& q0, const Eigen::Isometry3d& target,
                             double distance_mm, bool close, double speed_scale) const;
  /// Straight line to `target` with ALTER enabled (the destination follows corrections);
  /// `joint_interpolated`: a joint move instead (faster, the path not straight).
  Result<Plan> track(const trajectory::JointVector& q0, const Eigen::Isometry3d& target,
                     bool cumulative, bool world_frame, double speed_scale,
                     bool joint_interpolated = false) const;

  /// Plans where to meet a moving target: the earliest point of its path that the robot,
  /// starting at target.start_s from q0, reaches target.margin_s before the target comes
  /// within the meeting ramp of it, from which it can take up the target's pace and follow
  /// it for target.follow_s within the joints' speed and acceleration limits (the ramp is the
  /// shortest of D0, 2 D0, 4 D0, 8 D0 that can, D0 from the joints' acceleration limits
  /// there), the ramp's end within the travel window (the conveyor chapter's downstream limit
  /// checked before the robot moves), and the track there (ALTER enabled: the caller's
  /// corrections, along the ramp, make the destination follow the target once it arrives).
  /// Found by stepping the meeting time along the path (10 mm of travel a step) and then
  /// halving the last step to 0.2 mm, so the earliest meeting is found even where a later one
  /// needs a longer move.
  /// Errors: kOutOfRange when no point of the window can be met (the reason gives the last
  /// planning failure, if any, and how late the robot would be at the window's end);
  /// kInvalidArgument on a zero or non-finite velocity or bad times.
  Result<Intercept> intercept(const trajectory::JointVector& q0, const MovingTarget& target,
                              bool cumulative, bool world_frame, double speed_scale) const;

  /// The tool pose `distance_mm` "above" `base_T_tool` (see the class comment).
  Eigen::Isometry3d above(const Eigen::Isometry3d& base_T_tool, double distance_mm) const;

  const kinematics::RobotModel& model() const noexcept { return model_; }
  const PlannerOptions& options() const noexcept { return options_; }

 private:
  Status check_pose(const Eigen::Isometry3d& base_T_tool, const char* what) const;
  Result<trajectory::JointTrajectory> line(const trajectory::JointVector& q0,
                                           const Eigen::Isometry3d& goal, double speed_scale,
                                           const char* step) const;

  kinematics::RobotModel model_;
  PlannerOptions options_;
  trajectory::JointLimits limits_;
};

}  // namespace cell::motion
