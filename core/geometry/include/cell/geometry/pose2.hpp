#pragma once

#include <Eigen/Geometry>

#include "cell/common/result.hpp"

namespace cell::geometry {

/// A planar pose (x [mm], y [mm], rz [rad]) in the SCARA world and on the conveyor: the frame b
/// seen from frame a, named `a_T_b` like 3-D poses. As a matrix it is
/// [cos rz, -sin rz, x; sin rz, cos rz, y; 0, 0, 1] acting on column vectors.
///
/// The Adept V+ compound transform `a:b` (digest 002 §2.1, `part.loc = to.cam:vis.loc:grip.part`)
/// is exactly planar composition: `a:b:c` == `a * b * c`.
struct Pose2 {
  double x = 0.0;   ///< [mm]
  double y = 0.0;   ///< [mm]
  double rz = 0.0;  ///< rotation about z [rad]; compose() wraps it into (-pi, pi]

  /// The identity pose.
  static Pose2 identity() noexcept { return {}; }
  /// Convenience for tests and config: angle given in degrees.
  static Pose2 from_deg(double x_mm, double y_mm, double rz_deg) noexcept;
};

/// a_T_c = a_T_b * b_T_c (V+ `a:b`). The result's rz is wrapped into (-pi, pi]. RT-safe.
Pose2 compose(const Pose2& a_T_b, const Pose2& b_T_c) noexcept;

/// Same as compose().
inline Pose2 operator*(const Pose2& a_T_b, const Pose2& b_T_c) noexcept {
  return compose(a_T_b, b_T_c);
}

/// b_T_a from a_T_b: inverse(p) * p == identity. rz wrapped into (-pi, pi].
Pose2 inverse(const Pose2& a_T_b) noexcept;

/// p_a = a_T_b * p_b for a planar point [mm].
Eigen::Vector2d transform_point(const Pose2& a_T_b, const Eigen::Vector2d& p_b) noexcept;

/// The 3-D pose Trans(x, y, z) * Rz(rz): the planar pose lifted to height `z` [mm].
Eigen::Isometry3d to_3d(const Pose2& pose, double z = 0.0) noexcept;

/// The planar part of a 3-D pose whose z axis is parallel to the parent's z axis (within
/// `tol_rad`); the height is dropped. Errors: kInvalidArgument when the pose is tilted, with the
/// tilt angle in degrees.
Result<Pose2> from_3d(const Eigen::Isometry3d& a_T_b, double tol_rad = 1e-6);

}  // namespace cell::geometry
