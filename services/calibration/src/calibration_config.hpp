#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/calibration/board.hpp"
#include "cell/calibration/camera_calibration.hpp"
#include "cell/calibration/hand_eye.hpp"
#include "cell/calibration/intrinsics.hpp"
#include "cell/calibration/marker.hpp"
#include "cell/common/result.hpp"
#include "cell/config/yaml.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/service/common_config.hpp"

/// config/calibration.yaml and the procedure files it names (config/calibration/*.yaml);
/// services/calibration/README.md documents every key. Degrees and mm in the files; radians
/// and mm here.
namespace cell::calibration_service {

/// A camera the service keeps a calibration of.
struct CameraEntry {
  render::CameraDescription camera;  ///< config/cameras/<id>.yaml (its NOMINAL is the start)
  std::string robot_id;              ///< fixed cameras: the robot whose base it is expressed in
  Eigen::Isometry3d robot_world_T_base = Eigen::Isometry3d::Identity();  ///< fixed cameras
  double working_plane_z_mm = 0.0;   ///< in that robot's base
  /// The calibration published before any is stored (the camera file's nominal).
  calibration::CameraCalibration nominal;
};

/// A belt the service keeps a calibration of.
struct BeltEntry {
  std::string belt_id;
  std::string robot_id;   ///< whose base frame
  std::string camera_id;  ///< the camera that locates parts on it
  double surface_z_mm = 0.0;  ///< the belt's top in that base
};

/// Sim-only set-up of a procedure (the simulated cell: cell-sim-world). Absent on a real cell,
/// where the operator puts the target in place.
struct SimSetup {
  bool enabled = false;
  std::string scene_file;       ///< the scene the world is reset to (its parts are dropped)
  std::string scene_text;       ///< loaded from scene_file
  /// A chessboard of flat black squares stuck on the table (world frame).
  bool board_on_table = false;
  Eigen::Vector3d board_world_mm = Eigen::Vector3d::Zero();  ///< board origin (outer corner)
  double board_yaw_rad = 0.0;
  /// Flat markers put on the belt (world x, y), a part class of the scene or the catalogue.
  struct Marker {
    std::string class_name;
    double x_mm = 0.0;
    double y_mm = 0.0;
  };
  std::vector<Marker> markers;
  bool restore = true;  ///< reset the world to its configured scene afterwards
};

/// A guided board capture: the robot visits a pose set, the camera sees the board.
struct BoardCapture {
  calibration::BoardSpec board;
  /// Pose set: from a file (joints per pose, the robot file's units) or generated.
  std::vector<kinematics::JointVector> poses;
  bool generate = false;
  int count = 24;
  std::uint64_t seed = 1;
  std::vector<std::pair<double, double>> joint_ranges;  ///< generate: per joint [rad or mm]
  double margin_px = 30.0;
  /// Where the board is believed to be (for generating poses; the fit finds where it is).
  Eigen::Isometry3d base_T_board_nominal = Eigen::Isometry3d::Identity();
  double speed_scale = 1.0;
  double settle_s = 0.3;
  /// Lights to switch on first (a robot's gateway, RobotCommand CMD_LIGHTS): "" for none.
  std::string lights_robot_id;
  bool halogen = false;
  bool fluorescent = true;
};

struct HandEyeProcedure {
  std::string camera_id;
  std::string robot_id;
  BoardCapture capture;
  calibration::HandEyeOptions options;  ///< planar, planar_target_z_mm, sigmas, hold-out
  SimSetup sim;
};

struct PlanarProcedure {
  std::string camera_id;
  std::string robot_id;
  BoardCapture capture;
  Eigen::Vector2d ref_px{3.0, 457.0};  ///< the thesis's Ref_Point
  bool refine_links = true;
  SimSetup sim;
};

struct BeltProcedure {
  std::string belt_id;
  calibration::MarkerOptions marker;
  double marker_height_mm = 5.0;  ///< the part's height: its silhouette centre is at half
  int samples = 24;
  double period_s = 0.4;
  double max_duration_s = 40.0;
  double track_gate_mm = 60.0;    ///< a detection joins the nearest track within this
  SimSetup sim;
};

struct Timeouts {
  double motion_s = 60.0;
  double image_s = 10.0;
  double world_s = 5.0;
  double discovery_s = 5.0;
};

struct CalibrationConfig {
  service::CommonConfig common;
  std::string store_dir = "run/calibrations";
  std::string robots_dir = "config/robots";
  std::vector<CameraEntry> cameras;
  std::vector<BeltEntry> belts;
  calibration::IntrinsicsOptions intrinsics;
  std::vector<HandEyeProcedure> hand_eye;
  std::vector<PlanarProcedure> planar;
  std::vector<BeltProcedure> belt;
  std::map<std::string, kinematics::RobotModel> robots;  ///< loaded from robots_dir, by id
  Timeouts timeouts;

  const CameraEntry* camera(const std::string& id) const;
  const BeltEntry* belt_entry(const std::string& id) const;
  const HandEyeProcedure* hand_eye_for(const std::string& camera_id) const;
  const PlanarProcedure* planar_for(const std::string& camera_id) const;
  const BeltProcedure* belt_for(const std::string& belt_id) const;
  const kinematics::RobotModel* robot(const std::string& id) const;
};

/// Parses and validates config/calibration.yaml (and every file it names). Errors: kConfig,
/// every problem at once, "file:line:col: key 'a.b': what".
Result<CalibrationConfig> load_config(const config::Document& doc);

/// The scene text a sim set-up resets the world to: its scene file without parts or scatter,
/// plus the board's squares and the markers as parts (and the classes they need).
std::string sim_scene_yaml(const SimSetup& sim, const calibration::BoardSpec* board);

}  // namespace cell::calibration_service
