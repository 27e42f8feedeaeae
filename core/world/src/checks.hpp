#pragma once

// Checks the world's readers share (internal).

#include <cmath>

namespace cell::world::detail {

/// A coordinate beyond 1 km from the world's origin [mm] is a typo or garbage.
inline constexpr double kMaxCoordinateMm = 1e6;

inline bool finite_positive(double v) { return std::isfinite(v) && v > 0.0; }

}  // namespace cell::world::detail
