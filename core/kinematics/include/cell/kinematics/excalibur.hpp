#pragma once

#include <array>
#include <cstdint>
#include <string_view>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/kinematics/joints.hpp"
#include "cell/kinematics/workspace.hpp"

/// Kinematics of the RSI Excalibur, a 6-DOF elbow arm with a spherical wrist and no shoulder
/// offset (Simonian 1992, digest 001 §3).
///
/// Frames. Standard DH, A_n = Rot(z, theta_n) Trans(0, 0, d_n) Trans(a_n, 0, 0) Rot(x, alpha_n):
///
///   link | alpha | a  | d
///   1    |  90   | 0  | d1      base height (the world origin is on the bench under the base)
///   2    |   0   | a2 | 0       upper arm
///   3    | -90   | 0  | 0
///   4    |  90   | 0  | d4      forearm
///   5    | -90   | 0  | 0
///   6    |   0   | 0  | d6      wrist centre to the tool point
///
/// T6 = A1 ... A6 is base_T_flange (n, o, a, p of the thesis); base_T_tool = T6 * E with
/// E = flange_T_tool (the thesis's X = Z T6 E with Z = I). At q = 0 the upper arm is horizontal
/// along +x and the forearm and tool point straight up: p = (a2, 0, d1 + d4 + d6).
///
/// Joint angles here are DH angles. The controller's own angles q* differ by an offset:
/// theta2 = theta2* + 30 deg, theta3 = theta3* - 150 deg (digest 001 §2.3); see to_controller.
namespace cell::kinematics {

/// What the IK does with theta4 at the wrist singularity (theta5 = 0, axes 4 and 6 aligned),
/// where only theta4 + theta6 is determined.
enum class WristSingularity : std::uint8_t {
  kZeroTheta4,  ///< theta4 = 0, all the roll goes to theta6 (the thesis's rule, digest 001 §3.2)
  kKeepTheta4,  ///< theta4 = the reference (current) theta4, the rest goes to theta6
};

/// Immutable Excalibur geometry and limits. The thesis gives no link lengths and no joint limits:
/// config/robots/excalibur.yaml carries the digest's placeholders (d1 = 254, a2 = 304.8,
/// d4 = 304.8, d6 = 152.4 mm). Share across threads freely.
struct ExcaliburModel {
  double d1_mm = 0.0;                 ///< base to shoulder height [mm], >= 0
  double a2_mm = 0.0;                 ///< upper arm [mm], > 0
  double d4_mm = 0.0;                 ///< forearm [mm], > 0
  double d6_mm = 0.0;                 ///< wrist centre to tool point [mm], >= 0
  std::array<JointSpec, 6> joints{};  ///< theta1..theta6 (all revolute), DH angles
  /// theta = theta* + offset [rad], per joint: the thesis's (0, 30, -150, 0, 0, 0) deg.
  std::array<double, 6> controller_offset{};
  Eigen::Isometry3d flange_T_tool = Eigen::Isometry3d::Identity();  ///< E [mm]
  CartesianLimits cartesian_limits;  ///< table guard (z lower bound) and base guard
  WristSingularity wrist_singularity = WristSingularity::kZeroTheta4;

