#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "cell/calibration/board.hpp"
#include "cell/calibration/camera_calibration.hpp"
#include "cell/common/result.hpp"
#include "cell/kinematics/robot_model.hpp"

/// Pose sets for guided eye-in-hand captures, chosen for conditioning: joint vectors from which
/// a camera (its nominal calibration) sees the whole board (with a margin for the nominal's
/// error), spread as far apart as they can be in what determines the calibration: the camera's
/// heading about the vertical and where the board lands in the image (farthest-point
/// selection among many random candidates).
namespace cell::calibration {

struct PoseSetOptions {
  int count = 24;
  std::uint64_t seed = 1;
  /// Per joint [rad or mm]: candidates are drawn uniformly in these ranges (a zero-width range
  /// fixes the joint). Must have the robot's number of joints.
  std::vector<std::pair<double, double>> joint_ranges;
  double margin_px = 30.0;  ///< the board's outline stays this far inside the image
  int candidates = 20000;
};

/// `count` joint vectors within the robot's limits from which the eye-in-hand `camera` (its
/// extrinsics = mount_T_camera) sees `board` lying at `base_T_board`. Errors: kInvalidArgument
/// for a fixed camera, bad ranges or a mount frame the robot lacks; kOutOfRange when fewer
/// than `count` candidates see the board (saying how many did).
Result<std::vector<kinematics::JointVector>> eye_in_hand_pose_set(
    const kinematics::RobotModel& robot, const CameraCalibration& camera, const BoardSpec& board,
    const Eigen::Isometry3d& base_T_board, const PoseSetOptions& options);

}  // namespace cell::calibration
