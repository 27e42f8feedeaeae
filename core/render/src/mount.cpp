#include "cell/render/mount.hpp"

#include <fmt/format.h>

#include "cell/kinematics/scara.hpp"

namespace cell::render {

Result<Eigen::Isometry3d> base_T_mount(const kinematics::RobotModel& robot, MountFrame frame,
                                       const kinematics::JointVector& q) {
  auto base_T_tool = robot.forward(q);  // checks size and finiteness
  if (!base_T_tool) {
    return std::move(base_T_tool).error();
  }
  if (frame == MountFrame::kTool) {
    return *base_T_tool;
  }
  const kinematics::ScaraModel* scara = robot.scara();
  if (scara == nullptr) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("robot '{}' is a {}: only a SCARA has a link-2 camera mount",
                             robot.id(), kinematics::to_string(robot.kind()))};
  }
  // The flange with Z = 0 and its yaw along link 2.
  kinematics::ScaraJoints s(q[0], q[1], 0.0, 0.0);
  s[3] = kinematics::roll_from_tool_yaw(*scara, q[0], q[1], q[0] + q[1]);
  return kinematics::forward(*scara, s) * scara->flange_T_tool.inverse();
}

}  // namespace cell::render
