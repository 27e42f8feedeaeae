#include "cell/calibration/pixel_mapping.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/calibration/planar_model.hpp"
#include "cell/render/mount.hpp"

namespace cell::calibration {

Eigen::Isometry3d base_T_camera(const CameraCalibration& calibration,
                                const Eigen::Isometry3d& base_T_mount) {
  return calibration.mounting == Mounting::kFixed ? calibration.extrinsics
                                                  : base_T_mount * calibration.extrinsics;
}

Result<Eigen::Vector3d> pixel_to_plane(const render::CameraModel& camera,
                                       const Eigen::Isometry3d& base_T_camera,
                                       const Eigen::Vector2d& pixel, double plane_z_mm) {
  auto ray = camera.unproject(pixel);
  if (!ray) {
    return std::move(ray).error();
  }
  const Eigen::Vector3d origin = base_T_camera.translation();
  const Eigen::Vector3d direction = base_T_camera.linear() * *ray;
  if (std::abs(direction.z()) < 1e-12) {
    return Error{Errc::kOutOfRange,
                 fmt::format("pixel ({:.2f}, {:.2f}): its ray runs parallel to the plane z = {} mm",
                             pixel.x(), pixel.y(), plane_z_mm)};
  }
  const double t = (plane_z_mm - origin.z()) / direction.z();
  if (!(t > 0.0)) {
    return Error{Errc::kOutOfRange,
                 fmt::format("pixel ({:.2f}, {:.2f}): the plane z = {} mm lies behind the camera",
                             pixel.x(), pixel.y(), plane_z_mm)};
  }
  return Eigen::Vector3d(origin + t * direction);
}

Result<Eigen::Vector2d> base_to_pixel(const render::CameraModel& camera,
                                      const Eigen::Isometry3d& base_T_camera,
                                      const Eigen::Vector3d& p_base) {
  return camera.project(base_T_camera.inverse() * p_base);
}

Result<Eigen::Vector3d> pixel_to_base(const CameraCalibration& calibration,
                                      const kinematics::RobotModel* robot,
                                      const kinematics::JointVector& q,
                                      const Eigen::Vector2d& pixel,
                                      double height_above_plane_mm) {
  CELL_TRY(calibration.validate());
  const double plane_z = calibration.working_plane_z_mm + height_above_plane_mm;
  if (calibration.model == ModelType::kPlanar7545) {
    if (q.size() < 2 || !q.head(2).allFinite()) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("camera '{}': the planar model needs J1 and J2, got {} joints",
                               calibration.camera_id, q.size())};
    }
    const Eigen::Vector2d xy =
        planar_pixel_to_base(calibration.planar, q[0], q[1], pixel, height_above_plane_mm);
    return Eigen::Vector3d(xy.x(), xy.y(), plane_z);
  }
  auto camera = calibration.camera_model();
  if (!camera) {
    return std::move(camera).error();
  }
  Eigen::Isometry3d mount = Eigen::Isometry3d::Identity();
  if (calibration.mounting == Mounting::kEyeInHand) {
    if (robot == nullptr) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("camera '{}' rides robot '{}': its model is needed",
                               calibration.camera_id, calibration.robot_id)};
    }
    auto m = render::base_T_mount(*robot, calibration.mount_frame, q);
    if (!m) {
      return std::move(m).error();
    }
    mount = *m;
  }
  return pixel_to_plane(*camera, base_T_camera(calibration, mount), pixel, plane_z);
}

}  // namespace cell::calibration
