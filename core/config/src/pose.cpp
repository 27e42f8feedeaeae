#include "cell/config/pose.hpp"

#include <array>
#include <cmath>
#include <numbers>

#include "cell/geometry/pose.hpp"

namespace cell::config {

Eigen::Isometry3d read_pose(MapReader& parent, const std::string& key) {
  constexpr double kDegToRad = std::numbers::pi / 180.0;
  MapReader r = parent.child(key, true);
  std::array<double, 3> xyz{};
  std::array<double, 3> rpy{};
  r.required("xyz_mm", xyz);
  r.required("rpy_deg", rpy);
  for (std::size_t i = 0; i < 3; ++i) {
    if (!std::isfinite(xyz[i]) || !std::isfinite(rpy[i])) {
      r.fail("", "values must be finite");
      break;
    }
  }
  parent.absorb(r);
  return geometry::make_pose(
      Eigen::Vector3d(xyz[0], xyz[1], xyz[2]),
      geometry::Rpy{rpy[0] * kDegToRad, rpy[1] * kDegToRad, rpy[2] * kDegToRad});
}

}  // namespace cell::config
