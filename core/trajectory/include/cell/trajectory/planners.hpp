#pragma once

#include <functional>
#include <vector>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/trajectory/joint_trajectory.hpp"

namespace cell::trajectory {

// ---------------------------------------------------------------------------------------------
// Cubic via-point paths (IBM 7545 thesis, digest 000 §5, after Craig pp. 198-199).

/// Options of the thesis's via-point planner.
struct ViaPointOptions {
  /// Per-joint speed used to size segments (internal units per second). The thesis uses
  /// {45 deg/s, 50 deg/s, 100 mm/s, 70 deg/s} for {J1, J2, Z, R}.
  JointVector speed;
  /// Added to every segment: the thesis's code adds 0.2 s (its text calls it a minimum).
  double settle_s = 0.2;
  /// Floor on a segment's duration (a zero-length segment still takes this long).
  double min_segment_s = 0.0;
};

/// Plans the thesis's path through `points` (at least 2): segment i lasts
/// max_j |q[i+1]_j - q[i]_j| / speed_j + settle_s; the velocity at an interior via point is
/// the mean of the adjacent segments' slopes when they have the same sign and 0 otherwise
/// (a zero slope counts as the same sign, as the thesis's cmp_sign returns 1 for it); the
/// end velocities are 0; each segment is the cubic with those end values (Craig).
/// Errors: kInvalidArgument on mismatched sizes, non-finite values or a speed <= 0.
Result<JointTrajectory> plan_via_points(const std::vector<JointVector>& points,
                                        const ViaPointOptions& options);

// ---------------------------------------------------------------------------------------------
// Joint-interpolated moves.

/// Plans a synchronised trapezoidal-velocity move from q0 to q1: every joint starts and stops
/// together, the slowest joint (given its velocity and acceleration limits scaled by
/// speed_scale in (0, 1]) sets the duration; the profile is exact (knots at the phase changes).
/// Errors: kInvalidArgument (sizes, speed_scale), kOutOfRange (q1 or q0 beyond a limit,
/// naming the joint).
Result<JointTrajectory> plan_joint_move(const JointVector& q0, const JointVector& q1,
                                        const JointLimits& limits, double speed_scale = 1.0);

// ---------------------------------------------------------------------------------------------
// Straight-line Cartesian moves (V+ MOVES), approach and depart.

/// Forward kinematics: base_T_tool of a joint vector.
using ForwardFn = std::function<Eigen::Isometry3d(const JointVector& q)>;
/// Inverse kinematics on the branch nearest to `seed`.
using InverseFn = std::function<Result<JointVector>(const Eigen::Isometry3d& base_T_tool,
                                                    const JointVector& seed)>;

struct LinearMoveOptions {
  double max_speed_mm_s = 250.0;       ///< tool-point speed along the line
  double max_accel_mm_s2 = 1000.0;
  double max_angular_speed_rad_s = 1.5;
  double max_angular_accel_rad_s2 = 6.0;
  double knot_period_s = 0.008;        ///< spacing of IK knots along the line
  double speed_scale = 1.0;            ///< (0, 1]
};

/// Plans a straight line of the tool point from FK(q0) to base_T_goal, orientation by slerp,
/// with a trapezoidal profile on the path parameter sized by the linear and angular limits.
/// The joints come from IK at every knot (seeded with the previous knot, so the branch never
/// flips); knot velocities by finite differences of the IK solutions. If the joints would
/// exceed a velocity limit (near a singularity) the profile is slowed down uniformly until
/// they fit. Errors: kOutOfRange naming where along the line IK failed or which joint limit
/// broke; kInvalidArgument on bad options.
Result<JointTrajectory> plan_linear_move(const JointVector& q0, const Eigen::Isometry3d& base_T_goal,
                                         const ForwardFn& forward, const InverseFn& inverse,
                                         const JointLimits& limits,
                                         const LinearMoveOptions& options = {});

/// base_T_tool moved `distance_mm` along its own tool z axis (negative: backwards). An approach
/// to a grasp pose G is a line from offset_along_tool_z(G, -d) to G when the tool z points
/// into the part; a depart is the line from the current pose to offset_along_tool_z(P, -d).
Eigen::Isometry3d offset_along_tool_z(const Eigen::Isometry3d& base_T_tool, double distance_mm);

}  // namespace cell::trajectory
