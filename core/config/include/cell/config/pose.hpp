#pragma once

#include <string>

#include <Eigen/Geometry>

#include "cell/config/yaml.hpp"

namespace cell::config {

/// Reads `key: {xyz_mm: [x, y, z], rpy_deg: [roll, pitch, yaw]}` from `parent` (URDF
/// roll-pitch-yaw, R = Rz(yaw) Ry(pitch) Rx(roll), as the robot and camera files): both keys
/// required, values finite; problems are recorded in `parent` with their line and column.
/// Returns the identity when the pose is missing or bad (the reader has failed then).
Eigen::Isometry3d read_pose(MapReader& parent, const std::string& key);

}  // namespace cell::config
