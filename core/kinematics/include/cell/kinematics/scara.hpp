#pragma once

#include <array>
#include <cstdint>
#include <string_view>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/kinematics/joints.hpp"
#include "cell/kinematics/workspace.hpp"

/// 4-axis SCARA kinematics (J1 shoulder, J2 elbow, Z vertical, R roll): the IBM 7545 of the
/// AVRS thesis (digest 000) and conveyor pickers such as an Adept Cobra 600 (digest 002) are
/// configurations of the same model (config/robots/ibm7545.yaml, scara_picker.yaml).
///
/// Frames. The base frame has its origin on the J1 axis, z up along J1, x along link 1 when
/// J1 = 0 (so J1 = J2 = 0 stretches the arm along +x: the 7545's home (0, 0) <-> (650, 0) mm).
/// The flange frame sits on the R axis at the end of link 2, its z axis parallel to the base z
/// (up), its x axis at the flange yaw. base_T_tool = base_T_flange * flange_T_tool.
///
///   x = l1 cos J1 + l2 cos(J1 + J2),  y = l1 sin J1 + l2 sin(J1 + J2)   (eq. 4.11/4.12)
///   z = z_at_zero + Z (z_positive up) or z_at_zero - Z (z_positive down, the 7545: its Z
///       counts grow going down, digest 000 §2.1)
///   yaw = s R + (J1 + J2) (roll_reference link2) or s R (roll_reference world, the 7545),
///         s = +1 (roll_positive counterclockwise seen from above) or -1 (clockwise).
namespace cell::kinematics {

/// Direction in which the Z joint value grows.
enum class ZDirection : std::uint8_t {
  kUp,    ///< Z grows upward (tool z = z_at_zero + Z)
  kDown,  ///< Z grows downward, as on the 7545 (tool z = z_at_zero - Z)
};

/// What the R joint angle is measured from.
enum class RollReference : std::uint8_t {
  kLink2,  ///< from link 2, as on most SCARAs: tool yaw = J1 + J2 + s R
  kWorld,  ///< from the base x axis whatever J1, J2 do, as on the 7545: tool yaw = s R
};

/// Sense of a positive R, seen from above (looking down the base -z axis).
enum class RotationSense : std::uint8_t {
  kCounterClockwise,  ///< positive R turns the tool counter-clockwise (about base +z)
  kClockwise,         ///< positive R turns it clockwise (about the downward axis, the 7545)
};

/// Immutable geometry and limits of a SCARA. Loaded once from config/robots/<robot>.yaml (see
/// load_robot) and never mutated: share it across threads freely. To calibrate the links, copy
/// it, change link1_mm/link2_mm and build a new RobotModel (RobotModel::create validates).
struct ScaraModel {
  double link1_mm = 0.0;  ///< J1 axis to J2 axis [mm], > 0
  double link2_mm = 0.0;  ///< J2 axis to the R axis [mm], > 0
  /// J1, J2 (revolute), Z (prismatic), R (revolute): names, limits, speeds, encoder scales.
  std::array<JointSpec, 4> joints{};
  ZDirection z_direction = ZDirection::kUp;
  double z_at_zero_mm = 0.0;  ///< flange height in the base frame when Z = 0 [mm]
  RollReference roll_reference = RollReference::kLink2;
  RotationSense roll_sense = RotationSense::kCounterClockwise;
  Eigen::Isometry3d flange_T_tool = Eigen::Isometry3d::Identity();  ///< tool offset [mm]
  CartesianLimits cartesian_limits;  ///< bounds on the tool point in the base frame

  /// Ok, or kConfig naming every offending key, its value and the rule, one per line, e.g.
  /// "key 'scara.link2_mm': must be > 0, got -250".
  Status validate() const;
};

/// SCARA joint vector: J1 [rad], J2 [rad], Z [mm], R [rad].
using ScaraJoints = Eigen::Vector4d;

/// The two elbow branches, named by the sign of J2 (modulo 2 pi: the sign of sin J2).
/// j2_positive is the only branch the 7545 code computes ("only the J2 >= 0 elbow solution",
/// digest 000 §5); on Adept SCARAs it is the "righty" arm.
enum class ElbowBranch : std::uint8_t {
  kJ2Positive = 0,  ///< "j2_positive"
  kJ2Negative = 1,  ///< "j2_negative"
};

/// Branch names by index: {"j2_positive", "j2_negative"}.
inline constexpr std::array<std::string_view, 2> kScaraBranchNames = {"j2_positive", "j2_negative"};

/// The branch's name.
std::string_view to_string(ElbowBranch branch) noexcept;

/// Tool yaw [rad] about the base +z for roll R and elbow joints J1, J2 (see the file comment).
double tool_yaw_from_roll(const ScaraModel& model, double j1, double j2, double r) noexcept;

/// R [rad, wrapped into (-pi, pi]] giving flange yaw `yaw` [rad] with elbow joints J1, J2.
/// For the 7545 (world-referenced, clockwise) R = -yaw: a part lying at world angle phi is
/// gripped with R = -phi, which is the thesis's O_r = -(alpha + J1 + J2 - 90 - angl_err) with
/// phi = alpha + J1 + J2 - 90 - angl_err (digest 000 §5, eq. 4.2/4.3; the J1, J2 there are the
/// image-time joints that turn image angles into world angles).
double roll_from_tool_yaw(const ScaraModel& model, double j1, double j2, double yaw) noexcept;

/// base_T_tool for joints q. Pure, allocation-free, RT-safe. q must be finite (precondition;
/// RobotModel::forward checks it).
Eigen::Isometry3d forward(const ScaraModel& model, const ScaraJoints& q) noexcept;

/// Both elbow branches reaching base_T_tool, in branch order, each flagged with its first
/// joint-limit violation. Revolute joints are unwrapped into their limits, toward `reference`
/// when given (else toward the wrapped value). When the target lies on the J1 axis (only
/// possible if link1 == link2) J1 is free: it takes reference J1 (or 0) and `singular` is set.
/// Errors: kInvalidArgument when base_T_tool is not rigid or its flange z axis is tilted more
/// than 1e-6 rad from the base z (a SCARA reaches vertical tools only); kOutOfRange when the
/// tool point breaks the Cartesian limits or the R axis lies outside the annulus
/// |l1 - l2| <= r <= l1 + l2 (message gives r and the reach). Allocation-free on success.
Result<IkSolutions> inverse_all(const ScaraModel& model, const Eigen::Isometry3d& base_T_tool);
Result<IkSolutions> inverse_all(const ScaraModel& model,
                                const Eigen::Isometry3d& base_T_tool,
                                const ScaraJoints& reference);

/// The joints of one branch. Errors: as inverse_all, plus kOutOfRange naming the joint when that
/// branch breaks a joint limit.
Result<ScaraJoints> inverse(const ScaraModel& model,
                            const Eigen::Isometry3d& base_T_tool,
                            ElbowBranch branch);
Result<ScaraJoints> inverse(const ScaraModel& model,
                            const Eigen::Isometry3d& base_T_tool,
                            ElbowBranch branch,
                            const ScaraJoints& reference);

/// The branch within limits reachable fastest from `seed` (IkSolutions::nearest). Errors: as
/// inverse_all, plus kOutOfRange listing each branch's violated joint when none is within limits.
Result<ScaraJoints> inverse(const ScaraModel& model,
                            const Eigen::Isometry3d& base_T_tool,
                            const ScaraJoints& seed);

}  // namespace cell::kinematics
