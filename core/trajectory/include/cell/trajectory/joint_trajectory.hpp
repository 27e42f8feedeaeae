#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "cell/common/result.hpp"

namespace cell::trajectory {

/// Maximum number of joints of any robot of the cell (SCARA 4, Excalibur 6). Equal to
/// kinematics::kMaxDof, so both libraries' JointVector are the same type.
inline constexpr int kMaxJoints = 6;

/// A joint vector in the robot's internal units: radians for revolute joints, millimetres
/// for prismatic ones. Fixed capacity, so copies never allocate (safe in the 1 kHz loop).
using JointVector = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxJoints, 1>;

/// One knot: time from the start, position and velocity of every joint.
struct Knot {
  double t_s = 0.0;
  JointVector q;
  JointVector qd;  ///< per second
};

/// Position, velocity and acceleration of every joint at one instant.
struct JointSample {
  JointVector q;
  JointVector qd;
  JointVector qdd;
};

/// A joint-space trajectory as knots joined by cubic Hermite polynomials: between knots i and
/// i+1 each joint follows the unique cubic with the knots' positions and velocities. That is
/// exactly the 7545 thesis's cubic via-point segment (Craig's coefficients), exactly any
/// piecewise-quadratic (trapezoidal) profile whose phase boundaries are knots, and, with dense
/// knots, a straight-line Cartesian move. It is also the wire format (IDL Trajectory).
/// Immutable once built; sample() is allocation-free and thread-compatible.
class JointTrajectory {
 public:
  JointTrajectory() = default;

  /// Builds from knots. Errors (kInvalidArgument): fewer than 1 knot, first time not 0, times
  /// not strictly increasing, vectors of different sizes, a non-finite number (names the
  /// knot and joint).
  static Result<JointTrajectory> from_knots(std::vector<Knot> knots);

  /// Sample at time t (clamped to [0, duration]); after the end the last knot holds with
  /// zero velocity and acceleration.
  JointSample sample(double t_s) const;

  /// Same, writing into `out` (no allocation; out's vectors are resized within capacity).
  void sample(double t_s, JointSample& out) const;

  double duration_s() const noexcept { return knots_.empty() ? 0.0 : knots_.back().t_s; }
  int dof() const noexcept { return knots_.empty() ? 0 : static_cast<int>(knots_[0].q.size()); }
  const std::vector<Knot>& knots() const noexcept { return knots_; }
  const JointVector& start() const { return knots_.front().q; }
  const JointVector& end() const { return knots_.back().q; }

  /// This trajectory followed by `next`, whose start must equal this one's end within 1e-6
  /// (kInvalidArgument otherwise, naming the joint).
  Result<JointTrajectory> then(const JointTrajectory& next) const;

  /// The same path, `factor` (> 0) times slower: knot times times factor, velocities divided
  /// by it, so accelerations are divided by factor^2. Precondition: factor > 0 and finite.
  JointTrajectory time_scaled(double factor) const;

 private:
  explicit JointTrajectory(std::vector<Knot> knots) : knots_(std::move(knots)) {}
  std::size_t segment_at(double t_s) const noexcept;
  std::vector<Knot> knots_;
};

/// Limits of one robot's joints, in internal units (rad, mm, per second). From the robot's
/// model (core/kinematics); names are used in error messages.
struct JointLimits {
  std::vector<std::string> names;  ///< "J1", "J2", "Z", "R"
  std::vector<bool> prismatic;     ///< true: mm; false: rad (for messages in deg / mm)
  JointVector lower;
  JointVector upper;
  JointVector max_velocity;      ///< > 0
  JointVector max_acceleration;  ///< > 0

  int dof() const noexcept { return static_cast<int>(lower.size()); }
  /// Ok, or kInvalidArgument naming the inconsistent field.
  Status validate() const;
};

/// Checks every knot and the continuous path between knots against position, velocity and
/// acceleration limits (each Hermite cubic at its extrema; `velocity_tolerance` is the relative
/// slack granted on speeds and accelerations).
/// A path may start outside a position limit and lead back in (an arm that sagged past it with
/// its torques off): per joint, the bounds widen to include the start, never more.
/// Errors (kOutOfRange) name the segment, the time, the joint and the value against the limit
/// in user units, e.g. "segment 2 at t=1.234 s: joint J2 at 136.2 deg beyond its limit
/// [0, 135] deg".
Status check_limits(const JointTrajectory& trajectory, const JointLimits& limits,
                    double velocity_tolerance = 1e-6);

/// The largest |acceleration| / max_acceleration over every joint and segment (a cubic's
/// acceleration is linear in time: its extremes are at the segment ends). Precondition:
/// trajectory and limits have the same number of joints.
double peak_acceleration_ratio(const JointTrajectory& trajectory, const JointLimits& limits);

/// Formats a joint value in user units: "12.50 deg" or "200.00 mm".
std::string format_joint(double value, bool prismatic);

}  // namespace cell::trajectory
