#pragma once

// Tolerances of exact arithmetic: what floating-point rounding alone leaves of a computation
// whose true answer is known (a round trip, a closed form, a thesis's exact case). A test that
// needs more slack states its own, named for what it allows.

namespace cell::testing {

inline constexpr double kTolMm = 1e-9;    ///< lengths [mm]
inline constexpr double kTolRad = 1e-12;  ///< angles [rad]
inline constexpr double kTolDeg = 1e-9;   ///< angles where a protocol speaks degrees [deg]
inline constexpr double kTolPx = 1e-9;    ///< image coordinates [px]
inline constexpr double kTol = 1e-12;     ///< dimensionless (matrix entries, quaternions)

}  // namespace cell::testing
