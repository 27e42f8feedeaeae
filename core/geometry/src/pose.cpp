#include "cell/geometry/pose.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/geometry/angles.hpp"

namespace cell::geometry {

Eigen::Matrix3d rotation_from_rpy(const Rpy& rpy) noexcept {
  return (Eigen::AngleAxisd(rpy.yaw, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(rpy.pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(rpy.roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

Rpy rpy_from_rotation(const Eigen::Matrix3d& r) noexcept {
  Rpy out;
  const double cos_pitch = std::hypot(r(0, 0), r(1, 0));
  out.pitch = std::atan2(-r(2, 0), cos_pitch);
  if (cos_pitch < 1e-9) {
    // Gimbal lock: only yaw - roll (pitch = +90 deg) or yaw + roll (pitch = -90 deg) is defined.
    // With roll = 0, R(0,1) = -sin(yaw) and R(1,1) = cos(yaw) in both cases.
    out.roll = 0.0;
    out.yaw = std::atan2(-r(0, 1), r(1, 1));
  } else {
    out.roll = std::atan2(r(2, 1), r(2, 2));
    out.yaw = std::atan2(r(1, 0), r(0, 0));
  }
  out.roll = wrap_to_pi(out.roll);
  out.yaw = wrap_to_pi(out.yaw);
  return out;
}

Eigen::Isometry3d make_pose(const Eigen::Vector3d& translation, const Rpy& rpy) noexcept {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = rotation_from_rpy(rpy);
  pose.translation() = translation;
  return pose;
}

Eigen::Matrix3d rotation_from_paul_rpy(double phi_z, double theta_y, double psi_x) noexcept {
  return rotation_from_rpy(Rpy{.roll = psi_x, .pitch = theta_y, .yaw = phi_z});
}

Eigen::Isometry3d vplus_trans(
    double x, double y, double z, double yaw, double pitch, double roll) noexcept {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
                   Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                   Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()))
                      .toRotationMatrix();
  pose.translation() = Eigen::Vector3d(x, y, z);
  return pose;
}

Eigen::Isometry3d translate_in_frame(const Eigen::Isometry3d& a_T_b,
                                     const Eigen::Vector3d& offset_b) noexcept {
  return a_T_b * Eigen::Translation3d(offset_b);
}

Status check_rigid(const Eigen::Isometry3d& pose, std::string_view what, double tol) {
  const Eigen::Matrix4d& m = pose.matrix();
  if (!m.allFinite()) {
    return Error{Errc::kInvalidArgument, fmt::format("{}: pose has non-finite elements", what)};
  }
  const Eigen::RowVector4d bottom = m.row(3);
  if ((bottom - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > tol) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("{}: bottom row must be (0, 0, 0, 1), got ({}, {}, {}, {})", what,
                             bottom(0), bottom(1), bottom(2), bottom(3))};
  }
  const Eigen::Matrix3d r = m.topLeftCorner<3, 3>();
  const double defect = (r.transpose() * r - Eigen::Matrix3d::Identity()).norm();
  if (defect > tol) {
    return Error{
        Errc::kInvalidArgument,
        fmt::format("{}: rotation is not orthonormal (|R^T R - I| = {:.3g}, tolerance {:.3g})",
                    what, defect, tol)};
  }
  if (r.determinant() < 0.0) {
    return Error{
        Errc::kInvalidArgument,
        fmt::format("{}: rotation is a reflection (determinant {:.6f})", what, r.determinant())};
  }
  return ok_status();
}

double rotation_distance(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) noexcept {
  const Eigen::Quaterniond q(a.transpose() * b);
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

}  // namespace cell::geometry
