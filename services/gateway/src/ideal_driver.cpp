#include "ideal_driver.hpp"

namespace cell::gateway {

IdealDriver::IdealDriver(int dof, JointVector initial_q, double gripper_time_s,
                         std::chrono::nanoseconds cycle)
    : q_(std::move(initial_q)), qd_(JointVector::Zero(dof)), gripper_time_s_(gripper_time_s) {
  info_.name = "ideal";
  info_.dof = dof;
  info_.cycle = cycle;
}

Status IdealDriver::on_configure() { return ok_status(); }
Status IdealDriver::on_activate() { return ok_status(); }
void IdealDriver::on_deactivate() noexcept { qd_.setZero(); }
void IdealDriver::on_cleanup() noexcept {}

CycleStatus IdealDriver::read(Clock::time_point now, JointState& state) {
  last_now_ = now;
  if ((gripper_ == cell_robot_GRIPPER_CLOSING || gripper_ == cell_robot_GRIPPER_OPENING) &&
      now >= gripper_done_) {
    gripper_ = gripper_ == cell_robot_GRIPPER_CLOSING ? cell_robot_GRIPPER_CLOSED
                                                      : cell_robot_GRIPPER_OPEN;
  }
  state.q = q_;
  state.qd = qd_;
  state.effort = JointVector::Zero(q_.size());
  state.gripper = gripper_;
  state.homed = homed_;
  state.busy = gripper_ == cell_robot_GRIPPER_CLOSING || gripper_ == cell_robot_GRIPPER_OPENING;
  state.fault_bits = 0;
  return CycleStatus::kOk;
}

CycleStatus IdealDriver::write(Clock::time_point /*now*/, const JointSetpoint& setpoint) {
  q_ = setpoint.q;
  qd_ = setpoint.qd;
  return CycleStatus::kOk;
}

Status IdealDriver::command(DriverCommand command, const CommandArgs& /*args*/) {
  const auto dwell = std::chrono::duration_cast<Clock::duration>(
      std::chrono::duration<double>(gripper_time_s_));
  switch (command) {
    case DriverCommand::kHome:
      homed_ = true;
      return ok_status();
    case DriverCommand::kGripperClose:
      gripper_ = cell_robot_GRIPPER_CLOSING;
      gripper_done_ = last_now_ + dwell;
      return ok_status();
    case DriverCommand::kGripperOpen:
      gripper_ = cell_robot_GRIPPER_OPENING;
      gripper_done_ = last_now_ + dwell;
      return ok_status();
    case DriverCommand::kLights:
    case DriverCommand::kReset:
      return ok_status();
  }
  return Error{Errc::kInvalidArgument, "unknown driver command"};
}

std::string IdealDriver::describe_faults(std::uint32_t bits) const {
  return bits == 0 ? std::string() : "ideal robot has no faults";
}

}  // namespace cell::gateway
