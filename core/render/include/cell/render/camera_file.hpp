#pragma once

#include <string>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/config/yaml.hpp"
#include "cell/render/camera_model.hpp"
#include "cell/render/lighting.hpp"

/// Camera descriptions: config/cameras/<id>.yaml. Each file holds a camera's NOMINAL
/// parameters (what the cell believes: the data sheet, the drawing, the thesis's figures) and
/// its TRUTH (what the simulated world really has: a few mm and a degree or two away, plus a
/// lens distortion the nominal model ignores), so that calibration has something to find.
/// The renderer uses the truth; vision and calibration start from the nominal. Keys are
/// documented in config/cameras/README.md and in each shipped file.
///
/// Mounts. A fixed camera has world_T_camera. An eye-in-hand camera rides a robot: its pose is
/// world_T_camera = world_T_base * base_T_mount(joints at exposure) * mount_T_camera, where the
/// mount frame is the robot's tool frame (`frame: tool`: RobotState.base_T_tool) or, on a SCARA,
/// the end of link 2 (`frame: link2`: on the R axis at the flange's height with Z = 0, x along
/// link 2, z up), which carries the 7545's camera (digest 000 §1.1: "mounted on the arm next to
/// the end-effector on a rigid frame", so it turns with J1 + J2, not with R, and does not move
/// with Z).
namespace cell::render {

/// How the camera is carried.
enum class MountKind : std::uint8_t { kFixed, kEyeInHand };
/// Which robot frame an eye-in-hand camera is bolted to.
enum class MountFrame : std::uint8_t { kTool, kLink2 };

/// One parameter set: the model and the camera's pose in its mount.
struct CameraSetup {
  CameraModel model;
  /// world_T_camera (fixed) or mount_T_camera (eye-in-hand) [mm].
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
};

/// The robot an eye-in-hand camera rides.
struct RobotMount {
  std::string robot_id;
  MountFrame frame = MountFrame::kTool;
  /// The robot's base in the world [mm]: must agree with the world simulator's placement.
  Eigen::Isometry3d world_T_base = Eigen::Isometry3d::Identity();
};

/// A camera file.
struct CameraDescription {
  std::string id;
  std::string description;
  std::string path;  ///< the file it came from
  MountKind mount = MountKind::kFixed;
  RobotMount robot;  ///< eye-in-hand only
  CameraSetup nominal;
  CameraSetup truth;
  double exposure_s = 0.01;  ///< default integration time (strobe flash for the belt camera)
  Lighting lighting;
  /// Light switches assumed until `lights_robot_id` reports (or always, when it is empty).
  LightSwitches lights;
  /// Robot whose RobotState halogen_on / fluorescent_on switch the lamp and the tubes ("" for
  /// lights that stay as configured, e.g. a strobe that fires at every exposure).
  std::string lights_robot_id;

  /// The camera in the world for `setup` (nominal or truth). Fixed: setup.pose. Eye-in-hand:
  /// robot.world_T_base * base_T_mount * setup.pose (base_T_mount is ignored for fixed ones).
  Eigen::Isometry3d world_T_camera(const CameraSetup& setup,
                                   const Eigen::Isometry3d& base_T_mount) const;
};

/// Loads and validates a camera file. Errors: kConfig with every problem at once, one per line,
/// "file:line:col: key 'a.b': what" (missing or unknown keys, wrong types, sizes, a lens that
/// folds inside the image, a mount without its pose, lighting out of range).
Result<CameraDescription> load_camera(const std::string& path);

/// As load_camera, from a parsed document (its path names the errors).
Result<CameraDescription> parse_camera(const config::Document& doc);

/// "fixed" / "eye_in_hand"; "tool" / "link2".
std::string_view to_string(MountKind kind) noexcept;
std::string_view to_string(MountFrame frame) noexcept;

}  // namespace cell::render
