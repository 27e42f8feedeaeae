#pragma once

#include <Eigen/Geometry>

#include "cell/common/result.hpp"

/// Adapter for the row-vector convention of the RAPT thesis (Yin 1984, digest 003 §1.4).
///
/// The thesis writes positions as 4x4 matrices acting on homogeneous ROW vectors:
///   - the upper-left 3x3 block's rows are the local frame's X, Y, Z axes in the parent frame;
///   - a41, a42, a43 (the bottom row) are the translation; a14 = a24 = a34 = 0, a44 = 1;
///   - a point maps as P_parent = P_local ** M (eq. 5.3: P_c ** C = P_w);
///   - products read left to right from the inside out: a feature's world pose is f ** p
///     (feature-in-body, then body-in-world); PV = FM ** PN.
/// Such an M is the transpose of our column-vector `parent_T_local.matrix()`, so every product
/// reverses: f ** p == to_row_major_rapt(world_T_body * body_T_feature), and PV = FM ** PN
/// becomes world_T_verified = world_T_nominal * FM_col, with FM acting in the body's nominal frame.
/// core/rapt converts at its boundary with these two functions and nowhere else.
namespace cell::geometry {

/// The thesis-form (row-vector) matrix of `parent_T_local`: its transpose. Pure, RT-safe.
Eigen::Matrix4d to_row_major_rapt(const Eigen::Isometry3d& parent_T_local) noexcept;

/// parent_T_local from a thesis-form matrix (transpose). Errors: kInvalidArgument when `m` is
/// not a rigid position in the thesis's sense (non-finite entries, a14/a24/a34 not 0, a44 not 1,
/// or the 3x3 block not a rotation within `tol`); the message names the offending entries.
Result<Eigen::Isometry3d> from_row_major_rapt(const Eigen::Matrix4d& m, double tol = 1e-6);

}  // namespace cell::geometry
