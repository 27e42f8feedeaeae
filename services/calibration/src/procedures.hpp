#pragma once

#include <atomic>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "calibration_config.hpp"
#include "cell/calibration/belt_calibration.hpp"
#include "cell/calibration/camera_calibration.hpp"
#include "cell/calibration/planar_model.hpp"
#include "cell/calibration/report.hpp"
#include "cell/calibration/store.hpp"
#include "cell_link.hpp"

/// The calibration procedures the service runs, each a pure function of its request, the
/// config, the store's current calibrations and (guided ones) the cell through a CellLink.
/// None stores or publishes: the service does that with the outcome, and only when it is ok,
/// so a failed procedure never replaces the current calibration.
namespace cell::calibration_service {

/// A CalibrationRequest in C++ form (calibration_service.cpp converts and checks it).
struct Request {
  std::string procedure;  ///< "intrinsics", "hand_eye", "planar", "belt"
  std::string camera_id;
  std::string robot_id;
  std::string belt_id;
  std::optional<calibration::BoardSpec> board;  ///< from the request, else the procedure's
  std::string images_dir;
  int pose_count = 0;
  bool dry_run = false;
  std::vector<calibration::TwoStageReading> readings;
};

/// What a procedure produced.
struct Outcome {
  std::string device_id;  ///< what it calibrated ("ibm7545_eye", "ibm7545_eye.planar", "belt1")
  std::optional<calibration::CameraCalibration> camera;
  std::optional<calibration::BeltCalibration> belt;
  std::vector<calibration::ViewReport> views;
  double rms_px = 0.0;  ///< belt: [mm]
  double holdout_rms_px = 0.0;
  double holdout_mm = 0.0;
  std::string summary;  ///< the report's brief()
  std::string details;  ///< YAML: the full report (stored beside the calibration)
};

class Procedures {
 public:
  /// `current(id)` gives a camera's current calibration (the store's, else the nominal).
  /// `link` may be null: then guided procedures are refused (data sets still work).
  Procedures(const CalibrationConfig& config,
             std::function<calibration::CameraCalibration(const std::string&)> current,
             CellLink* link, calibration::ProgressFn progress, const std::atomic<bool>& cancel);

  /// Intrinsics from the board images in request.images_dir. With a camera_id the result
  /// is that camera's current calibration with new intrinsics (its extrinsics kept).
  Result<Outcome> intrinsics(const Request& request);
  /// Camera to robot: guided (the procedure's pose set) or from a recorded data set
  /// (images_dir with poses.yaml, README.md). Needs the camera's intrinsics calibrated.
  Result<Outcome> hand_eye(const Request& request);
  /// The thesis's planar model of a SCARA's link-2 camera: the same capture, then the
  /// two-stage values (request.readings, else from the current pinhole) refined over it.
  Result<Outcome> planar(const Request& request);
  /// mm per count and direction of a belt from markers riding it past its camera (guided).
  Result<Outcome> belt(const Request& request);

 private:
  struct Capture {
    std::vector<calibration::HandEyeSample> samples;
    std::vector<kinematics::JointVector> joints;
    std::optional<double> target_z_mm;  ///< a data set's target height (planar reduction)
    std::optional<bool> target_level;   ///< and whether its face is level (planar reduction)
  };
  Result<Capture> capture_board(const BoardCapture& capture, const SimSetup& sim,
                                const calibration::CameraCalibration& camera,
                                const kinematics::RobotModel& robot, int pose_count,
                                const calibration::BoardSpec& board);
  Result<Capture> load_data_set(const std::string& dir, const calibration::CameraCalibration& camera,
                                const kinematics::RobotModel* robot,
                                const calibration::BoardSpec& board);
  /// Sets the simulated world up; the returned guard restores it.
  Status sim_setup(const SimSetup& sim, const calibration::BoardSpec* board);
  /// Puts the simulated world back (a guard's destructor calls it): never throws; a failure
  /// is logged.
  void sim_restore(const SimSetup& sim) noexcept;
  bool cancelled() const noexcept { return cancel_.load(); }
  void progress(std::string_view stage, std::size_t step, std::size_t total,
                std::string_view message) const;

  const CalibrationConfig& config_;
  std::function<calibration::CameraCalibration(const std::string&)> current_;
  CellLink* link_;
  calibration::ProgressFn progress_;
  const std::atomic<bool>& cancel_;
};

/// True when a camera calibration came out of an intrinsics procedure (or a later one built
/// on it): the service refuses extrinsics on top of nominal intrinsics.
bool intrinsics_calibrated(const calibration::CameraCalibration& calibration);

}  // namespace cell::calibration_service
