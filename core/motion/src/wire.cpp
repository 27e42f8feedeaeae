#include "cell/motion/wire.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/bus/view.hpp"
#include "cell/geometry/idl_pose.hpp"

namespace cell::motion {

void to_idl(const Plan& plan, const std::string& robot_id, const std::string& trajectory_id,
            const std::string& motion_id, TrajectoryWire& wire) {
  wire.robot_id = robot_id;
  wire.trajectory_id = trajectory_id;
  wire.motion_id = motion_id;
  wire.frame_id = robot_id + "/joints";
  const auto& knots = plan.trajectory.knots();
  wire.positions.assign(knots.size(), {});
  wire.velocities.assign(knots.size(), {});
  wire.knots.assign(knots.size(), cell_motion_TrajectoryKnot{});
  for (std::size_t i = 0; i < knots.size(); ++i) {
    wire.positions[i].assign(knots[i].q.data(), knots[i].q.data() + knots[i].q.size());
    wire.velocities[i].assign(knots[i].qd.data(), knots[i].qd.data() + knots[i].qd.size());
    wire.knots[i].time_from_start_s = knots[i].t_s;
    bus::borrow(wire.knots[i].position_rad_or_mm, wire.positions[i]);
    bus::borrow(wire.knots[i].velocity_rad_or_mm_per_s, wire.velocities[i]);
  }
  wire.events.assign(plan.events.size(), cell_motion_TrajectoryEvent{});
  for (std::size_t i = 0; i < plan.events.size(); ++i) {
    wire.events[i].time_from_start_s = plan.events[i].t_s;
    wire.events[i].kind =
        plan.events[i].close ? cell_motion_EVENT_GRIPPER_CLOSE : cell_motion_EVENT_GRIPPER_OPEN;
    wire.events[i].dwell_s = plan.events[i].dwell_s;
  }
  cell_motion_Trajectory& m = wire.message;
  m = cell_motion_Trajectory{};
  m.robot_id = bus::borrow(wire.robot_id);
  m.header.frame_id = bus::borrow(wire.frame_id);
  m.trajectory_id = bus::borrow(wire.trajectory_id);
  m.motion_id = bus::borrow(wire.motion_id);
  bus::borrow(m.knots, wire.knots);
  bus::borrow(m.events, wire.events);
  m.alter_enabled = plan.alter_enabled;
  m.alter_cumulative = plan.alter_cumulative;
  m.alter_world_frame = plan.alter_world_frame;
}

Result<Plan> from_idl(const cell_motion_Trajectory& message, int dof) {
  const auto knots_in = bus::span(message.knots);
  if (knots_in.empty()) {
    return Error{Errc::kInvalidArgument, "trajectory has no knots"};
  }
  std::vector<trajectory::Knot> knots;
  knots.reserve(knots_in.size());
  for (std::size_t i = 0; i < knots_in.size(); ++i) {
    const auto q = bus::span(knots_in[i].position_rad_or_mm);
    const auto qd = bus::span(knots_in[i].velocity_rad_or_mm_per_s);
    if (static_cast<int>(q.size()) != dof || static_cast<int>(qd.size()) != dof) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("trajectory knot {} has {} positions and {} velocities; the robot "
                               "has {} joints",
                               i, q.size(), qd.size(), dof)};
    }
    trajectory::Knot k;
    k.t_s = knots_in[i].time_from_start_s;
    k.q = Eigen::Map<const Eigen::VectorXd>(q.data(), dof);
    k.qd = Eigen::Map<const Eigen::VectorXd>(qd.data(), dof);
    knots.push_back(std::move(k));
  }
  auto traj = trajectory::JointTrajectory::from_knots(std::move(knots));
  if (!traj) {
    return with_context(std::move(traj).error(), "trajectory");
  }
  Plan plan;
  plan.trajectory = std::move(*traj);
  for (const auto& e : bus::span(message.events)) {
    const auto kind = bus::raw(e.kind);  // any value may come off the wire
    if (kind != cell_motion_EVENT_GRIPPER_CLOSE && kind != cell_motion_EVENT_GRIPPER_OPEN) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("trajectory event has unknown kind {}", kind)};
    }
    if (!std::isfinite(e.time_from_start_s) || !std::isfinite(e.dwell_s) || e.dwell_s < 0 ||
        e.time_from_start_s < 0 || e.time_from_start_s > plan.trajectory.duration_s() + 1e-9) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("trajectory event at {} s with dwell {} s lies outside the "
                               "trajectory's {} s",
                               e.time_from_start_s, e.dwell_s, plan.trajectory.duration_s())};
    }
    plan.events.push_back(GripperEvent{e.time_from_start_s,
                                       e.kind == cell_motion_EVENT_GRIPPER_CLOSE, e.dwell_s});
  }
  plan.alter_enabled = message.alter_enabled;
  plan.alter_cumulative = message.alter_cumulative;
  plan.alter_world_frame = message.alter_world_frame;
  return plan;
}

cell_common_Pose to_idl(const Eigen::Isometry3d& pose) { return geometry::pose_to_idl(pose); }

Result<Eigen::Isometry3d> from_idl(const cell_common_Pose& pose) {
  return geometry::pose_from_idl(pose);
}

}  // namespace cell::motion
