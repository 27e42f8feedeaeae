#include "cell/geometry/idl_pose.hpp"

#include <fmt/format.h>

namespace cell::geometry {

cell_common_Pose pose_to_idl(const Eigen::Isometry3d& a_T_b) noexcept {
  const Eigen::Quaterniond q(a_T_b.linear());
  const Eigen::Vector3d t = a_T_b.translation();
  cell_common_Pose out{};
  out.position_mm = cell_common_Vector3{t.x(), t.y(), t.z()};
  out.orientation = cell_common_Quaternion{q.w(), q.x(), q.y(), q.z()};
  return out;
}

Result<Eigen::Isometry3d> pose_from_idl(const cell_common_Pose& pose) {
  const Eigen::Vector3d t(pose.position_mm.x, pose.position_mm.y, pose.position_mm.z);
  Eigen::Quaterniond q(pose.orientation.w, pose.orientation.x, pose.orientation.y,
                       pose.orientation.z);
  if (!t.allFinite() || !q.coeffs().allFinite()) {
    return Error{Errc::kInvalidArgument, "pose: non-finite position or orientation"};
  }
  const double n = q.norm();
  if (n < 0.9 || n > 1.1) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("pose: quaternion norm {:.3f} is not 1 (not a unit quaternion)", n)};
  }
  q.normalize();
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = q.toRotationMatrix();
  out.translation() = t;
  return out;
}

}  // namespace cell::geometry
