#pragma once

#include <optional>

#include <Eigen/Core>

#include "cell/common/result.hpp"

namespace cell::kinematics {

/// A closed interval [lower, upper] in mm.
struct Interval {
  double lower = 0.0;
  double upper = 0.0;

  /// True when lower <= value <= upper (within `tol`).
  bool contains(double value, double tol = 1e-9) const noexcept {
    return value >= lower - tol && value <= upper + tol;
  }
};

/// The base guard of the Excalibur (digest 001 §3.3): a vertical cylinder around the base axis,
/// from the table up to `height_mm`, that the tool point must not enter. The thesis gives only
/// "R = sqrt(x^2 + y^2) < R_base is refused"; we bound it in height as well, so that a tool
/// point straight above the shoulder (digest case 8) stays reachable.
struct BaseGuard {
  double radius_mm = 0.0;  ///< > 0
  double height_mm = 0.0;  ///< > 0, measured from the base frame's z = 0
};

/// Cartesian limits of the tool point, expressed in the robot base frame [mm]. Each bound is
/// optional. Immutable part of a robot model.
///   - 7545: X in [-650, 650], Y in [-386, 650] (digest 000 §2.1, checked before IK as the code).
///   - Excalibur: z >= 0 (the table guard, digest 001 §3.3) and the base guard.
struct CartesianLimits {
  std::optional<Interval> x;            ///< config cartesian_limits.x_mm: [lower, upper]
  std::optional<Interval> y;            ///< config cartesian_limits.y_mm
  std::optional<Interval> z;            ///< config cartesian_limits.z_mm (z lower = table)
  std::optional<BaseGuard> base_guard;  ///< config cartesian_limits.base_guard

  /// Ok when the tool point `p_base` [mm] satisfies every bound. Errors: kOutOfRange naming the
  /// bound and the values, e.g. "tool point y = -400.000 mm is outside cartesian_limits.y_mm
  /// [-386.000, 650.000] mm", or "... is inside the base guard (radius 12.000 mm < 120.000 mm
  /// at z = 100.000 mm < 254.000 mm)". Allocation-free on success.
  Status check(const Eigen::Vector3d& p_base) const;
};

}  // namespace cell::kinematics
