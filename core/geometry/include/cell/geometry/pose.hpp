#pragma once

#include <string_view>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"

/// Frames and poses of the cell (see core/geometry/README.md).
///
/// Convention: column vectors, millimetres and radians. A pose is an Eigen::Isometry3d named
/// `a_T_b`: it maps coordinates in frame b to frame a (`p_a = a_T_b * p_b`), so chains cancel
/// visibly: `base_T_cam = base_T_tool * tool_T_cam`; composition is `*`, inversion is
/// `.inverse()` (Eigen::Isometry3d::inverse is the rigid inverse).
namespace cell::geometry {

/// Roll, pitch, yaw [rad] in the URDF/ROS convention used throughout the cell's config files
/// (`rpy_deg: [roll, pitch, yaw]`): R = Rz(yaw) * Ry(pitch) * Rx(roll), i.e. rotate about the
/// fixed x axis by roll, then fixed y by pitch, then fixed z by yaw.
struct Rpy {
  double roll = 0.0;   ///< about x [rad]
  double pitch = 0.0;  ///< about y [rad]
  double yaw = 0.0;    ///< about z [rad]
};

/// R = Rz(rpy.yaw) * Ry(rpy.pitch) * Rx(rpy.roll). Pure, RT-safe.
Eigen::Matrix3d rotation_from_rpy(const Rpy& rpy) noexcept;

/// Inverse of rotation_from_rpy for a proper rotation matrix: pitch in [-pi/2, pi/2], roll and
/// yaw in (-pi, pi]. At the gimbal lock (|pitch| = pi/2) roll is set to 0 and the whole
/// rotation about z goes to yaw, so rotation_from_rpy(rpy_from_rotation(R)) == R still holds.
Rpy rpy_from_rotation(const Eigen::Matrix3d& rotation) noexcept;

/// Pose from a translation [mm] and URDF roll-pitch-yaw [rad].
Eigen::Isometry3d make_pose(const Eigen::Vector3d& translation, const Rpy& rpy) noexcept;

/// Paul's RPY (Paul 1981, "Robot Manipulators", and the Excalibur thesis's keyboard moves,
/// digest 001 §4.5): RPY(phi, theta, psi) = Rot(z, phi) * Rot(y, theta) * Rot(x, psi), where Paul
/// calls phi (about z, the approach axis) "roll" and psi (about x) "yaw". It is the same matrix
/// as rotation_from_rpy({.roll = psi, .pitch = theta, .yaw = phi}); only the names swap.
Eigen::Matrix3d rotation_from_paul_rpy(double phi_z, double theta_y, double psi_x) noexcept;

/// Adept V+ location angles (yaw, pitch, roll) [rad]: Z-Y-Z Euler angles,
/// R = Rz(yaw) * Ry(pitch) * Rz(roll) (rotate about z, then the new y, then the new z). A SCARA
/// tool pointing down is pitch = 180 degrees in V+. Used by the conveyor seed (digest 002).
Eigen::Isometry3d vplus_trans(
    double x, double y, double z, double yaw, double pitch, double roll) noexcept;

/// `a_T_b` moved by `offset_b` expressed in frame b: a_T_b * Trans(offset_b). E.g. a relative
/// tool move "+20 mm along the approach vector a" is translate_in_frame(base_T_tool, {0, 0, 20}).
Eigen::Isometry3d translate_in_frame(const Eigen::Isometry3d& a_T_b,
                                     const Eigen::Vector3d& offset_b) noexcept;

/// Ok when every element is finite, the linear part is a rotation (orthonormal to `tol`,
/// determinant +1) and the bottom row is (0, 0, 0, 1). Otherwise kInvalidArgument naming `what`
/// and the defect, e.g. "base_T_tool: rotation is not orthonormal (|R^T R - I| = 0.2)".
Status check_rigid(const Eigen::Isometry3d& pose, std::string_view what, double tol = 1e-6);

/// Angle [rad] of the rotation a^-1 * b (0 when the orientations coincide). Accurate for small
/// angles (uses atan2, not acos).
double rotation_distance(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) noexcept;

}  // namespace cell::geometry
