#include "cell/rapt/camera.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace cell::rapt {

namespace {
constexpr double kMinDepthMm = 1e-9;
}

Result<ImagePoint> CameraModel::project(const Eigen::Vector3d& p_world) const {
  const Eigen::Vector3d p = world_T_camera.inverse() * p_world;
  if (!(p.x() > kMinDepthMm)) {
    return Error{Errc::kOutOfRange,
                 fmt::format("the point ({:.3f}, {:.3f}, {:.3f}) mm is behind the camera (depth "
                             "{:.3f} mm along the lens axis)",
                             p_world.x(), p_world.y(), p_world.z(), p.x())};
  }
  return ImagePoint(focus * p.y() / p.x(), focus * p.z() / p.x());
}

Eigen::Matrix<double, 2, 3> CameraModel::jacobian(const Eigen::Vector3d& p_world) const {
  const Eigen::Matrix3d r_cw = world_T_camera.linear().transpose();
  const Eigen::Vector3d p = world_T_camera.inverse() * p_world;
  Eigen::Matrix<double, 2, 3> d_dp;                              // d(y,z)/d(a,b,c)
  d_dp << -focus * p.y() / (p.x() * p.x()), focus / p.x(), 0.0,  //
      -focus * p.z() / (p.x() * p.x()), 0.0, focus / p.x();
  return d_dp * r_cw;
}

Eigen::Vector3d CameraModel::ray(const ImagePoint& image) const {
  return (world_T_camera.linear() * Eigen::Vector3d(focus, image.x(), image.y())).normalized();
}

Result<Plane> face_from_image(const CameraModel& camera,
                              const ImagePoint& p1,
                              const ImagePoint& p2) {
  if (!p1.allFinite() || !p2.allFinite()) {
    return Error{Errc::kInvalidArgument, "image end points must be finite numbers"};
  }
  const Eigen::Vector3d r1(camera.focus, p1.x(), p1.y());
  const Eigen::Vector3d r2(camera.focus, p2.x(), p2.y());
  const Eigen::Vector3d n = r1.cross(r2);
  if (n.norm() < 1e-12 * r1.norm() * r2.norm()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("the image end points ({}, {}) and ({}, {}) coincide: they do not "
                             "define an edge",
                             p1.x(), p1.y(), p2.x(), p2.y())};
  }
  Plane plane;
  plane.point = camera.world_T_camera.translation();
  plane.normal = (camera.world_T_camera.linear() * n).normalized();
  return plane;
}

Result<Window> suggest_window(const CameraModel& camera,
                              const Eigen::Vector3d& q1,
                              const Eigen::Vector3d& q2,
                              const Eigen::Vector3d& tolerance_mm) {
  auto e1 = camera.project(q1);
  if (!e1) {
    return e1.error();
  }
  auto e2 = camera.project(q2);
  if (!e2) {
    return e2.error();
  }
  Window w;
  Eigen::Vector2d along = *e2 - *e1;
  const double length = along.norm();
  if (length < 1e-12) {
    along = Eigen::Vector2d::UnitX();  // the edge points at the lens: a dot
  } else {
    along /= length;
  }
  const Eigen::Vector2d across(-along.y(), along.x());
  const Eigen::Vector3d tol = tolerance_mm.cwiseAbs();
  auto extent = [&](const Eigen::Vector3d& q, const Eigen::Vector2d& dir) {
    const Eigen::Matrix<double, 2, 3> j = camera.jacobian(q);
    const Eigen::RowVector3d s = dir.transpose() * j;
    return s.cwiseAbs().dot(tol.transpose());
  };
  w.half_width = std::max(extent(q1, across), extent(q2, across));
  w.margin1 = extent(q1, along);
  w.margin2 = extent(q2, along);
  Eigen::Vector2d s1 = *e1 + w.margin1 * along;
  Eigen::Vector2d s2 = *e2 - w.margin2 * along;
  if ((s2 - s1).dot(along) < 0.0) {
    w.guaranteed = false;
    s1 = s2 = 0.5 * (*e1 + *e2);
  }
  w.p1 = s1 - w.half_width * across;
  w.p2 = s1 + w.half_width * across;
  w.p3 = s2 - w.half_width * across;
  return w;
}

}  // namespace cell::rapt
