#pragma once

#include <Eigen/Geometry>

#include "cell/common/result.hpp"

/// Frames, poses and the one conversion boundary to the thesis's row-vector convention.
///
/// Inside core/rapt every pose is an Eigen::Isometry3d in the project's column-vector
/// convention, named a_T_b (maps b coordinates to a): world_T_body, body_T_feature,
/// world_T_camera. Lengths are mm, angles radians.
///
/// The thesis (Yin 1984, digest 003 §1.4) writes positions as 4x4 matrices acting on ROW
/// vectors: rows 1-3 are the frame's X, Y, Z axes, row 4 the translation; products compose
/// left to right (a feature's world pose is f ** p; PV = FM ** PN). Such a matrix is the
/// transpose of our `matrix()`, so every thesis product reverses order:
///   thesis f ** p            ==  to_thesis(world_T_body * body_T_feature)
///   thesis PV = FM ** PN     ==  world_T_verified = world_T_nominal * FM     (FM in the body's
///                                                                          nominal frame)
///   thesis PV_i ** TA = PV_j ==  world_T_j = TA_col * world_T_i             (TA in world axes)
/// `to_thesis` / `from_thesis` are the only places where a row-form matrix is produced or read
/// (they wrap cell/geometry/rapt.hpp); tests pin the thesis's equations in both forms.
namespace cell::rapt {

/// A rigid pose (column-vector convention), mm.
using Pose = Eigen::Isometry3d;

/// The thesis-form (row-vector) matrix of a pose: its transpose (see the namespace comment).
Eigen::Matrix4d to_thesis(const Pose& pose) noexcept;

/// A pose from a thesis-form matrix. Errors: kInvalidArgument when the matrix is not a rigid
/// row-form position (translation not in the bottom row, 3x3 block not a rotation within
/// `tol`).
Result<Pose> from_thesis(const Eigen::Matrix4d& row_form, double tol = 1e-6);

/// The thesis's M: a half turn about Y, which turns +X into -X (used by AGAINST, FITS, PARAX).
Pose flip_x() noexcept;

/// A rotation by `rad` about X.
Pose rot_x(double rad) noexcept;

/// A pure translation [mm].
Pose translation(const Eigen::Vector3d& t) noexcept;

/// Any unit vector perpendicular to the unit vector `v` (deterministic).
Eigen::Vector3d any_perpendicular(const Eigen::Vector3d& v) noexcept;

/// A right-handed frame with origin `origin`, X axis along the unit vector `x`, and Y the part
/// of `y_hint` perpendicular to X (or any perpendicular when the hint is parallel to X or
/// zero). This is how RAPT's "Y and Z arbitrary but right-handed" (digest §1.4) is fixed here.
Pose frame_from_x(const Eigen::Vector3d& origin,
                  const Eigen::Vector3d& x,
                  const Eigen::Vector3d& y_hint = Eigen::Vector3d::Zero()) noexcept;

/// The smallest rotation turning unit vector `a` into unit vector `b` (a half turn about a
/// perpendicular when they are opposite).
Eigen::Matrix3d rotation_between(const Eigen::Vector3d& a, const Eigen::Vector3d& b) noexcept;

/// The rotation R with R*v1 = w1 and R*v2 ~ w2 (w2's component perpendicular to w1): the triad
/// method. Preconditions: unit vectors, v1 not parallel to v2, w1 not parallel to w2.
Eigen::Matrix3d rotation_from_pairs(const Eigen::Vector3d& v1,
                                    const Eigen::Vector3d& v2,
                                    const Eigen::Vector3d& w1,
                                    const Eigen::Vector3d& w2) noexcept;

/// Angle [rad] of the rotation a^T b (0 when equal); accurate for small angles.
double rotation_angle(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) noexcept;

/// True when the unit vectors are parallel or anti-parallel within `tol_rad`.
bool parallel(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double tol_rad) noexcept;

/// True when the unit vectors are perpendicular within `tol_rad`.
bool perpendicular(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double tol_rad) noexcept;

}  // namespace cell::rapt
