#include "cell/kinematics/workspace.hpp"

#include <cmath>

#include <fmt/format.h>

namespace cell::kinematics {
namespace {

Status check_axis(const std::optional<Interval>& bound,
                  double value,
                  char axis,
                  std::string_view extra) {
  if (bound && !bound->contains(value)) {
    return Error{Errc::kOutOfRange,
                 fmt::format("tool point {} = {:.3f} mm is outside cartesian_limits.{}_mm "
                             "[{:.3f}, {:.3f}] mm{}",
                             axis, value, axis, bound->lower, bound->upper, extra)};
  }
  return ok_status();
}

}  // namespace

Status CartesianLimits::check(const Eigen::Vector3d& p) const {
  CELL_TRY(check_axis(x, p.x(), 'x', ""));
  CELL_TRY(check_axis(y, p.y(), 'y', ""));
  CELL_TRY(check_axis(z, p.z(), 'z', z && p.z() < z->lower ? " (table guard)" : ""));
  if (base_guard) {
    const double radius = std::sqrt(p.x() * p.x() + p.y() * p.y());
    if (radius < base_guard->radius_mm && p.z() < base_guard->height_mm) {
      return Error{Errc::kOutOfRange,
                   fmt::format("tool point ({:.3f}, {:.3f}, {:.3f}) mm is inside the base guard "
                               "(radius {:.3f} mm < {:.3f} mm at z = {:.3f} mm < {:.3f} mm)",
                               p.x(), p.y(), p.z(), radius, base_guard->radius_mm, p.z(),
                               base_guard->height_mm)};
    }
  }
  return ok_status();
}

}  // namespace cell::kinematics
