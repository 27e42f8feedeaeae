#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

#include "cell/calibration/board.hpp"
#include "cell/calibration/report.hpp"
#include "cell/common/result.hpp"
#include "cell/render/camera_model.hpp"

/// Hand-eye calibration: where a camera is relative to a robot, from robot poses paired with
/// views of a calibration target.
///
/// Setups and frames (a_T_b maps b-coordinates into a, mm and rad):
/// - **Eye-in-hand**: the camera rides the robot's mount frame (the flange, or a SCARA's link
///   2: render/mount.hpp); the target is fixed in the robot's base. Unknowns mount_T_camera
///   (CameraCalibration::extrinsics for eye_in_hand) and base_T_target.
/// - **Eye-to-hand**: the camera is fixed (over a belt or table); the target rides the mount
///   frame. Unknowns base_T_camera (CameraCalibration::extrinsics for fixed, V+'s to.cam) and
///   mount_T_target.
/// Each sample: base_T_mount (the robot's pose at the exposure) and the target's corners in
/// that image. The chain of a target point P (target frame) to its pixel:
///   eye-in-hand  pixel = project((base_T_mount * mount_T_camera)^-1 * base_T_target * P)
///   eye-to-hand  pixel = project(base_T_camera^-1 * base_T_mount * mount_T_target * P)
///
/// Procedure. (1) Every sample's camera_T_target by cv::solvePnP. (2) Degenerate motion sets
/// are refused with the reason: a robot that never moved, too little rotation, rotation axes
/// all (nearly) parallel, which is what a SCARA gives: for it, the planar reduction. (3) A
/// closed form: OpenCV's cv::calibrateHandEye (Tsai, Park, Horaud, Andreff, Daniilidis) or
/// cv::calibrateRobotWorldHandEye (Shah, Li); planar: a linear least squares in the plane
/// (below). (4) Ceres refines everything jointly on reprojection error, the robot poses
/// included as noisy measurements (a correction per sample with a Gaussian prior of the
/// robot's accuracy: an errors-in-variables fit), Huber loss first, then plain least squares.
/// (5) Held-out samples (never in the fit) give the hold-out figures.
///
/// Planar reduction (SCARA: every robot rotation is about the base z). The camera's height
/// above the target cannot be told from the mount's height then: only their difference is
/// seen. The target's height is therefore given, `planar_target_z_mm`: eye-in-hand, the
/// target's printed face in the base frame (a board lying on the table: the table top plus
/// the board's thickness); eye-to-hand, the target's face in the mount frame. The camera's
/// tilt and yaw and everything horizontal are estimated (and the target's tilt, unless it is
/// declared level).
///
/// Sample pairing. Each sample carries its own id, the exposure stamp and the stamp of the
/// robot pose used: a sample whose pose is further than max_pair_gap_s from its exposure, a
/// duplicate id, or a failed detection (detection_error set) is rejected by id, so a missing
/// image never shifts a pose onto the wrong view.
namespace cell::calibration {

enum class HandEyeSetup : std::uint8_t { kEyeInHand, kEyeToHand };

/// The closed forms OpenCV offers (the first five: cv::calibrateHandEye; the last two:
/// cv::calibrateRobotWorldHandEye).
enum class HandEyeMethod : std::uint8_t {
  kTsai,
  kPark,
  kHoraud,
  kAndreff,
  kDaniilidis,
  kShah,
  kLi,
};

std::string_view to_string(HandEyeSetup setup) noexcept;   ///< "eye_in_hand" / "eye_to_hand"
std::string_view to_string(HandEyeMethod method) noexcept;  ///< "tsai", "park", ...

/// One robot pose with its image's detection.
struct HandEyeSample {
  std::string id;                  ///< unique key, e.g. "pose 7"
  std::int64_t stamp_ns = 0;       ///< the image's exposure
  std::int64_t robot_stamp_ns = 0; ///< when base_T_mount was valid (0: same as stamp_ns)
  Eigen::Isometry3d base_T_mount = Eigen::Isometry3d::Identity();
  BoardObservation observation;    ///< the target's corners in the image
  std::string detection_error;     ///< non-empty: the target was not found (sample rejected)
};

struct HandEyeOptions {
  HandEyeSetup setup = HandEyeSetup::kEyeInHand;
  /// The closed form that starts the refinement (non-planar).
  HandEyeMethod init = HandEyeMethod::kPark;
  /// Planar reduction for robots that only turn about the base z (SCARA); see the file comment.
  bool planar = false;
  double planar_target_z_mm = 0.0;
  /// Planar: the target's face is level, parallel to the base's xy plane (eye-in-hand: a board
  /// lying on the table) or to the mount's (eye-to-hand: a board flat under the flange), so
  /// only its yaw is unknown. With the small turns a SCARA camera can make while it keeps a
  /// board in view, a target tilt and a camera tilt cannot be told apart otherwise.
  bool planar_target_level = true;
  /// Refine the intrinsics too (otherwise they stay as given: calibrate them first).
  bool refine_intrinsics = false;
  /// Noise model of the joint fit: corner noise [px] and the robot's pose accuracy (1-sigma
  /// per axis). Robot sigmas of 0 treat the robot's poses as exact.
  double pixel_sigma_px = 0.2;
  double robot_rotation_sigma_deg = 0.05;
  double robot_translation_sigma_mm = 0.1;
  double huber_px = 1.0;
  /// Degeneracy: the largest rotation between two poses must reach min_rotation_deg; for the
  /// general (non-planar) problem the relative rotation axes must also spread over at least
  /// min_axis_spread_deg; poses closer than 0.1 mm and 0.01 deg count as one.
  double min_rotation_deg = 10.0;
  double min_axis_spread_deg = 15.0;
  /// Pairing: the robot pose must be valid within this of the exposure.
  double max_pair_gap_s = 0.05;
  /// A sample is an outlier when its RMS exceeds outlier_factor x the median sample RMS and
  /// outlier_min_px.
  double outlier_factor = 4.0;
  double outlier_min_px = 1.0;
  double holdout_fraction = 0.2;
  int min_holdout_samples = 2;
  int min_fit_samples = 5;
  int max_iterations = 200;

