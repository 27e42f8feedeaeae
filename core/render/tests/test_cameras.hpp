#pragma once

// Cameras the renderer's tests share.

#include <Eigen/Geometry>

#include "cell/render/camera_model.hpp"

namespace cell::render::testing {

/// A camera at `position` [mm, world] looking straight down (camera z = -world z), its x along
/// world x turned by `yaw` [rad] about the vertical: world_T_camera.
inline Eigen::Isometry3d looking_down(const Eigen::Vector3d& position, double yaw = 0.0) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                  Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
  pose.translation() = position;
  return pose;
}

/// The thesis's camera without a lens: 512 x 484, 3.56 x 3.48 px/mm at 420 mm, centre
/// (255, 241).
inline CameraModel pinhole() {
  return CameraModel::create(512, 484, 3.56 * 420, 3.48 * 420, 255.0, 241.0, {}).value();
}

}  // namespace cell::render::testing
