#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include <Eigen/Core>

#include "cell/common/result.hpp"
#include "cell/geometry/angles.hpp"

/// Joint descriptions, joint vectors, encoder counts and IK solution sets shared by every robot
/// model of the cell (SCARA, Excalibur). Units inside: radians for revolute joints, millimetres
/// for prismatic ones; degrees appear only in config keys and in messages.
namespace cell::kinematics {

/// Largest number of joints of any robot model (the Excalibur has 6).
inline constexpr int kMaxDof = 6;

/// Joint vector of a robot: size == dof(), entries in rad (revolute) or mm (prismatic).
/// Fixed capacity (kMaxDof) on the stack: constructing, copying and resizing never allocate.
using JointVector = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxDof, 1>;

/// Encoder counts per joint (size == dof()). Fixed capacity, never allocates.
using CountVector = Eigen::Matrix<std::int64_t, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxDof, 1>;

/// Tolerance [rad or mm] granted at joint limits so that a solution computed exactly on a limit
/// is not rejected for rounding noise.
inline constexpr double kLimitTolerance = 1e-9;

/// Kind of a joint.
enum class JointType : std::uint8_t {
  kRevolute,   ///< value in rad; config keys in degrees (_deg, _deg_s, counts_per_deg)
  kPrismatic,  ///< value in mm; config keys in mm (_mm, _mm_s, counts_per_mm)
};

/// "revolute" or "prismatic" (the config spelling).
std::string_view to_string(JointType type) noexcept;

/// One joint of a robot model. Plain data, part of an immutable model.
struct JointSpec {
  std::string name;                       ///< e.g. "j1", "z", "theta3"; unique in a model
  JointType type = JointType::kRevolute;  ///< fixed by the robot kind
  double lower = 0.0;                     ///< lower limit [rad] or [mm]
  double upper = 0.0;                     ///< upper limit [rad] or [mm], > lower
  double max_speed = 0.0;                 ///< speed limit [rad/s] or [mm/s], > 0
  /// Acceleration limit [rad/s^2] or [mm/s^2], > 0, for trajectory planning. None of the seeds
  /// gives one; config key max_accel_deg_s2 / max_accel_mm_s2, default 4 * max_speed per second
  /// (full speed in 0.25 s) when the key is absent.
  double max_accel = 0.0;
  double counts_per_unit = 0.0;  ///< encoder counts per rad or per mm; 0 = none
  /// The controller's own hard (overrun) limits in counts [min, max], when known (the 7545
  /// slave's OVERRUN thresholds, digest 000 §2.1). Informational for drivers and simulators.
  std::optional<std::array<std::int64_t, 2>> overrun_counts;

  /// "deg" for revolute joints, "mm" for prismatic ones: the unit users see.
  std::string_view display_unit() const noexcept;
  /// A value [rad or mm] in the display unit [deg or mm].
  double to_display(double value) const noexcept;
  /// A value in the display unit [deg or mm] to the internal unit [rad or mm].
  double from_display(double value) const noexcept;
  /// True when `value` lies in [lower, upper] within kLimitTolerance.
  bool within_limits(double value) const noexcept {
    return value >= lower - kLimitTolerance && value <= upper + kLimitTolerance;
  }
};

/// "137.200 deg" or "-1.000 mm": a joint value in its display unit, three decimals.
std::string format_joint_value(const JointSpec& joint, double value);

/// Ok when q has one finite entry per joint. Errors: kInvalidArgument "joint vector has 5
/// entries, robot has 6 joints" or "joint 'theta2' is not finite (nan)".
Status check_joint_vector(std::span<const JointSpec> joints, const JointVector& q);

/// Ok when every joint is within its limits. Errors: kInvalidArgument as check_joint_vector;
/// kOutOfRange naming the first offending joint, its value and its limits in display units:
/// "joint 'j2' = 137.200 deg is outside its limits [0.000, 135.000] deg".
Status check_limits(std::span<const JointSpec> joints, const JointVector& q);

/// Index of the first joint of q outside its limits, or -1. Allocation-free.
int first_limit_violation(std::span<const JointSpec> joints, const JointVector& q) noexcept;

/// Encoder counts of q: round-to-nearest of value * counts_per_unit, per joint. (The 7545 code
/// rounds J1/J2 with (long)(x + 0.5), identical for the non-negative counts it produces, and
/// truncates R; we round every joint, so R may differ by one count: digest 000 §5.)
/// Errors: kInvalidArgument when q has the wrong size or a joint has no encoder scale.
Result<CountVector> to_counts(std::span<const JointSpec> joints, const JointVector& q);

/// Joint values of encoder counts: counts / counts_per_unit. Errors as to_counts.
Result<JointVector> from_counts(std::span<const JointSpec> joints, const CountVector& counts);

/// Time [s] a joint-interpolated move from `from` to `to` needs at the joints' speed limits:
/// max over joints of |to - from| / max_speed. Both vectors must have joints.size() entries
/// (precondition). Allocation-free.
double min_move_time(std::span<const JointSpec> joints,
                     const JointVector& from,
                     const JointVector& to) noexcept;

namespace detail {
double fit_revolute_outside(const JointSpec& joint, double base, double reference) noexcept;
}  // namespace detail

/// The revolute angle equal to `angle` modulo 2 pi that lies within the joint's limits and is
/// closest to `reference`; when no equivalent lies within the limits, the one closest to
/// `reference`. Allocation-free.
inline double fit_revolute(const JointSpec& joint, double angle, double reference) noexcept {
  const double base = geometry::nearest_equivalent(angle, reference);
  return joint.within_limits(base) ? base : detail::fit_revolute_outside(joint, base, reference);
}

/// One inverse-kinematics solution (one branch) of a robot.
struct IkSolution {
  JointVector q;                    ///< joints [rad, mm], 2 pi-unwrapped toward the reference
  std::string_view branch;          ///< branch name, static storage (e.g. "j2_positive")
  std::uint8_t branch_index = 0;    ///< index of `branch` in the robot's branch-name table
  std::int8_t violated_joint = -1;  ///< first joint outside its limits, -1 when none
  bool singular = false;            ///< a singular-case policy fixed a free joint (see models)

