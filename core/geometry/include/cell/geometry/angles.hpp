#pragma once

#include <cmath>
#include <numbers>

namespace cell::geometry {

/// pi, for readability at call sites.
inline constexpr double kPi = std::numbers::pi;

/// One degree in radians: `x_deg * kDeg` is radians. Use only at the edges (config, CLI,
/// protocols that speak degrees, tests written in the thesis's degrees).
inline constexpr double kDeg = kPi / 180.0;

/// Degrees to radians. Use only at the edges (config, CLI, protocols that speak degrees).
constexpr double deg_to_rad(double deg) noexcept { return deg * (kPi / 180.0); }

/// Radians to degrees, for messages and protocols that speak degrees.
constexpr double rad_to_deg(double rad) noexcept { return rad * (180.0 / kPi); }

namespace detail {
double wrap_to_pi_slow(double angle) noexcept;
}  // namespace detail

/// Wraps an angle [rad] into (-pi, pi]: wrap_to_pi(pi) == pi, wrap_to_pi(-pi) == pi.
/// Non-finite input is returned unchanged (NaN stays NaN). Pure, allocation-free, RT-safe.
inline double wrap_to_pi(double angle) noexcept {
  // Fast paths (inline): angles from atan2 and their +-pi flips are within one turn.
  if (angle > -kPi && angle <= kPi) {
    return angle;
  }
  if (angle > kPi && angle <= 3.0 * kPi) {
    const double r = angle - 2.0 * kPi;
    return r > -kPi ? r : kPi;
  }
  if (angle <= -kPi && angle > -3.0 * kPi) {
    const double r = angle + 2.0 * kPi;
    return r <= kPi ? r : kPi;
  }
  return detail::wrap_to_pi_slow(angle);
}

/// Folds an angle [rad] into (-pi/2, pi/2] by adding a multiple of pi: the equivalent angle of a
/// 180-degree-symmetric object (an IC, a parallel-jaw grip). The 7545 code folds the IC
/// orientation the same way (digest 000 §5, "wrapped into [-90, 90] by +-180").
double fold_half_turn(double angle) noexcept;

/// The angle equal to `angle` modulo 2*pi that is closest to `reference` [rad]; ties go to the
/// larger value. Used to keep revolute joints continuous (unwrapping toward the current joints).
inline double nearest_equivalent(double angle, double reference) noexcept {
  return reference + wrap_to_pi(angle - reference);
}

}  // namespace cell::geometry
