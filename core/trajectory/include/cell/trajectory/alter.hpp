#pragma once

#include <cstdint>

#include <Eigen/Geometry>

namespace cell::trajectory {

/// Real-time path modification of a running move (Adept V+ ALTER; conveyor chapter, digest
/// 002 §1.4 and §2). The two mode bits of ALTON: cumulative (bit 1: each correction adds to
/// the sum; clear: each correction is the total) and world frame (bit 2: corrections are in
/// the robot base frame; clear: in the tool frame).
struct AlterMode {
  bool cumulative = false;
  bool world_frame = true;
};

/// One ALTER: a small rigid displacement (translation in mm, rotation rx, ry, rz in rad applied
/// as Rz*Ry*Rx) plus, as an extension of V+, its rate of change. The rate lets the executor
/// extrapolate between corrections, which removes V+'s one-cycle lag (48 mm at 3 m/s with a
/// 16 ms cycle, digest 002 §2.3) when tracking a belt of known speed.
struct AlterCorrection {
  Eigen::Vector3d translation_mm = Eigen::Vector3d::Zero();
  Eigen::Vector3d rotation_rad = Eigen::Vector3d::Zero();
  Eigen::Vector3d velocity_mm_s = Eigen::Vector3d::Zero();  ///< d(translation)/dt
  double stamp_s = 0.0;  ///< time (executor clock) the values hold at
  /// How far past stamp_s the rate may carry it [s]: 0 (or more than
  /// AlterState::kExtrapolationHorizonS) means that horizon. A sender that knows a limit
  /// ahead (the belt window's end) sends the time left to it.
  double horizon_s = 0.0;
};

/// The meeting ramp: how a robot waiting at rest on a moving target's path takes up the
/// target's pace without a velocity step (which no arm can follow: its joints would lag, and
/// the gripper close beside the part). With d the target's travel past the wait point and D
/// the ramp's length, the robot's displacement along the path is
///   f(d) = 0 (d <= -D),  (d + D)^2 / 4D (-D < d < D),  d (d >= D):
/// it starts when the target is D short of it, accelerates at v^2 / 2D (v the target's speed),
/// and is on the target, at its speed, from d = D on (D past the wait point). C1, so the
/// corrections keep a bounded acceleration. D = 0: the target's travel itself (a step).
struct MeetingRamp {
  double length_mm = 0.0;  ///< D
  /// f(d) [mm].
  double displacement(double d_mm) const noexcept;
  /// f'(d): the robot's speed as a fraction of the target's.
  double rate(double d_mm) const noexcept;
  /// True from d = D on: the robot is on the target.
  bool on_target(double d_mm) const noexcept { return d_mm >= length_mm; }
};

/// The executor's side of ALTER for one move. Corrections arrive at any rate; the executor
/// calls begin_cycle() once per trajectory cycle: only the last correction submitted during a
/// cycle is used (V+: "if ALTER is executed more often, only the last set of values defined
/// during each cycle will be used"). In total mode the effective correction is that last one;
/// in cumulative mode every cycle's last correction is added to the sum.
/// Not thread-safe: feed it from the executor's own thread. Allocation-free.
class AlterState {
 public:
  explicit AlterState(AlterMode mode = {}) : mode_(mode) {}

  /// Queues a correction for the current cycle (replacing one queued earlier this cycle).
  void submit(const AlterCorrection& correction) noexcept;

  /// Closes the cycle: folds the pending correction (if any) into the effective one.
  void begin_cycle() noexcept;

  /// How far past its stamp a correction is extrapolated with its rate [s]. A sender that
  /// falls silent (a lost link, a crashed task, the last correction before ALTOFF) leaves the
  /// arm at most rate * horizon beyond its last correction, never running on with the belt
  /// (netlab: an ALTOFF retransmitted after 50 ms delay and loss let a 500 mm/s track run 62 mm
  /// out of reach). 0.15 s covers a correction every 16 ms over a 100 ms link.
  static constexpr double kExtrapolationHorizonS = 0.15;

  /// The effective correction extrapolated to `now_s` with its rate (translation only), for at
  /// most its horizon_s (kExtrapolationHorizonS at the most) past its stamp.
  AlterCorrection effective_at(double now_s) const noexcept;

  /// Applies `correction` to a nominal pose: in the world frame C * base_T_tool (rotation about
  /// the tool point, so a pure rotation does not swing the tool point), in the tool frame
  /// base_T_tool * C.
  Eigen::Isometry3d apply(const Eigen::Isometry3d& base_T_tool,
                          const AlterCorrection& correction) const noexcept;

  const AlterMode& mode() const noexcept { return mode_; }
  std::uint64_t cycles_with_correction() const noexcept { return applied_; }

 private:
  AlterMode mode_;
  AlterCorrection effective_;
  AlterCorrection pending_;
  bool has_pending_ = false;
  std::uint64_t applied_ = 0;
};

}  // namespace cell::trajectory