  /// Ok, or kConfig naming every offending key, its value and the rule, one per line.
  Status validate() const;
};

/// Excalibur joint vector: theta1..theta6 [rad], DH convention.
using ExcaliburJoints = Eigen::Matrix<double, 6, 1>;

/// The 8 IK branches, index = 4 * shoulder + 2 * elbow + wrist:
///   shoulder_front: theta1 points the arm plane at the wrist centre; shoulder_back: theta1 + pi,
///     the arm reaches over its own base.
///   elbow_up: the elbow lies above the shoulder-to-wrist-centre line (in front this is C3 <= 0,
///     the thesis's "elbow-up"); elbow_down: below it.
///   wrist_noflip: sin(theta5) >= 0 (the corrected formula's solution); wrist_flip: the other one,
///     (theta4 + pi, -theta5, theta6 + pi), which the thesis's printed theta4 formula selects.
inline constexpr std::array<std::string_view, 8> kExcaliburBranchNames = {
    "shoulder_front/elbow_up/wrist_noflip",   "shoulder_front/elbow_up/wrist_flip",
    "shoulder_front/elbow_down/wrist_noflip", "shoulder_front/elbow_down/wrist_flip",
    "shoulder_back/elbow_up/wrist_noflip",    "shoulder_back/elbow_up/wrist_flip",
    "shoulder_back/elbow_down/wrist_noflip",  "shoulder_back/elbow_down/wrist_flip",
};

/// base_T_tool = T6(q) * flange_T_tool. Pure, allocation-free, RT-safe.
Eigen::Isometry3d forward(const ExcaliburModel& model, const ExcaliburJoints& q) noexcept;

/// The wrist centre (origin of frames 4 and 5) in the base frame for base_T_tool [mm].
Eigen::Vector3d wrist_centre(const ExcaliburModel& model,
                             const Eigen::Isometry3d& base_T_tool) noexcept;

/// The gripper guards on a target: the table guard (tool point below cartesian_limits.z) and the
/// base guard, plus any x/y bound. Errors: kOutOfRange naming the guard and the values.
Status check_guards(const ExcaliburModel& model, const Eigen::Isometry3d& base_T_tool);

/// All 8 branches reaching base_T_tool (closed form, Paul's method with the corrections of
/// digest 001 §3.2), in branch-index order, each flagged with its first joint-limit violation.
/// Singular cases never produce NaN:
///   - wrist centre on the base axis: theta1 is free; it takes reference theta1 (or 0) for the
///     front branches and that + pi for the back ones; `singular` is set;
///   - theta5 = 0 (|sin theta5| < 1e-12): theta4 follows model.wrist_singularity (0, or the
///     reference theta4), theta6 takes the rest of the roll; `singular` is set;
///   - elbow stretched (|S3| = 1): both elbow branches coincide.
/// Revolute joints are unwrapped into their limits toward `reference` (else toward (-pi, pi]).
/// Errors: kInvalidArgument when base_T_tool is not rigid; kOutOfRange when a guard refuses the
/// target (check_guards) or the wrist centre is out of reach (|S3| > 1: the message gives the
/// distance from the shoulder and the reach [|a2 - d4|, a2 + d4]). Allocation-free on success.
Result<IkSolutions> inverse_all(const ExcaliburModel& model, const Eigen::Isometry3d& base_T_tool);
Result<IkSolutions> inverse_all(const ExcaliburModel& model,
                                const Eigen::Isometry3d& base_T_tool,
                                const ExcaliburJoints& reference);

/// The branch within limits reachable fastest from `seed` (the default choice rule,
/// IkSolutions::nearest). Errors: as inverse_all, plus kOutOfRange listing each branch's
/// violated joint when no branch is within limits.
Result<ExcaliburJoints> inverse(const ExcaliburModel& model,
                                const Eigen::Isometry3d& base_T_tool,
                                const ExcaliburJoints& seed);

/// The branch named `branch` (one of kExcaliburBranchNames). Errors: as inverse_all, plus
/// kInvalidArgument for an unknown name (listing the valid ones) and kOutOfRange naming the
/// joint when that branch breaks a limit.
Result<ExcaliburJoints> inverse(const ExcaliburModel& model,
                                const Eigen::Isometry3d& base_T_tool,
                                std::string_view branch,
                                const ExcaliburJoints& seed);

/// Controller angles q* [rad] of DH angles q: q* = q - controller_offset (theta2* = theta2 - 30
/// deg, theta3* = theta3 + 150 deg for the thesis's offsets). Not wrapped.
ExcaliburJoints to_controller(const ExcaliburModel& model, const ExcaliburJoints& q) noexcept;

/// DH angles q [rad] of controller angles q*: q = q* + controller_offset. Not wrapped.
ExcaliburJoints from_controller(const ExcaliburModel& model,
                                const ExcaliburJoints& q_controller) noexcept;

}  // namespace cell::kinematics
