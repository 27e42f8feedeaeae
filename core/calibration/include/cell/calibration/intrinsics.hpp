#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/calibration/board.hpp"
#include "cell/calibration/report.hpp"
#include "cell/common/result.hpp"
#include "cell/render/camera_model.hpp"

/// Camera intrinsics from board views: a Ceres bundle adjustment of the pinhole model with
/// OpenCV's radial-tangential lens (render::CameraModel: fx, fy, cx, cy [px], k1 k2 p1 p2 k3)
/// over every view's board pose, with a robust loss, a per-view residual report, rejection of
/// outlier views with the reason, and a hold-out figure on views kept out of the fit.
///
/// Procedure. (1) Zhang's closed form through cv::initCameraMatrix2D and a cv::solvePnP per
/// view (no lens); (2) Ceres, robust (Huber) loss, every view; (3) views whose RMS exceeds
/// `outlier_factor` x the median view RMS (and `outlier_min_px`) are rejected, naming their RMS
/// and the limit, and (2) runs again without them, then once more with a plain squared loss so
/// that the result is the least-squares optimum of the inliers; (4) the held-out views get
/// their pose by cv::solvePnP with the fitted model: their RMS is the hold-out figure.
/// Frames: camera_T_board maps the board frame (board.hpp) into the camera frame
/// (camera_model.hpp). Units: mm, rad, px.
namespace cell::calibration {

/// Which lens coefficients are estimated (the others stay 0).
enum class LensModel : std::uint8_t {
  kNone,              ///< ideal pinhole
  kRadial2,           ///< k1 k2
  kRadialTangential,  ///< k1 k2 p1 p2
  kFull,              ///< k1 k2 p1 p2 k3 (OpenCV's default five)
};

struct IntrinsicsOptions {
  /// k3 stays 0 by default: on the cell's narrow lenses (about 20 to 30 degrees of field) it is not
  /// observable and only trades against k1, k2 and the principal point (OpenCV's advice too:
  /// CALIB_FIX_K3 unless the lens is wide).
  LensModel lens = LensModel::kRadialTangential;
  /// Hold fy / fx at `aspect_ratio` (> 0), or at the closed form's ratio when 0.
  bool fix_aspect_ratio = false;
  double aspect_ratio = 0.0;
  /// Hold (cx, cy) at `principal_point_px`, or at the image centre ((w - 1) / 2, (h - 1) / 2).
  bool fix_principal_point = false;
  std::optional<Eigen::Vector2d> principal_point_px;
  /// Huber loss scale [px] for the robust passes (> 0).
  double huber_px = 1.0;
  /// A view is an outlier when its RMS exceeds both outlier_factor x the median view RMS and
  /// outlier_min_px.
  double outlier_factor = 3.0;
  double outlier_min_px = 0.5;
  /// Views kept out of the fit for the hold-out figure: every round(1 / holdout_fraction)-th
  /// view, at least `min_holdout_views` when there are enough views (0 disables).
  double holdout_fraction = 0.2;
  int min_holdout_views = 2;
  /// Fewest views the fit itself needs (after hold-out and rejections), >= 3.
  int min_fit_views = 5;
  /// Fewest corners per view (ChArUco partial views), >= 4.
  int min_corners_per_view = 6;
  int max_iterations = 200;

  /// Ok, or kInvalidArgument naming the option, its value and the rule.
  Status validate() const;
};

/// One view to calibrate from.
struct BoardView {
  std::string id;             ///< e.g. the image file name
  std::int64_t stamp_ns = 0;
  BoardObservation observation;
};

struct IntrinsicsReport {
  render::CameraModel camera;  ///< the fitted model
  std::vector<ViewReport> views;  ///< every input view, in input order
  /// camera_T_board of every view used in the fit or held out (same order as `views`;
  /// identity for rejected ones).
  std::vector<Eigen::Isometry3d> camera_T_board;
  double rms_px = 0.0;          ///< over the fitted views (kRmsConvention)
  double holdout_rms_px = 0.0;  ///< over the held-out views (0 when none)
  double initial_rms_px = 0.0;  ///< after the closed form, before Ceres
  int views_used = 0;
  int views_held_out = 0;
  int views_rejected = 0;
  std::size_t points_used = 0;
  /// One-sigma uncertainty of fx, fy, cx, cy [px] from Ceres's covariance (0 when unknown).
  Eigen::Vector4d sigma_px = Eigen::Vector4d::Zero();
  SolverSummary solver;

  /// "fx 2006.52 fy 2004.07 cx 515.31 cy 508.82 px, k1 -0.0501 ..., RMS 0.201 px over 16
  /// views, hold-out 0.207 px over 4, 0 rejected (...), 12 iterations".
  std::string brief() const;
};

/// Calibrates from detected views of one camera. Views whose image size differs from
/// `width_px` x `height_px`, or with fewer than min_corners_per_view corners, are rejected
/// with the reason (they are reported, not fitted). Errors: kInvalidArgument for bad options,
/// a bad image size, or fewer than min_fit_views usable views (the message counts the views
/// given, rejected and held out, and says how many are needed); kOutOfRange when the closed
/// form fails or the solve does not give a valid lens (render::CameraModel::create's reason).
/// `progress` (optional) hears "init", "solve", "reject", "holdout".
/// Thread-safe (no shared state); not real-time.
Result<IntrinsicsReport> calibrate_intrinsics(const std::vector<BoardView>& views, int width_px,
                                              int height_px, const IntrinsicsOptions& options = {},
                                              const ProgressFn& progress = {});

/// Loads every image of `directory` (png, jpg, jpeg, bmp, pgm, ppm, tif, tiff; sorted by
/// name), converts it to grey, finds `board`, and calibrates. Images where no board is found
/// or whose size differs from the first readable image's are reported as rejected views with
/// the reason. Errors: kIo when the directory cannot be read or holds no image;
/// kInvalidArgument "no <board> found in any of the N images of DIR" or "inconsistent image
/// sizes ..." when nothing usable is left; and calibrate_intrinsics's errors.
/// `progress` hears "detect" once per image, then calibrate_intrinsics's stages.
Result<IntrinsicsReport> calibrate_intrinsics_from_directory(const std::string& directory,
                                                             const BoardSpec& board,
                                                             const IntrinsicsOptions& options = {},
                                                             const ProgressFn& progress = {});

/// The image files calibrate_intrinsics_from_directory would read, sorted. Errors: kIo.
Result<std::vector<std::string>> list_images(const std::string& directory);

/// Pose of a board from one view with a known camera: cv::solvePnP (iterative, from the
/// homography), then refined. Errors: kInvalidArgument (fewer than 4 points), kOutOfRange
/// (OpenCV failed or the board is behind the camera).
Result<Eigen::Isometry3d> solve_board_pose(const render::CameraModel& camera,
                                           const BoardObservation& observation);

/// Reprojection RMS [px] of `observation` for the board at `camera_T_board` (kRmsConvention);
/// infinity when a point cannot be projected.
double reprojection_rms(const render::CameraModel& camera, const Eigen::Isometry3d& camera_T_board,
                        const BoardObservation& observation);

}  // namespace cell::calibration
