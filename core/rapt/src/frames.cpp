#include "cell/rapt/frames.hpp"

#include <cmath>

#include "cell/geometry/rapt.hpp"

namespace cell::rapt {

Eigen::Matrix4d to_thesis(const Pose& pose) noexcept { return geometry::to_row_major_rapt(pose); }

Result<Pose> from_thesis(const Eigen::Matrix4d& row_form, double tol) {
  return geometry::from_row_major_rapt(row_form, tol);
}

Pose flip_x() noexcept {
  Pose p = Pose::Identity();
  // Rot(Y, pi) written out exactly (no 1e-16 noise from cos(pi)).
  p.linear() << -1, 0, 0, 0, 1, 0, 0, 0, -1;
  return p;
}

Pose rot_x(double rad) noexcept {
  Pose p = Pose::Identity();
  p.linear() = Eigen::AngleAxisd(rad, Eigen::Vector3d::UnitX()).toRotationMatrix();
  return p;
}

Pose translation(const Eigen::Vector3d& t) noexcept {
  Pose p = Pose::Identity();
  p.translation() = t;
  return p;
}

Eigen::Vector3d any_perpendicular(const Eigen::Vector3d& v) noexcept {
  // The coordinate axis least aligned with v, made perpendicular.
  Eigen::Vector3d ref = Eigen::Vector3d::UnitX();
  if (std::abs(v.y()) < std::abs(v.x()) && std::abs(v.y()) <= std::abs(v.z())) {
    ref = Eigen::Vector3d::UnitY();
  } else if (std::abs(v.z()) < std::abs(v.x()) && std::abs(v.z()) < std::abs(v.y())) {
    ref = Eigen::Vector3d::UnitZ();
  }
  return (ref - ref.dot(v) * v).normalized();
}

Pose frame_from_x(const Eigen::Vector3d& origin,
                  const Eigen::Vector3d& x,
                  const Eigen::Vector3d& y_hint) noexcept {
  Eigen::Vector3d y = y_hint - y_hint.dot(x) * x;
  if (y.norm() < 1e-9) {
    y = any_perpendicular(x);
  } else {
    y.normalize();
  }
  Pose p = Pose::Identity();
  p.linear().col(0) = x;
  p.linear().col(1) = y;
  p.linear().col(2) = x.cross(y);
  p.translation() = origin;
  return p;
}

Eigen::Matrix3d rotation_between(const Eigen::Vector3d& a, const Eigen::Vector3d& b) noexcept {
  const double c = a.dot(b);
  if (c < -1.0 + 1e-12) {
    return Eigen::AngleAxisd(M_PI, any_perpendicular(a)).toRotationMatrix();
  }
  return Eigen::Quaterniond::FromTwoVectors(a, b).toRotationMatrix();
}

Eigen::Matrix3d rotation_from_pairs(const Eigen::Vector3d& v1,
                                    const Eigen::Vector3d& v2,
                                    const Eigen::Vector3d& w1,
                                    const Eigen::Vector3d& w2) noexcept {
  Eigen::Matrix3d b;
  b.col(0) = v1;
  b.col(1) = v1.cross(v2).normalized();
  b.col(2) = b.col(0).cross(b.col(1));
  Eigen::Matrix3d a;
  a.col(0) = w1;
  a.col(1) = w1.cross(w2).normalized();
  a.col(2) = a.col(0).cross(a.col(1));
  return a * b.transpose();
}

double rotation_angle(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) noexcept {
  const Eigen::Matrix3d r = a.transpose() * b;
  const double s =
      0.5 * Eigen::Vector3d(r(2, 1) - r(1, 2), r(0, 2) - r(2, 0), r(1, 0) - r(0, 1)).norm();
  const double c = 0.5 * (r.trace() - 1.0);
  return std::atan2(s, c);
}

bool parallel(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double tol_rad) noexcept {
  return a.cross(b).norm() <= std::sin(tol_rad);
}

bool perpendicular(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double tol_rad) noexcept {
  return std::abs(a.dot(b)) <= std::sin(tol_rad);
}

}  // namespace cell::rapt
