#include "cell/kinematics/robot_model.hpp"

#include <fmt/format.h>

namespace cell::kinematics {
namespace {

template <typename Model>
Status check_model(const std::string& id, const Model& model) {
  if (id.empty()) {
    return Error{Errc::kInvalidArgument, "robot id must not be empty"};
  }
  const Status valid = model.validate();
  if (!valid) {
    return with_context(valid.error(), fmt::format("robot '{}'", id));
  }
  return ok_status();
}

}  // namespace

std::string_view to_string(RobotKind kind) noexcept {
  return kind == RobotKind::kScara ? "scara" : "excalibur";
}

Result<RobotModel> RobotModel::create(std::string id, ScaraModel model, std::string description) {
  CELL_TRY(check_model(id, model));
  return RobotModel(std::move(id), std::move(description), std::move(model));
}

Result<RobotModel> RobotModel::create(std::string id,
                                      ExcaliburModel model,
                                      std::string description) {
  CELL_TRY(check_model(id, model));
  return RobotModel(std::move(id), std::move(description), std::move(model));
}

RobotKind RobotModel::kind() const noexcept {
  return std::holds_alternative<ScaraModel>(model_) ? RobotKind::kScara : RobotKind::kExcalibur;
}

int RobotModel::dof() const noexcept { return static_cast<int>(joints().size()); }

std::span<const JointSpec> RobotModel::joints() const noexcept {
  if (const ScaraModel* s = scara()) {
    return s->joints;
  }
  return excalibur()->joints;
}

std::span<const std::string_view> RobotModel::branch_names() const noexcept {
  if (kind() == RobotKind::kScara) {
    return kScaraBranchNames;
  }
  return kExcaliburBranchNames;
}

const CartesianLimits& RobotModel::cartesian_limits() const noexcept {
  if (const ScaraModel* s = scara()) {
    return s->cartesian_limits;
  }
  return excalibur()->cartesian_limits;
}

Result<Eigen::Isometry3d> RobotModel::forward(const JointVector& q) const {
  CELL_TRY(check_joint_vector(joints(), q));
  if (const ScaraModel* s = scara()) {
    return kinematics::forward(*s, ScaraJoints(q));
  }
  return kinematics::forward(*excalibur(), ExcaliburJoints(q));
}

Result<IkSolutions> RobotModel::inverse_all(const Eigen::Isometry3d& base_T_tool) const {
  if (const ScaraModel* s = scara()) {
    return kinematics::inverse_all(*s, base_T_tool);
  }
  return kinematics::inverse_all(*excalibur(), base_T_tool);
}

Result<IkSolutions> RobotModel::inverse_all(const Eigen::Isometry3d& base_T_tool,
                                            const JointVector& reference) const {
  CELL_TRY(check_joint_vector(joints(), reference));
  if (const ScaraModel* s = scara()) {
    return kinematics::inverse_all(*s, base_T_tool, ScaraJoints(reference));
  }
  return kinematics::inverse_all(*excalibur(), base_T_tool, ExcaliburJoints(reference));
}

Result<JointVector> RobotModel::inverse(const Eigen::Isometry3d& base_T_tool,
                                        const JointVector& seed) const {
  auto all = inverse_all(base_T_tool, seed);
  if (!all) {
    return std::move(all).error();
  }
  const IkSolution* best = all->nearest(joints(), seed);
  if (best == nullptr) {
    const Eigen::Vector3d p = base_T_tool.translation();
    return no_branch_within_limits(
        joints(), *all, fmt::format("target ({:.3f}, {:.3f}, {:.3f}) mm", p.x(), p.y(), p.z()));
  }
  return best->q;
}

Result<JointVector> RobotModel::inverse(const Eigen::Isometry3d& base_T_tool,
                                        std::string_view branch,
                                        const JointVector& seed) const {
  auto all = inverse_all(base_T_tool, seed);
  if (!all) {
    return std::move(all).error();
  }
  return pick_branch(joints(), *all, branch_names(), branch);
}

Status RobotModel::check_limits(const JointVector& q) const {
  return kinematics::check_limits(joints(), q);
}

Result<CountVector> RobotModel::to_counts(const JointVector& q) const {
  return kinematics::to_counts(joints(), q);
}

Result<JointVector> RobotModel::from_counts(const CountVector& counts) const {
  return kinematics::from_counts(joints(), counts);
}

}  // namespace cell::kinematics
