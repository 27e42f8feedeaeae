#pragma once

#include <Eigen/Geometry>
#include <cstdint>

#include "cell/common/result.hpp"
#include "cell/trajectory/alter.hpp"
#include "cell/trajectory/joint_limiter.hpp"
#include "cell/trajectory/joint_trajectory.hpp"
#include "cell/trajectory/planners.hpp"

namespace cell::trajectory {

/// What the executor is doing (V+ STATE(2) semantics for kArrived).
enum class ExecState : std::uint8_t {
  kIdle,      ///< nothing loaded
  kMoving,    ///< following the trajectory
  kArrived,   ///< "motion stopped at planned location"; still tracking if ALTER is on
  kFailed,    ///< the altered pose left the workspace; holding the last good setpoint
};

/// Turns a trajectory (plus ALTER corrections, if enabled) into joint setpoints, one call per
/// servo cycle. Used by the gateway's servo loop and by the ideal robot that stands in for
/// it. With ALTER off the setpoint is the trajectory sample. With ALTER on, the nominal tool
/// pose FK(q(t)) is displaced by the effective correction, blended in with a smoothstep of
/// the move's time fraction (so a correction that built up before the move began does not
/// make the path jump), reaching the full correction at the destination; after arrival the
/// executor keeps the tool on destination + correction(t) (it tracks the moving part) until
/// alter_off(). Each altered setpoint comes from IK seeded with the previous one.
///
/// With joint limits (the robot file's speeds and accelerations: motion::joint_limits), the
/// setpoints keep them on the whole path, sampled cycle by cycle (JointLimiter): an altered path is
/// followed through the limiter, which lags where the corrections ask more than the arm can do
/// (counted: limited_cycles()); ALTOFF brakes the arm from its tracking speed at its limits to rest
/// (kMoving until it rests) instead of holding it at once; a path loaded while the setpoints
/// still move (a move that starts on a moving part) is joined with bounded acceleration. A
/// planned path without ALTER keeps the limits by construction (the planners check them) and
/// passes through unchanged. Without limits, the setpoints are the altered path itself.
/// Not thread-safe; step() is allocation-free when the IK is.
class TrajectoryExecutor {
 public:
  TrajectoryExecutor(ForwardFn forward, InverseFn inverse, JointLimits limits = {});

  /// Loads a trajectory starting at time `start_s` (executor clock, seconds).
  void load(JointTrajectory trajectory, double start_s, bool alter_enabled, AlterMode mode);

  /// Queues an ALTER correction (ignored unless the loaded trajectory enables ALTER).
  void submit_alter(const AlterCorrection& correction) noexcept;

  /// Ends alter mode (V+ ALTOFF): the robot rests where destination + total correction put it.
  void alter_off() noexcept;

  /// Computes the setpoint for time `now_s` into `out` (q and qd); call once per cycle.
  ExecState step(double now_s, JointSample& out);

  /// Stops: the trajectory is dropped and the last setpoint held.
  void stop() noexcept;

  /// Delays the trajectory's remainder by `s` seconds (the host stalled: the path resumes
  /// where it was instead of jumping ahead by the stall). ALTER keeps the wall clock.
  void delay(double s) noexcept { start_s_ += s; }

  /// Drops the trajectory and whatever was held: step() is idle until the next load(), so
  /// the caller's own setpoint stands (after a fault is reset the arm may rest far from the
  /// last setpoint: holding that would drive it back at once, or fault it again).
  void clear() noexcept;

  ExecState state() const noexcept { return state_; }
  /// True while ALTER corrections are applied (loaded with ALTER and not yet alter_off()).
  bool alter_active() const noexcept { return alter_enabled_; }
  double progress() const noexcept;
  const JointTrajectory& trajectory() const noexcept { return trajectory_; }
  /// Why the state is kFailed.
  const Error& failure() const noexcept { return failure_; }
  /// Cycles (cumulative) in which the joint limits held the setpoints off the altered path.
  std::uint64_t limited_cycles() const noexcept { return limiter_.limited_steps(); }
  /// The largest distance [mm] of the tool from the altered path (or the path being joined)
  /// while the limits held it off, since the last load().
  double max_lag_mm() const noexcept { return max_lag_mm_; }

 private:
  ForwardFn forward_;
  InverseFn inverse_;
  JointTrajectory trajectory_;
  double start_s_ = 0.0;
  double last_now_s_ = 0.0;
  double last_step_s_ = 0.0;
  bool alter_enabled_ = false;
  AlterState alter_;
  ExecState state_ = ExecState::kIdle;
  JointSample nominal_;
  JointVector last_q_;
  bool has_last_ = false;
  Error failure_;
  JointLimiter limiter_;
  bool limiting_ = false;      ///< the setpoints come from the limiter (not yet on the path)
  bool limiter_live_ = false;  ///< the limiter holds the last setpoint and its speed
  double limiter_s_ = 0.0;     ///< time of the limiter's last step
  double last_dt_s_ = 0.0;     ///< the last cycle's length
  JointVector last_ref_q_;     ///< the altered path's last point (its speed by difference)
  bool has_ref_ = false;
  double max_lag_mm_ = 0.0;
};

}  // namespace cell::trajectory
