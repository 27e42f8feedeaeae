#pragma once

#include <cstdint>

#include "cell/trajectory/joint_trajectory.hpp"

namespace cell::trajectory {

/// Follows a joint reference, one step per servo cycle, with each joint's speed and
/// acceleration bounded. Where the reference keeps the bounds the output is the reference
/// (to rounding: a step closes the error left by the last one, dead-beat); where it does not
/// (an ALTER correction faster than the arm, a path that starts while the arm still moves, an
/// ALTOFF at belt speed) the output lags and catches up along the discrete braking curve, so
/// that the sampled acceleration (q[k+1] - 2 q[k] + q[k-1]) / dt^2 of the output never exceeds
/// max_accel nor its speed max_speed (with a constant dt; with a varying dt, (qd[k+1] - qd[k]) /
/// dt[k+1] does not).
///
/// The law, per joint, with e the error the reference left at the last step:
///   v_des = qd_ref + sign(e) min(|e| / dt, a dt (sqrt(1/4 + 2 |e| / (a dt^2)) - 1/2))
/// (the second term: the largest speed from which steps of decel a stop within |e|), clamped
/// to +-max_speed, then the change of speed clamped to +-a dt. Not thread-safe; allocation-free
/// once sized.
class JointLimiter {
 public:
  JointLimiter() = default;
  explicit JointLimiter(JointLimits limits);

  /// True when bounds were given (a limiter without them passes the reference through). Only
  /// max_velocity and max_acceleration bound it (the robot file's joint units: rad or mm).
  bool bounded() const noexcept { return limits_.max_acceleration.size() > 0; }
  const JointLimits& limits() const noexcept { return limits_; }

  /// Sets the output's state (the arm's setpoint and its speed) without a step.
  void reset(const JointVector& q, const JointVector& qd);

  /// One step of `dt_s` towards the reference at the step's end (q_ref, qd_ref). Returns true
  /// when a bound acted (the output is not the reference).
  bool step(const JointVector& q_ref, const JointVector& qd_ref, double dt_s);

  const JointVector& q() const noexcept { return q_; }
  const JointVector& qd() const noexcept { return qd_; }
  const JointVector& qdd() const noexcept { return qdd_; }

  /// The point each joint comes to rest at when braked from its present speed at its bound
  /// (the discrete braking distance v^2 / 2a + |v| dt / 2).
  JointVector stopping_point(double dt_s) const;

  /// Steps (cumulative) in which a bound acted.
  std::uint64_t limited_steps() const noexcept { return limited_steps_; }

 private:
  JointLimits limits_;
  JointVector q_;
  JointVector qd_;
  JointVector qdd_;
  std::uint64_t limited_steps_ = 0;
};

}  // namespace cell::trajectory
