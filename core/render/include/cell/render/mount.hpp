#pragma once

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/render/camera_file.hpp"

/// Where an eye-in-hand camera's mount frame is, for the robot's joints at the exposure.
namespace cell::render {

/// base_T_mount for joints `q` (the robot's joint vector, rad / mm):
///   kTool: the robot's tool frame, RobotModel::forward(q) (RobotState.base_T_tool).
///   kLink2 (SCARA only): the end of link 2, on the R axis at the flange's height with Z = 0,
///     x along link 2 (yaw J1 + J2), z up; R and Z do not move it. The 7545's camera rides
///     there (digest 000 §1.1).
/// Errors: kInvalidArgument for a joint vector of the wrong size or with non-finite values
/// (RobotModel::forward), or kLink2 on a robot that is not a SCARA. Pure; thread-safe.
Result<Eigen::Isometry3d> base_T_mount(const kinematics::RobotModel& robot, MountFrame frame,
                                       const kinematics::JointVector& q);

}  // namespace cell::render
