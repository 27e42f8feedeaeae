#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/config/yaml.hpp"
#include "cell/service/common_config.hpp"
#include "cell/vision/edge.hpp"
#include "cell/vision/locate.hpp"

namespace cell::vision {

/// How vision builds a camera's NOMINAL calibration (calibration::nominal_calibration), used
/// until a CameraCalibration for it is published on the bus.
struct CameraEntry {
  std::string id;
  std::string camera_file;  ///< resolved; default <camera_dir>/<id>.yaml
  /// Fixed cameras: the robot whose base frame the calibration refers to, and where that base
  /// stands in the world (config/sim-world.yaml). Eye-in-hand cameras take both from the file.
  std::string robot_id;
  Eigen::Isometry3d world_T_base = Eigen::Isometry3d::Identity();
  double working_plane_z_mm = 0.0;  ///< table or belt top in that robot's base frame
  /// The `locate:` options for this camera's frames: the global section with the entry's own
  /// `locate:` keys over it (a camera's resolution and contrast set e.g. max_fit_rms_px).
  /// nullopt: the global section as it is.
  std::optional<LocateOptions> locate;
  std::string where;                ///< file:line:col of the entry
};

/// config/vision.yaml (services/vision/README.md documents every key):
///
///   service: {id: vision}
///   cameras:
///     - {id: ibm7545_eye, working_plane_z_mm: -231.51}
///     - {id: belt_cam, robot_id: scara_picker, working_plane_z_mm: -200,
///        world_T_base: {xyz_mm: [1000, 0, 960], rpy_deg: [0, 0, 0]}}
///   camera_dir: config/cameras
///   robot_dir: config/robots
///   history_frames: 8
///   edge_image_timeout_s: 2.0
///   max_pending_edges: 64
///   locate: {...}        # core/vision options.hpp
///   edges: {...}
struct VisionConfig {
  service::CommonConfig common;
  std::vector<CameraEntry> cameras;
  std::string camera_dir;  ///< resolved
  std::string robot_dir;   ///< resolved
  int history_frames = 8;
  double edge_image_timeout_s = 2.0;
  int max_pending_edges = 64;
  LocateOptions locate;
  EdgeFinderOptions edges;

  /// The entry for camera `id`, or nullptr.
  const CameraEntry* camera(const std::string& id) const;
};

/// Reads and validates a vision config. Errors: kConfig, every problem at once, each
/// "file:line:col: key 'a.b': what".
Result<VisionConfig> load_config(const config::Document& doc);

}  // namespace cell::vision
