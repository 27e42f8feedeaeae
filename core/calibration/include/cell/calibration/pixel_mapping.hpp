#pragma once

#include <Eigen/Geometry>

#include "cell/calibration/camera_calibration.hpp"
#include "cell/common/result.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/render/camera_model.hpp"

/// From pixels to the robot and back with a calibration: the step vision takes for every part.
/// Frames: base = the base frame of the calibration's robot_id; a pixel's ray is cut with the
/// working plane z = working_plane_z_mm (+ a height above it: a part's top face). mm, rad, px.
namespace cell::calibration {

/// base_T_camera for a calibration: fixed, its extrinsics; eye-in-hand, base_T_mount *
/// mount_T_camera (base_T_mount from render::base_T_mount for the robot's joints at exposure).
Eigen::Isometry3d base_T_camera(const CameraCalibration& calibration,
                                const Eigen::Isometry3d& base_T_mount);

/// The point where `pixel`'s ray through `camera` at `base_T_camera` meets the plane z =
/// `plane_z_mm` of the base frame. Errors: kOutOfRange when the pixel cannot be unprojected
/// (beyond the lens's fold), the ray is parallel to the plane or meets it behind the camera.
Result<Eigen::Vector3d> pixel_to_plane(const render::CameraModel& camera,
                                       const Eigen::Isometry3d& base_T_camera,
                                       const Eigen::Vector2d& pixel, double plane_z_mm);

/// The pixel of base point `p_base` (CameraModel::project's errors).
Result<Eigen::Vector2d> base_to_pixel(const render::CameraModel& camera,
                                      const Eigen::Isometry3d& base_T_camera,
                                      const Eigen::Vector3d& p_base);

/// Either model type: the base point of the working plane (plus `height_above_plane_mm`) that
/// `pixel` sees with the robot at joints `q` (ignored for a fixed camera; `robot` may then be
/// null). Pinhole: pixel_to_plane with render::base_T_mount. Planar 7545: planar_model.hpp
/// with J1, J2 = q[0], q[1] (its own link lengths) and the parallax for the height.
/// Errors: kInvalidArgument for an invalid calibration, a missing robot or a joint vector of
/// the wrong size for an eye-in-hand camera; pixel_to_plane's errors.
Result<Eigen::Vector3d> pixel_to_base(const CameraCalibration& calibration,
                                      const kinematics::RobotModel* robot,
                                      const kinematics::JointVector& q,
                                      const Eigen::Vector2d& pixel,
                                      double height_above_plane_mm = 0.0);

}  // namespace cell::calibration
