#include "cell/geometry/pose2.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/geometry/angles.hpp"

namespace cell::geometry {

Pose2 Pose2::from_deg(double x_mm, double y_mm, double rz_deg) noexcept {
  return Pose2{x_mm, y_mm, deg_to_rad(rz_deg)};
}

Pose2 compose(const Pose2& a_T_b, const Pose2& b_T_c) noexcept {
  const double c = std::cos(a_T_b.rz);
  const double s = std::sin(a_T_b.rz);
  return Pose2{a_T_b.x + c * b_T_c.x - s * b_T_c.y, a_T_b.y + s * b_T_c.x + c * b_T_c.y,
               wrap_to_pi(a_T_b.rz + b_T_c.rz)};
}

Pose2 inverse(const Pose2& a_T_b) noexcept {
  const double c = std::cos(a_T_b.rz);
  const double s = std::sin(a_T_b.rz);
  return Pose2{-(c * a_T_b.x + s * a_T_b.y), s * a_T_b.x - c * a_T_b.y, wrap_to_pi(-a_T_b.rz)};
}

Eigen::Vector2d transform_point(const Pose2& a_T_b, const Eigen::Vector2d& p_b) noexcept {
  const double c = std::cos(a_T_b.rz);
  const double s = std::sin(a_T_b.rz);
  return {a_T_b.x + c * p_b.x() - s * p_b.y(), a_T_b.y + s * p_b.x() + c * p_b.y()};
}

Eigen::Isometry3d to_3d(const Pose2& pose, double z) noexcept {
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = Eigen::AngleAxisd(pose.rz, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  out.translation() = Eigen::Vector3d(pose.x, pose.y, z);
  return out;
}

Result<Pose2> from_3d(const Eigen::Isometry3d& a_T_b, double tol_rad) {
  const Eigen::Matrix3d r = a_T_b.linear();
  const Eigen::Vector3d z_axis = r.col(2);
  const double tilt = std::atan2(std::hypot(z_axis.x(), z_axis.y()), z_axis.z());
  if (!a_T_b.matrix().allFinite()) {
    return Error{Errc::kInvalidArgument, "planar pose: the 3-D pose has non-finite elements"};
  }
  if (tilt > tol_rad) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("planar pose: z axis is tilted {:.6f} deg from the parent's z axis "
                             "(tolerance {:.6f} deg)",
                             rad_to_deg(tilt), rad_to_deg(tol_rad))};
  }
  return Pose2{a_T_b.translation().x(), a_T_b.translation().y(), std::atan2(r(1, 0), r(0, 0))};
}

}  // namespace cell::geometry
