#pragma once

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "common.h"

/// Conversion between Eigen poses and the bus's `cell::common::Pose` (idl/common.idl):
/// translation in mm, rotation as a unit quaternion (w, x, y, z), a_T_b as everywhere.
namespace cell::geometry {

/// The bus form of a pose. Pure, allocation-free.
cell_common_Pose pose_to_idl(const Eigen::Isometry3d& a_T_b) noexcept;

/// A pose from the bus. Errors (kInvalidArgument): a non-finite value, or a quaternion whose
/// norm is not within 10 % of 1 (not a rotation; a small drift is normalised away).
Result<Eigen::Isometry3d> pose_from_idl(const cell_common_Pose& pose);

}  // namespace cell::geometry
