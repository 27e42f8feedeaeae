#include "cell/motion/robot_adapters.hpp"

namespace cell::motion {

trajectory::JointLimits joint_limits(const kinematics::RobotModel& model) {
  trajectory::JointLimits limits;
  const auto joints = model.joints();
  const auto n = static_cast<Eigen::Index>(joints.size());
  limits.lower.resize(n);
  limits.upper.resize(n);
  limits.max_velocity.resize(n);
  limits.max_acceleration.resize(n);
  for (Eigen::Index j = 0; j < n; ++j) {
    const auto& spec = joints[static_cast<std::size_t>(j)];
    limits.names.push_back(spec.name);
    limits.prismatic.push_back(spec.type == kinematics::JointType::kPrismatic);
    limits.lower[j] = spec.lower;
    limits.upper[j] = spec.upper;
    limits.max_velocity[j] = spec.max_speed;
    limits.max_acceleration[j] = spec.max_accel;
  }
  return limits;
}

trajectory::ForwardFn forward_fn(const kinematics::RobotModel& model) {
  return [&model](const trajectory::JointVector& q) {
    auto pose = model.forward(q);
    return pose ? *pose : Eigen::Isometry3d::Identity();
  };
}

trajectory::InverseFn inverse_fn(const kinematics::RobotModel& model) {
  return [&model](const Eigen::Isometry3d& pose,
                  const trajectory::JointVector& seed) -> Result<trajectory::JointVector> {
    return model.inverse(pose, seed);
  };
}

}  // namespace cell::motion
