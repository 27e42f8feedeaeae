#include "cell/kinematics/scara.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "model_issues.hpp"
#include "describe.hpp"

namespace cell::kinematics {
namespace {

using geometry::kPi;
using geometry::wrap_to_pi;

constexpr double kTiltToleranceRad = 1e-6;  // flange z axis vs base z
const double kCosTiltTolerance = std::cos(kTiltToleranceRad);
constexpr double kReachToleranceMm = 1e-9;  // at the inner and outer reach circles
constexpr double kRollOnShoulderAxisMm = 1e-10;  // R axis on the J1 axis: J1 undetermined

double roll_sign(const ScaraModel& model) noexcept {
  return model.roll_sense == RotationSense::kClockwise ? -1.0 : 1.0;
}

// Solves into `out` (both branches, or only `only` when it is 0 or 1). Allocation-free unless it
// fails.
Status solve(const ScaraModel& model,
             const Eigen::Isometry3d& base_T_tool,
             const ScaraJoints* reference,
             IkSolutions& out,
             int only = -1) {
  CELL_TRY(geometry::check_rigid(base_T_tool, "base_T_tool"));
  CELL_TRY(model.cartesian_limits.check(base_T_tool.translation()));
  const Eigen::Isometry3d base_T_flange =
      base_T_tool * model.flange_T_tool.inverse(Eigen::Isometry);
  const Eigen::Matrix3d& r = base_T_flange.linear();
  // cos(tilt) = r(2, 2); the angle itself is only needed for the message.
  if (r(2, 2) < kCosTiltTolerance) {
    const double tilt = std::atan2(std::hypot(r(0, 2), r(1, 2)), r(2, 2));
    return Error{Errc::kInvalidArgument,
                 fmt::format("base_T_tool: the flange z axis is tilted {:.6f} deg from the base z "
                             "axis; a SCARA reaches vertical tool axes only",
                             geometry::rad_to_deg(tilt))};
  }
  const double x = base_T_flange.translation().x();
  const double y = base_T_flange.translation().y();
  const double z = base_T_flange.translation().z();
  const double l1 = model.link1_mm;
  const double l2 = model.link2_mm;
  const double r2 = x * x + y * y;
  const double rho = std::sqrt(r2);
  const double reach_in = std::abs(l1 - l2);
  const double reach_out = l1 + l2;
  if (rho > reach_out + kReachToleranceMm || rho < reach_in - kReachToleranceMm) {
    return Error{Errc::kOutOfRange,
                 fmt::format("target R axis (x, y) = ({:.3f}, {:.3f}) mm is {:.3f} mm from the J1 "
                             "axis; the arm reaches [{:.3f}, {:.3f}] mm (|link1 - link2| to "
                             "link1 + link2)",
                             x, y, rho, reach_in, reach_out)};
  }
  const double yaw = std::atan2(r(1, 0), r(0, 0));
  const double z_joint =
      model.z_direction == ZDirection::kDown ? model.z_at_zero_mm - z : z - model.z_at_zero_mm;

  // Digest 000 §5, the 7545 code (not the thesis text): w = (X^2 + Y^2 + l1^2 - l2^2) / (2 l1)
  // (the code hard-codes 97500 / 800 for 400/250 mm; we use the configured links),
  // J1 = atan2(Y, X) + atan2(-sqrt(X^2 + Y^2 - w^2), w), J2 = atan2(-X sJ1 + Y cJ1,
  // X cJ1 + Y sJ1 - l1). The -sqrt root is the J2 >= 0 branch; +sqrt gives J2 <= 0.
  // cos/sin of J1 come from the angle-sum formula instead of cos(J1)/sin(J1).
  const double w = (r2 + l1 * l1 - l2 * l2) / (2.0 * l1);
  const double h = std::sqrt(std::max(r2 - w * w, 0.0));
  const bool on_axis = rho < kRollOnShoulderAxisMm;
  const double cos_bearing = on_axis ? 1.0 : x / rho;
  const double sin_bearing = on_axis ? 0.0 : y / rho;
  const double wh = std::sqrt(w * w + h * h);

  const std::uint8_t first = only == 1 ? 1 : 0;
  const std::uint8_t last = only == 0 ? 0 : 1;
  out.resize(static_cast<std::size_t>(last) - static_cast<std::size_t>(first) + 1);
  for (std::uint8_t b = first; b <= last; ++b) {
    const bool positive = b == 0;
    double j1 = 0.0;
    double j2 = 0.0;
    if (on_axis) {  // only when l1 == l2: J1 is free, the elbow folds completely
      j1 = reference != nullptr ? (*reference)(0) : 0.0;
      j2 = positive ? kPi : -kPi;
    } else {
      const double cos_phi = w / wh;
      const double sin_phi = (positive ? -h : h) / wh;
      const double c1 = cos_bearing * cos_phi - sin_bearing * sin_phi;
      const double s1 = sin_bearing * cos_phi + cos_bearing * sin_phi;
      j1 = std::atan2(s1, c1);
      j2 = std::atan2(-x * s1 + y * c1, x * c1 + y * s1 - l1);
    }
    double roll = roll_from_tool_yaw(model, j1, j2, yaw);
    // Unwrap the revolute joints into their limits, toward the reference when there is one.
    // Shifting J1/J2 by whole turns leaves the pose, and R, unchanged.
    j1 = fit_revolute(model.joints[0], j1, reference ? (*reference)(0) : wrap_to_pi(j1));
    j2 = fit_revolute(model.joints[1], j2, reference ? (*reference)(1) : wrap_to_pi(j2));
    roll = fit_revolute(model.joints[3], roll, reference ? (*reference)(3) : roll);

    IkSolution& s = out[b - first];
    s.q.resize(4);
    s.q << j1, j2, z_joint, roll;
    s.branch = kScaraBranchNames[b];
    s.branch_index = b;
    s.violated_joint = static_cast<std::int8_t>(first_limit_violation(model.joints, s.q));
    s.singular = on_axis;
  }
  return ok_status();
}

using detail::describe_target;

Status check_reference(const ScaraJoints& reference) {
  if (!reference.allFinite()) {
    return Error{Errc::kInvalidArgument, "reference joints are not finite"};
  }
  return ok_status();
}

}  // namespace

Status ScaraModel::validate() const { return detail::to_status(detail::scara_issues(*this)); }

std::string_view to_string(ElbowBranch branch) noexcept {
  return kScaraBranchNames[static_cast<std::size_t>(branch)];
}

double tool_yaw_from_roll(const ScaraModel& model, double j1, double j2, double r) noexcept {
  const double link_yaw = model.roll_reference == RollReference::kLink2 ? j1 + j2 : 0.0;
  return link_yaw + roll_sign(model) * r;
}

double roll_from_tool_yaw(const ScaraModel& model, double j1, double j2, double yaw) noexcept {
  const double link_yaw = model.roll_reference == RollReference::kLink2 ? j1 + j2 : 0.0;
  return wrap_to_pi(roll_sign(model) * (yaw - link_yaw));
}

Eigen::Isometry3d forward(const ScaraModel& model, const ScaraJoints& q) noexcept {
  const double j1 = q(0);
  const double j12 = q(0) + q(1);
  const double yaw = tool_yaw_from_roll(model, q(0), q(1), q(3));
  const double z = model.z_direction == ZDirection::kDown ? model.z_at_zero_mm - q(2)
                                                          : model.z_at_zero_mm + q(2);
  Eigen::Isometry3d base_T_flange = Eigen::Isometry3d::Identity();
  const double cy = std::cos(yaw);
  const double sy = std::sin(yaw);
  base_T_flange.linear() << cy, -sy, 0.0, sy, cy, 0.0, 0.0, 0.0, 1.0;
  base_T_flange.translation() << model.link1_mm * std::cos(j1) + model.link2_mm * std::cos(j12),
      model.link1_mm * std::sin(j1) + model.link2_mm * std::sin(j12), z;
  return base_T_flange * model.flange_T_tool;
}

Result<IkSolutions> inverse_all(const ScaraModel& model, const Eigen::Isometry3d& base_T_tool) {
  Result<IkSolutions> out{IkSolutions{}};
  CELL_TRY(solve(model, base_T_tool, nullptr, *out));
  return out;
}

Result<IkSolutions> inverse_all(const ScaraModel& model,
                                const Eigen::Isometry3d& base_T_tool,
                                const ScaraJoints& reference) {
  CELL_TRY(check_reference(reference));
  Result<IkSolutions> out{IkSolutions{}};
  CELL_TRY(solve(model, base_T_tool, &reference, *out));
  return out;
}

namespace {

Result<ScaraJoints> one_branch(const ScaraModel& model,
                               const Eigen::Isometry3d& base_T_tool,
                               ElbowBranch branch,
                               const ScaraJoints* reference) {
  IkSolutions out;
  CELL_TRY(solve(model, base_T_tool, reference, out, static_cast<int>(branch)));
  const IkSolution& s = out[0];
  if (!s.within_limits()) {
    return pick_branch(model.joints, out, kScaraBranchNames, s.branch).error();
  }
  return ScaraJoints(s.q);
}

}  // namespace

Result<ScaraJoints> inverse(const ScaraModel& model,
                            const Eigen::Isometry3d& base_T_tool,
                            ElbowBranch branch) {
  return one_branch(model, base_T_tool, branch, nullptr);
}

Result<ScaraJoints> inverse(const ScaraModel& model,
                            const Eigen::Isometry3d& base_T_tool,
                            ElbowBranch branch,
                            const ScaraJoints& reference) {
  CELL_TRY(check_reference(reference));
  return one_branch(model, base_T_tool, branch, &reference);
}

Result<ScaraJoints> inverse(const ScaraModel& model,
                            const Eigen::Isometry3d& base_T_tool,
                            const ScaraJoints& seed) {
  CELL_TRY(check_reference(seed));
  IkSolutions all;
  CELL_TRY(solve(model, base_T_tool, &seed, all));
  const JointVector seed_v = seed;
  const IkSolution* best = all.nearest(model.joints, seed_v);
  if (best == nullptr) {
    return no_branch_within_limits(model.joints, all, describe_target(base_T_tool));
  }
  return ScaraJoints(best->q);
}

}  // namespace cell::kinematics
