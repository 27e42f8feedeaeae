#include "cell/geometry/angles.hpp"

namespace cell::geometry {

namespace detail {

double wrap_to_pi_slow(double angle) noexcept {
  // More than one turn away (or not finite): the inline fast paths did not apply.
  if (!std::isfinite(angle)) {
    return angle;
  }
  double r = std::remainder(angle, 2.0 * kPi);  // [-pi, pi]
  if (r <= -kPi) {
    r += 2.0 * kPi;
  }
  return r;
}

}  // namespace detail

double fold_half_turn(double angle) noexcept {
  if (!std::isfinite(angle)) {
    return angle;
  }
  double r = std::remainder(angle, kPi);  // [-pi/2, pi/2]
  if (r <= -kPi / 2.0) {
    r += kPi;
  }
  return r;
}

}  // namespace cell::geometry
