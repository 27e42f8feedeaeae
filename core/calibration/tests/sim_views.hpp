#pragma once

// Test support: renders of calibration boards through the simulator's TRUE cameras
// (config/cameras/*.yaml, core/render), their detections, and the noise the tests add.

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "cell/calibration/board.hpp"
#include "cell/calibration/hand_eye.hpp"
#include "cell/calibration/intrinsics.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/render/camera_file.hpp"
#include "cell/render/renderer.hpp"
#include "cell/render/scene.hpp"

namespace cell::calibration::testing {

/// config/cameras/<name> of the checkout (fails the test when it does not load).
render::CameraDescription camera_file(const std::string& name);
/// config/robots/<name>.
kinematics::RobotModel robot_file(const std::string& name);

/// A render::Chessboard for `spec` (inner corners -> squares), white margin 12 mm.
render::Chessboard chessboard_target(const BoardSpec& spec, const Eigen::Isometry3d& world_T_board);

/// camera_T_board for a board facing the camera: its centre at `center_camera` [mm], turned
/// about the camera's line of sight by `roll`, and tilted by `tilt_x`, `tilt_y` [rad] about
/// its own x and y axes. The board's printed face looks back at the camera.
Eigen::Isometry3d board_facing_camera(const BoardSpec& spec, const Eigen::Vector3d& center_camera,
                                      double roll, double tilt_x, double tilt_y);

/// Renders `scene` through `camera` at `world_T_camera` (noise in grey levels, seeded).
cv::Mat render_view(const render::CameraModel& camera, const render::Lighting& lighting,
                    const render::Scene& scene, const Eigen::Isometry3d& world_T_camera,
                    double noise_sigma, std::uint64_t seed);

/// Adds isotropic Gaussian noise of `sigma_px` per coordinate to every corner.
void add_corner_noise(BoardObservation& obs, double sigma_px, std::mt19937_64& rng);

/// What an operator's board images are: 20 views of the board (intrinsics_views' poses for
/// `seed`, no corner noise) rendered through the camera's TRUE model with 1 grey level of noise,
/// the board on a dark background in an evenly lit room. Write them out for `cellctl calibrate
/// intrinsics --images DIR`.
std::vector<cv::Mat> intrinsics_images(const render::CameraDescription& camera,
                                       const BoardSpec& board, double depth_mm,
                                       std::uint64_t seed = 7);

/// `count` views of a board held in front of a fixed camera (an operator waving it), spread
/// over the field with tilts up to about 40 degrees, depth around `depth_mm`; rendered through
/// the camera's TRUE model, detected, and `corner_noise_px` added. Fails the test when a view
/// is not detected.
std::vector<BoardView> intrinsics_views(const render::CameraDescription& camera,
                                        const BoardSpec& spec,
                                        int count,
                                        double depth_mm,
                                        double corner_noise_px,
                                        std::uint64_t seed,
                                        std::vector<Eigen::Isometry3d>* truth_poses = nullptr);

/// A hand-eye data set rendered through a true camera, with the truth it came from.
struct HandEyeScenario {
  std::string name;
  render::CameraModel camera;  ///< the TRUE intrinsics
  HandEyeOptions options;      ///< setup, planar reduction and its known height
  Eigen::Isometry3d truth_extrinsics = Eigen::Isometry3d::Identity();  ///< mount_T_ / base_T_camera
  Eigen::Isometry3d truth_target = Eigen::Isometry3d::Identity();      ///< base_T_ / mount_T_target
  BoardSpec board;
  std::vector<HandEyeSample> samples;          ///< robot poses with noise
  std::vector<Eigen::Isometry3d> true_mount;   ///< the exact base_T_mount of each sample
  std::vector<kinematics::JointVector> joints; ///< the exact joints of each sample
};

/// Robot pose noise: each pose times exp(rotation N(0, sigma) per axis, translation N(0, sigma)
/// per axis), in the mount frame. `yaw_only`: the rotation noise is about z only (a SCARA).
Eigen::Isometry3d noisy_pose(const Eigen::Isometry3d& pose, double rotation_sigma_deg,
                             double translation_sigma_mm, bool yaw_only, std::mt19937_64& rng);

/// The Excalibur with a camera on its flange (a synthetic 800 x 600 camera, 43 degrees of
/// field) looking at a 9x6 board on the table from `count` poses around it, at elevations
/// (angle of the line of sight above the table) between the two given [deg], from every side.
HandEyeScenario excalibur_eye_in_hand(int count, double rotation_sigma_deg,
                                      double translation_sigma_mm, double pixel_sigma_px,
                                      std::uint64_t seed, double min_elevation_deg = 25.0,
                                      double max_elevation_deg = 65.0);

/// The IBM 7545 with its eye-in-hand camera on link 2 (config/cameras/ibm7545_eye.yaml, truth)
/// looking down at a 7x4 board on the table, from `count` elbow poses around the image-grab
/// pose. Planar: the board's face height in the base is known.
HandEyeScenario ibm7545_eye_in_hand(int count, double rotation_sigma_deg,
                                    double translation_sigma_mm, double pixel_sigma_px,
                                    std::uint64_t seed);

/// The belt camera (config/cameras/belt_cam.yaml, truth) over the conveyor picker, which
/// holds a 9x6 board under its flange. Planar: the board's face in the tool frame is known.
HandEyeScenario picker_eye_to_hand(int count, double rotation_sigma_deg,
                                   double translation_sigma_mm, double pixel_sigma_px,
                                   std::uint64_t seed);

/// A fixed camera looking down at the Excalibur, which holds a 9x6 board in its gripper and
/// shows it tilted every way.
HandEyeScenario excalibur_eye_to_hand(int count, double rotation_sigma_deg,
                                      double translation_sigma_mm, double pixel_sigma_px,
                                      std::uint64_t seed);

/// Rotation angle between two rotations [rad].
double rotation_error_rad(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b);

}  // namespace cell::calibration::testing
