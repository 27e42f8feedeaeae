#include "cell/geometry/rapt.hpp"

#include <cmath>

#include <fmt/format.h>

namespace cell::geometry {

Eigen::Matrix4d to_row_major_rapt(const Eigen::Isometry3d& parent_T_local) noexcept {
  return parent_T_local.matrix().transpose();
}

Result<Eigen::Isometry3d> from_row_major_rapt(const Eigen::Matrix4d& m, double tol) {
  if (!m.allFinite()) {
    return Error{Errc::kInvalidArgument, "RAPT position matrix has non-finite entries"};
  }
  for (int i = 0; i < 3; ++i) {
    if (std::abs(m(i, 3)) > tol) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("RAPT position matrix: a{}4 must be 0 (row-vector convention: the "
                               "translation is in the bottom row a41..a43), got {}",
                               i + 1, m(i, 3))};
    }
  }
  if (std::abs(m(3, 3) - 1.0) > tol) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("RAPT position matrix: a44 must be 1, got {}", m(3, 3))};
  }
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.matrix() = m.transpose();
  const Eigen::Matrix3d r = out.linear();
  const double defect = (r.transpose() * r - Eigen::Matrix3d::Identity()).norm();
  if (defect > tol || r.determinant() < 0.0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("RAPT position matrix: the upper-left 3x3 block is not a rotation "
                             "(|R^T R - I| = {:.3g}, det = {:.6f})",
                             defect, r.determinant())};
  }
  return out;
}

}  // namespace cell::geometry