  /// Ok, or kInvalidArgument naming the option, its value and the rule.
  Status validate() const;
};

/// How much the robot moved between the samples (all pairs).
struct MotionSpread {
  int distinct_poses = 0;           ///< poses further than 0.1 mm / 0.01 deg from every other
  double max_rotation_deg = 0.0;    ///< largest relative rotation between two poses
  /// Largest angle between two relative rotation axes (A_i^-1 A_j), in the mount frame (what
  /// eye-in-hand needs) and in the base frame (eye-to-hand).
  double axis_spread_deg = 0.0;
  double base_axis_spread_deg = 0.0;
  double max_translation_mm = 0.0;  ///< largest distance between two mount origins
  double max_tilt_deg = 0.0;        ///< largest angle of a mount z axis from the base z
};

/// The motion spread of a set of poses (relative rotations under 1 degree carry no axis).
MotionSpread motion_spread(const std::vector<Eigen::Isometry3d>& base_T_mount);

/// Ok, or kOutOfRange saying why the motion set cannot determine the calibration: "the robot
/// never moved", "too little rotation", "near-parallel rotation axes" (non-planar), or for
/// `planar` a mount that tilts (the reduction needs rotations about the base z only).
Status check_motion(const MotionSpread& spread, const HandEyeOptions& options);

/// The result of one of OpenCV's closed forms on the fitted samples.
struct MethodEstimate {
  HandEyeMethod method = HandEyeMethod::kTsai;
  bool ok = false;
  std::string error;
  Eigen::Isometry3d camera_extrinsics = Eigen::Isometry3d::Identity();  ///< as in the report
};

struct HandEyeReport {
  HandEyeSetup setup = HandEyeSetup::kEyeInHand;
  bool planar = false;
  /// mount_T_camera (eye-in-hand) or base_T_camera (eye-to-hand).
  Eigen::Isometry3d camera_extrinsics = Eigen::Isometry3d::Identity();
  /// base_T_target (eye-in-hand) or mount_T_target (eye-to-hand).
  Eigen::Isometry3d target_pose = Eigen::Isometry3d::Identity();
  render::CameraModel camera;  ///< as given, or refined
  std::vector<ViewReport> samples;  ///< every input sample, in input order
  std::string init;                 ///< the closed form used ("park", "planar")
  std::vector<MethodEstimate> closed_forms;  ///< every OpenCV closed form on the same samples
  MotionSpread motion;
  double rms_px = 0.0;          ///< fitted samples (kRmsConvention)
  double holdout_rms_px = 0.0;  ///< held-out samples, with their robot poses as measured
  /// Held-out samples: a target point (the centre of the target's corners) where the chain
  /// predicts it vs where that image alone (solvePnP) measures it, RMS [mm].
  double holdout_mm = 0.0;
  /// RMS of the estimated robot pose corrections (what the fit thinks the robot's error is).
  double robot_rotation_rms_deg = 0.0;
  double robot_translation_rms_mm = 0.0;
  int samples_used = 0;
  int samples_held_out = 0;
  int samples_rejected = 0;
  SolverSummary solver;

  /// One paragraph: the extrinsics (mm, deg), RMS, hold-out figures, counts, the motion.
  std::string brief() const;
};

/// Calibrates. `camera` is the calibrated camera (intrinsics). Errors: kInvalidArgument for
/// bad options or too few usable samples (counting given, rejected and held out, and saying
/// how many are needed); kOutOfRange for a degenerate motion set (check_motion's reason) or a
/// closed form that fails. `progress` hears "pose", "init", "solve", "holdout".
/// Thread-safe (no shared state).
Result<HandEyeReport> calibrate_hand_eye(const std::vector<HandEyeSample>& samples,
                                         const render::CameraModel& camera,
                                         const HandEyeOptions& options = {},
                                         const ProgressFn& progress = {});

/// One OpenCV closed form on `samples` (each sample's target pose by solvePnP with `camera`;
/// rejected samples are skipped as calibrate_hand_eye skips them). Returns the camera
/// extrinsics as HandEyeReport::camera_extrinsics. Errors: kInvalidArgument (fewer than 3
/// usable samples), kOutOfRange (OpenCV failed or returned non-finite values).
Result<Eigen::Isometry3d> opencv_hand_eye(const std::vector<HandEyeSample>& samples,
                                          const render::CameraModel& camera, HandEyeSetup setup,
                                          HandEyeMethod method);

}  // namespace cell::calibration
