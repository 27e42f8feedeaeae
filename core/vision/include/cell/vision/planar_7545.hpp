#pragma once

#include <Eigen/Core>

#include "cell/calibration/camera_calibration.hpp"
#include "cell/common/result.hpp"

/// The AVRS thesis's planar camera-to-robot model (digest 000 §4, §5 "Camera -> robot
/// position", eq. 4.2-4.14 as the printed code rec_po.c computes them), and its parallax
/// correction (eq. 2.21/2.22). Pure functions; thread-safe.
///
/// Pixels (i, j) = (u, v): i the column, j the row. Joints J1, J2 [rad]; robot coordinates
/// (X, Y) [mm] in the 7545's base frame. The model is written, as the thesis wrote it, for
/// objects in the quadrant of the image away from the Ref_Point corner (it uses |i - b_x| and
/// |j - b_y|); outside that quadrant it is what the thesis computed, not a correct mapping.
namespace cell::vision {

/// Eq. 2.21/2.22 without the integer rounding: the pixel where the table point under a point
/// seen at `px` would appear, for a point `height_mm` above the table and a camera
/// `camera_height_mm` above it, the image centre being `centre_px`:
///   i_N = i + (I_cp - i) * d_ft / d_ct   (and the same for j).
/// (The OCR of the code's x line reads "+ i_c_h/c_i_d"; a "*" is meant, digest 000 §3.)
Eigen::Vector2d thesis_parallax(const Eigen::Vector2d& px,
                                const Eigen::Vector2d& centre_px,
                                double height_mm,
                                double camera_height_mm) noexcept;

/// The thesis's integer form: floor(x + (x0 - x) * h / D + 0.5) per coordinate.
Eigen::Vector2i thesis_parallax_int(const Eigen::Vector2i& px,
                                    const Eigen::Vector2i& centre_px,
                                    double height_mm,
                                    double camera_height_mm) noexcept;

/// Robot (X, Y) [mm] of a table-level pixel `px` (already parallax-corrected) with the arm at
/// J1, J2 [rad] (digest 000 §5):
///   theta = 180 - b_angl - angl_err;  alpha_p = atan(c_y |j - b_y| / (c_x |i - b_x|))
///   (90 deg when i = b_x);  gamma = theta + alpha_p;
///   d_c_ic = |((b_x - i) / c_x, (b_y - j) / c_y)|  (c in px/mm);
///   d_t_ic = sqrt(d_t_c^2 + d_c_ic^2 - 2 d_t_c d_c_ic cos gamma);
///   beta_1 = acos((d_t_c^2 + d_t_ic^2 - d_c_ic^2) / (2 d_t_ic d_t_c));
///   phi = 180 - (b_angl - beta_1) - (J1 + J2);
///   X = X_E + d_t_ic cos phi,  Y = Y_E - d_t_ic sin phi,  (X_E, Y_E) = FK(J1, J2) with the
///   model's link lengths.
/// The thesis's code stores c_x, c_y as mm/px; the calibration holds px/mm, so the factors are
/// divided here. Errors: kInvalidArgument for non-positive scales or non-finite input.
Result<Eigen::Vector2d> planar_pixel_to_base(const calibration::PlanarParameters& planar,
                                             double j1_rad,
                                             double j2_rad,
                                             const Eigen::Vector2d& px);

/// Inverse of planar_pixel_to_base (Newton's method on the forward map, from the image centre),
/// to 1e-9 px. Errors: kOutOfRange when the iteration does not converge (the point is not
/// reachable through the model's quadrant), kInvalidArgument as above.
Result<Eigen::Vector2d> planar_base_to_pixel(const calibration::PlanarParameters& planar,
                                             double j1_rad,
                                             double j2_rad,
                                             const Eigen::Vector2d& base_xy_mm);

/// The image orientation of an IC from its ordered corners, eq. 2.12 as rec_po.c computes it
/// [deg]: dy = (j0 - j1) * aspect, dx = i0 - i1 (and corners 2, 3), a zero dy replaced by 0.01,
/// alpha = mean of atan(dx/dy) over both long sides, or 90 when the two differ by more than 150
/// degrees (long sides near horizontal). `aspect` is the code's c_y/c_x of mm-per-pixel figures,
/// i.e. (c_x / c_y) of the px/mm ones: 3.56/3.48 = 1.023 for the thesis's camera.
double thesis_alpha_deg(const Eigen::Vector2d& c0,
                        const Eigen::Vector2d& c1,
                        const Eigen::Vector2d& c2,
                        const Eigen::Vector2d& c3,
                        double aspect) noexcept;

/// The gripper roll the thesis commands for an IC at image angle `alpha_deg` (eq. 4.2/4.3):
/// O_r = -(alpha + J1 + J2 - 90 - angl_err), wrapped into [-90, 90] by +-180 [deg].
double thesis_roll_deg(double alpha_deg,
                       double j1_rad,
                       double j2_rad,
                       double angl_err_rad) noexcept;

/// R joint counts of a roll [deg]: (long)(O_r * 227.5556), truncated toward zero (rec_po.c).
long thesis_roll_counts(double roll_deg) noexcept;

}  // namespace cell::vision
