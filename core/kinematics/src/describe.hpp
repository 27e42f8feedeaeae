#pragma once

// Text for the solvers' error messages (private).

#include <string>

#include <Eigen/Geometry>
#include <fmt/format.h>

namespace cell::kinematics::detail {

/// "target (x, y, z) mm": the tool point a solver was asked for, in the base frame.
inline std::string describe_target(const Eigen::Isometry3d& base_T_tool) {
  const Eigen::Vector3d p = base_T_tool.translation();
  return fmt::format("target ({:.3f}, {:.3f}, {:.3f}) mm", p.x(), p.y(), p.z());
}

}  // namespace cell::kinematics::detail
