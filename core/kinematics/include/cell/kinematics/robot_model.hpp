#pragma once

#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <variant>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/kinematics/excalibur.hpp"
#include "cell/kinematics/joints.hpp"
#include "cell/kinematics/scara.hpp"
#include "cell/kinematics/workspace.hpp"

namespace cell::kinematics {

/// Which kinematic family a robot belongs to (config key `kind`).
enum class RobotKind : std::uint8_t {
  kScara,      ///< "scara": ScaraModel (IBM 7545, conveyor pickers)
  kExcalibur,  ///< "excalibur": ExcaliburModel
};

/// "scara" or "excalibur".
std::string_view to_string(RobotKind kind) noexcept;

/// One robot of the cell, whatever its kind: the entry point for trajectory planning and the
/// motion service. Obtain it from load_robot(path) (config/robots/*.yaml) or create().
///
/// Immutable after creation (every method is const) and a plain value: copy it or share it
/// across threads freely. forward, inverse_all and inverse do not allocate on success and are
/// RT-safe; errors allocate their message.
///
/// Frames: forward returns base_T_tool, the tool frame in the robot's base frame (see scara.hpp
/// and excalibur.hpp for each kind's base and flange frames). Units: mm and rad; joint vectors
/// hold rad for revolute and mm for prismatic joints, in the order of joints().
class RobotModel {
 public:
  /// Validates `model` (ScaraModel::validate) and wraps it. Errors: kConfig from validate
  /// (prefixed "robot '<id>': "), or kInvalidArgument for an empty id.
  static Result<RobotModel> create(std::string id, ScaraModel model, std::string description = {});
  /// Validates `model` (ExcaliburModel::validate) and wraps it. Errors as above.
  static Result<RobotModel> create(std::string id,
                                   ExcaliburModel model,
                                   std::string description = {});

  /// The robot id (config key `id`), e.g. "ibm7545"; matches robot_id on the bus.
  const std::string& id() const noexcept { return id_; }
  /// Free text for people (config key `description`), possibly empty.
  const std::string& description() const noexcept { return description_; }
  /// The robot's kind.
  RobotKind kind() const noexcept;
  /// Number of joints: 4 (SCARA) or 6 (Excalibur).
  int dof() const noexcept;
  /// Joint names, types, limits, speed limits and encoder scales, in joint-vector order.
  std::span<const JointSpec> joints() const noexcept;
  /// The IK branch names in branch-index order (kScaraBranchNames or kExcaliburBranchNames).
  std::span<const std::string_view> branch_names() const noexcept;
  /// Cartesian limits of the tool point in the base frame.
  const CartesianLimits& cartesian_limits() const noexcept;
  /// The kind-specific model, or nullptr when the robot is of the other kind.
  const ScaraModel* scara() const noexcept { return std::get_if<ScaraModel>(&model_); }
  const ExcaliburModel* excalibur() const noexcept { return std::get_if<ExcaliburModel>(&model_); }

  /// base_T_tool for joints q. Errors: kInvalidArgument when q has the wrong size or a
  /// non-finite entry (check_joint_vector). Joint limits are NOT checked (see check_limits).
  Result<Eigen::Isometry3d> forward(const JointVector& q) const;

  /// Every IK branch reaching base_T_tool, each flagged with its joint-limit violation; revolute
  /// joints unwrapped toward `reference` (joint-vector order, dof() entries) when given.
  /// Errors: the kind's inverse_all errors (kInvalidArgument, kOutOfRange with the reason), and
  /// kInvalidArgument when `reference` has the wrong size or is not finite.
  Result<IkSolutions> inverse_all(const Eigen::Isometry3d& base_T_tool) const;
  Result<IkSolutions> inverse_all(const Eigen::Isometry3d& base_T_tool,
                                  const JointVector& reference) const;

  /// The default choice: the branch within limits reachable fastest from `seed` at the joints'
  /// speed limits (IkSolutions::nearest). Errors: as inverse_all, plus kOutOfRange when no
  /// branch is within limits (each branch's violation listed).
  Result<JointVector> inverse(const Eigen::Isometry3d& base_T_tool, const JointVector& seed) const;

  /// The branch called `branch` (one of branch_names()), unwrapped toward `seed`. Errors: as
  /// inverse_all, plus kInvalidArgument for an unknown branch name, kOutOfRange when that branch
  /// breaks a joint limit (naming the joint).
  Result<JointVector> inverse(const Eigen::Isometry3d& base_T_tool,
                              std::string_view branch,
                              const JointVector& seed) const;

  /// Ok, or kOutOfRange naming the first joint outside its limits with its value and limits in
  /// deg or mm; kInvalidArgument for a wrong size or non-finite entry.
  Status check_limits(const JointVector& q) const;

  /// Encoder counts of q and back (see joints.hpp to_counts/from_counts). Errors:
  /// kInvalidArgument when a joint has no encoder scale or the size is wrong.
  Result<CountVector> to_counts(const JointVector& q) const;
  Result<JointVector> from_counts(const CountVector& counts) const;

 private:
  RobotModel(std::string id,
             std::string description,
             std::variant<ScaraModel, ExcaliburModel> model)
      : id_(std::move(id)), description_(std::move(description)), model_(std::move(model)) {}

  std::string id_;
  std::string description_;
  std::variant<ScaraModel, ExcaliburModel> model_;
};

}  // namespace cell::kinematics
