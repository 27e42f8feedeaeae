#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "calibration.h"
#include "cell/calibration/report.hpp"
#include "cell/common/result.hpp"
#include "cell/geometry/pose2.hpp"

/// A conveyor belt's calibration: millimetres per encoder count and the belt's direction of
/// travel in the base frame of the robot that picks from it (not assumed parallel to an axis:
/// digest 002 §2.2, §4), from the same part located at two or more encoder counts; its YAML
/// file and bus form (`cell/calibration/belt`, idl/calibration.idl); and the conveyor chapter's
/// chain `part.loc = to.cam : vis.loc : grip.part`, advanced along the belt.
///
/// Frames: base = the base frame of `robot_id`. A point riding the belt, at p when the encoder
/// read c0, is at p + (c - c0) * mm_per_count * direction when it reads c. Units: mm, counts.
namespace cell::calibration {

struct BeltCalibration {
  std::string belt_id;
  std::string robot_id;
  std::string camera_id;    ///< the camera that located the part ("" if none)
  std::string version;      ///< store version ("" outside the store)
  std::string created_utc;
  std::string source;
  double mm_per_count = 0.0;  ///< > 0
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();  ///< unit, travel for rising counts
  /// The reference part's position extrapolated to count 0 [mm, base]: a point of the belt's
  /// line of travel at its surface.
  Eigen::Vector3d origin_mm = Eigen::Vector3d::Zero();
  double rms_mm = 0.0;      ///< fit residual
  double holdout_mm = 0.0;  ///< predicted vs located positions of held-out samples
  std::uint32_t sample_count = 0;

  /// Ok, or kInvalidArgument naming the field: ids non-empty, mm_per_count finite and > 0, a
  /// finite unit direction (|d| within 1e-6 of 1), finite origin.
  Status validate() const;

  /// Where a point at `p_base` when the encoder read `count_then` is at `count_now` [mm].
  Eigen::Vector3d advance(const Eigen::Vector3d& p_base, std::int64_t count_then,
                          std::int64_t count_now) const;
};

/// YAML (core/calibration/README.md): every error at once, "file:line:col: key ...".
Result<BeltCalibration> load_belt_calibration(const std::string& path);
Result<BeltCalibration> parse_belt_calibration(const std::string& text, const std::string& origin);
std::string format_belt_calibration(const BeltCalibration& calibration);
/// Atomic write; errors as save_camera_calibration.
Status save_belt_calibration(const BeltCalibration& calibration, const std::string& path);

/// Storage the IDL sample of to_idl borrows from.
struct BeltIdlHolder {
  std::string frame_id;
};
/// The bus sample: strings borrow from `calibration` and `holder` (keep both while writing).
cell_calibration_BeltCalibration to_idl(const BeltCalibration& calibration, BeltIdlHolder& holder,
                                        std::int64_t stamp_ns);
/// From a bus sample, validated. Errors: kInvalidArgument naming the field.
Result<BeltCalibration> from_idl(const cell_calibration_BeltCalibration& sample);

/// One location of a part riding the belt.
struct BeltObservation {
  std::string id;                 ///< the sample's key ("part 1 @ 123456")
  std::string part;               ///< which part: samples of one part share it
  std::int64_t encoder_count = 0; ///< latched at the exposure (Image.belt_count)
  std::int64_t stamp_ns = 0;
  Eigen::Vector3d position_mm = Eigen::Vector3d::Zero();  ///< located, base frame
};

struct BeltOptions {
  double min_travel_mm = 50.0;     ///< the part must travel at least this between samples
  int min_samples_per_part = 2;    ///< parts with fewer located samples are ignored
  double holdout_fraction = 0.2;   ///< of each part's samples (never its first two)
  double outlier_mm = 2.0;         ///< a sample further than this from the fitted line is out
  Status validate() const;
};

struct BeltReport {
  BeltCalibration calibration;
  std::vector<ViewReport> samples;  ///< rms_px holds the sample's residual [mm]
  double travel_mm = 0.0;           ///< largest travel of one part between its samples
  /// Angle of the direction out of the base's xy plane [deg] (a belt tilted against the
  /// robot, or a camera calibration that is).
  double elevation_deg = 0.0;
  int parts = 0;
  std::string brief() const;
};

/// Fits p_i = a_part + c_i v over every sample (v = mm_per_count * direction, a per part),
/// by linear least squares; mm_per_count = |v|, direction = v / |v| (its sign follows rising
/// counts). Held-out samples get their position predicted from their part's other samples.
/// Errors: kInvalidArgument for bad options or ids, no part with enough samples (counted), a
/// belt that did not move between samples (all counts equal, or less than min_travel_mm).
Result<BeltReport> calibrate_belt(const std::vector<BeltObservation>& samples,
                                  const std::string& belt_id, const std::string& robot_id,
                                  const BeltOptions& options = {});

/// The conveyor chapter's grasp target (digest 002 §2.1): part.loc = to.cam : vis.loc :
/// grip.part in the base frame (planar V+ compound transforms), for a part located by vision
/// at encoder count `count_image`, advanced along the belt to `count_now` (§2.2, the ALTER
/// offset, with the calibrated direction instead of an assumed Y0).
geometry::Pose2 part_location(const geometry::Pose2& to_cam, const geometry::Pose2& vis_loc,
                              const geometry::Pose2& grip_part, const BeltCalibration& belt,
                              std::int64_t count_image, std::int64_t count_now);

}  // namespace cell::calibration
