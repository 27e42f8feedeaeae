#pragma once

#include "cell/kinematics/robot_model.hpp"
#include "cell/trajectory/joint_trajectory.hpp"
#include "cell/trajectory/planners.hpp"

/// The bridge between robot models (core/kinematics) and the robot-agnostic trajectory
/// library: limits and kinematics functions of one model.
namespace cell::motion {

/// Joint names, types, position, speed and acceleration limits of `model`, in joint order.
trajectory::JointLimits joint_limits(const kinematics::RobotModel& model);

/// FK of `model` (base_T_tool); a malformed joint vector gives the identity (callers pass
/// vectors of the model's size, checked upstream). The model must outlive the function.
trajectory::ForwardFn forward_fn(const kinematics::RobotModel& model);

/// IK of `model` on the branch nearest to the seed, within joint limits. The model must
/// outlive the function.
trajectory::InverseFn inverse_fn(const kinematics::RobotModel& model);

}  // namespace cell::motion
