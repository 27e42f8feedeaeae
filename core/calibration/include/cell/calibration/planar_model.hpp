#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

#include "cell/calibration/camera_calibration.hpp"
#include "cell/calibration/report.hpp"
#include "cell/common/result.hpp"

/// The AVRS thesis's planar eye-in-hand model of the IBM 7545's camera (digest 000 §4, §5),
/// done in vector form, and its two calibrations: the thesis's two-stage procedure and an
/// on-line least-squares refinement of every parameter over many observations.
///
/// The model (PlanarParameters of camera_calibration.hpp; pixels (i, j) = (u, v)). With the
/// elbow at (J1, J2), link 2's heading is lambda = J1 + J2 and the end-effector (the R axis) is
///   E = link1 (cos J1, sin J1) + link2 (cos lambda, sin lambda)          (eq. 4.11/4.12)
/// The Ref_Point pixel (b_x, b_y) sees the table point
///   R = E + d_t_c u(lambda + pi + b_angl)
/// i.e. d_t_c from the end-effector, b_angl counter-clockwise from the tip->elbow direction
/// (the digest's "angle between tip->elbow and tip->Ref"). The image axes on the table are
///   e_i = u(lambda + pi - angl_err),  e_j = e_i turned a quarter turn clockwise
/// (the camera's i axis runs back along link 2, turned by angl_err; looking down, the image is
/// mirrored), and pixel (i, j) sees
///   P = R + ((i - b_x) / c_x) e_i + ((j - b_y) / c_y) e_j
/// with c_x, c_y in px/mm. u(a) = (cos a, sin a). This reproduces the thesis's printed
/// equations (eq. 4.4-4.14 with the code's defaults) wherever their absolute values hold: the
/// digest's cases 8-10 to 0.01 mm (tests). It has no sign trap: no atan of a ratio and no
/// absolute value, so every quadrant of the image maps right.
///
/// Parallax (eq. 2.21/2.22): a point h above the table, seen at pixel p, lies over the table
/// point seen at p + (centre - p) h / d_ct, centre = (I_cp, J_cp), d_ct = camera_height_mm.
///
/// The two-stage procedure (Appendix A), vector form. Stage 1: a table point A on the
/// Ref_Point pixel, the elbow at (J1, J2), so A = R(J1, J2). Stage 2: the end-effector over A,
/// its position (x2, y2) = A. Then with E1 = E(J1, J2):
///   d_t_c = |A - E1|,  b_angl = atan2(A - E1) - (J1 + J2 + pi)   (wrapped to [0, 2 pi))
/// which is what A.1-A.5 intend; as printed, A.5 gives 102.3 deg instead of 137.7 (digest 000
/// §4, "sign problem"): this form needs no sign convention for delta.
namespace cell::calibration {

/// The end-effector (R axis) in the base frame [mm] for link lengths and elbow joints [rad].
Eigen::Vector2d planar_end_effector(const PlanarParameters& p, double j1_rad, double j2_rad);

/// Table point [mm, base frame] that `pixel` sees with the elbow at (j1, j2); `height_mm` above
/// the table moves the pixel by the parallax first. Pure; never fails (validate the parameters
/// beforehand: c_x, c_y > 0).
Eigen::Vector2d planar_pixel_to_base(const PlanarParameters& p, double j1_rad, double j2_rad,
                                     const Eigen::Vector2d& pixel, double height_mm = 0.0);

/// Pixel that sees table point `point` [mm, base] with the elbow at (j1, j2) (the inverse).
Eigen::Vector2d planar_base_to_pixel(const PlanarParameters& p, double j1_rad, double j2_rad,
                                     const Eigen::Vector2d& point);

/// The thesis's two-stage readings: stage 1's elbow joints and stage 2's end-effector x, y.
struct TwoStageReading {
  double j1_rad = 0.0;
  double j2_rad = 0.0;
  Eigen::Vector2d stage2_mm = Eigen::Vector2d::Zero();
};

struct TwoStageResult {
  double d_t_c_mm = 0.0;
  double b_angl_rad = 0.0;
  double d_t_c_spread_mm = 0.0;    ///< max - min over the readings
  double b_angl_spread_rad = 0.0;
  int readings = 0;
};

/// d_t_c and b_angl from two-stage readings, averaged (angles as unit vectors) over 1 or more
/// (the thesis repeats it 2-3 times). Link lengths from `p`. Errors: kInvalidArgument for no
/// readings, non-finite values, or a reading whose stage-2 point is on the end-effector.
Result<TwoStageResult> two_stage_calibration(const PlanarParameters& p,
                                             const std::vector<TwoStageReading>& readings);

/// One view for the on-line refinement: the elbow joints at the image and the pixels of points
/// of a flat target lying on the table (its own frame, mm), or of table points known in the
/// base frame.
struct PlanarView {
  std::string id;
  double j1_rad = 0.0;
  double j2_rad = 0.0;
  std::vector<Eigen::Vector2d> pixels;
  std::vector<Eigen::Vector2d> target_points_mm;  ///< target frame (board_known false) or base
};

struct PlanarOptions {
  /// The target's points are in the base frame already (touched or placed points), so no
  /// target pose is estimated. Otherwise the target lies flat at an unknown (x, y, yaw).
  bool target_in_base = false;
  /// Refine the link lengths too (the thesis: link_1 in [399, 401], link_2 in [249, 251]).
  bool refine_links = true;
  double huber_px = 2.0;
  double holdout_fraction = 0.2;
  int min_holdout_views = 1;
  int min_fit_views = 3;
  int max_iterations = 200;
  Status validate() const;
};

struct PlanarReport {
  PlanarParameters parameters;
  Eigen::Vector3d target_pose = Eigen::Vector3d::Zero();  ///< x, y [mm], yaw [rad] on the table
  std::vector<ViewReport> views;
  double rms_px = 0.0;
  double holdout_rms_px = 0.0;
  /// Held-out views: each target point mapped through the model vs where the fit puts it [mm].
  double holdout_mm = 0.0;
  int views_used = 0;
  int views_held_out = 0;
  SolverSummary solver;
  std::string brief() const;
};

/// Refines every parameter of `initial` (c_x, c_y, d_t_c, b_angl, angl_err, link lengths;
/// Ref_Point and the centre stay) by least squares over the views, reprojection error in
/// pixels, with the target's pose on the table when it is not given. Errors: kInvalidArgument
/// for bad options, invalid initial parameters or too few views/points (counted); kOutOfRange
/// when the solve leaves c_x or c_y <= 0. Thread-safe.
Result<PlanarReport> refine_planar(const PlanarParameters& initial,
                                   const std::vector<PlanarView>& views,
                                   const PlanarOptions& options = {},
                                   const ProgressFn& progress = {});

/// The planar parameters a pinhole eye-in-hand calibration implies on its working plane, for
/// the Ref_Point pixel `ref_px` (the thesis's (3, 457)): scales from fx, fy and the camera's
/// height above the plane, angl_err from the camera's yaw against link 2, d_t_c and b_angl
/// from where the Ref_Point's ray meets the plane. Lens distortion is not representable in the
/// planar model and is left out (so is a camera tilt). Errors: kInvalidArgument unless the
/// calibration is a pinhole, eye-in-hand on link 2 of a SCARA with `link1_mm`, `link2_mm`.
Result<PlanarParameters> planar_from_pinhole(const CameraCalibration& calibration,
                                             const Eigen::Vector2d& ref_px,
                                             double link1_mm,
                                             double link2_mm);

}  // namespace cell::calibration
