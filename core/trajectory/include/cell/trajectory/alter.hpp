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