  /// True when every joint is within its limits.
  bool within_limits() const noexcept { return violated_joint < 0; }
};

/// The solutions of one IK call, at most kCapacity, in branch-index order. A fixed-capacity
/// value type: no heap allocation, cheap enough to return by value.
class IkSolutions {
 public:
  /// Most branches any robot has (the Excalibur's 8).
  static constexpr std::size_t kCapacity = 8;

  /// Number of solutions (one per branch the solver returned).
  std::size_t size() const noexcept { return size_; }
  /// True when there is no solution.
  bool empty() const noexcept { return size_ == 0; }
  /// Solution i, in branch-index order; precondition i < size().
  const IkSolution& operator[](std::size_t i) const noexcept { return items_[i]; }
  /// Mutable access for the solvers, which fill the slots in place; precondition i < size().
  IkSolution& operator[](std::size_t i) noexcept { return items_[i]; }
  /// Range over the solutions (valid while this object lives).
  const IkSolution* begin() const noexcept { return items_.data(); }
  /// End of the range.
  const IkSolution* end() const noexcept { return items_.data() + size_; }

  /// The solution of branch `name`, or nullptr.
  const IkSolution* find(std::string_view name) const noexcept;

  /// Among the solutions within limits, the one reachable fastest from `seed` (min_move_time,
  /// ties to the lower branch index), or nullptr when none is within limits. This is the
  /// default choice rule of every robot's inverse(pose, seed). `seed` must have
  /// joints.size() entries (precondition).
  const IkSolution* nearest(std::span<const JointSpec> joints,
                            const JointVector& seed) const noexcept;

  /// Appends a solution; precondition size() < kCapacity (used by the solvers).
  void push_back(const IkSolution& solution) noexcept;
  /// Sets the number of solutions (at most kCapacity); new slots are default solutions.
  void resize(std::size_t n) noexcept { size_ = n < kCapacity ? n : kCapacity; }

 private:
  std::array<IkSolution, kCapacity> items_{};
  std::size_t size_ = 0;
};

/// kOutOfRange error for an IK call whose branches all break a joint limit, listing each branch
/// and its first offending joint. `what` names the target, e.g. "target (x, y, z) mm".
Error no_branch_within_limits(std::span<const JointSpec> joints,
                              const IkSolutions& solutions,
                              std::string_view what);

/// Picks branch `name` from `solutions`. Errors: kInvalidArgument when the robot has no such
/// branch (the message lists the valid names), kOutOfRange when that branch breaks a limit
/// (message as check_limits, prefixed by the branch name).
Result<JointVector> pick_branch(std::span<const JointSpec> joints,
                                const IkSolutions& solutions,
                                std::span<const std::string_view> branch_names,
                                std::string_view name);

}  // namespace cell::kinematics
