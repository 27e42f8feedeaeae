#include "ideal_driver.hpp"

#include <fmt/format.h>

namespace cell::gateway {

IdealDriver::IdealDriver(int dof, JointVector initial_q, double gripper_time_s,
                         std::chrono::nanoseconds cycle)
    : q_(std::move(initial_q)), qd_(JointVector::Zero(dof)), gripper_time_s_(gripper_time_s) {
  info_.name = "ideal";
  info_.dof = dof;
  info_.cycle = cycle;
  // The arm holds each setpoint from the next cycle on: the host samples its path one cycle
  // ahead, so at every read the arm is on the path (2 mm behind it at 2 m/s otherwise).
  info_.setpoint_lead = cycle;
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
    default:
      return Error{Errc::kInvalidArgument, "the ideal robot has no gains, modes or tolerance"};
  }
  return Error{Errc::kInvalidArgument, "unknown driver command"};
}

bool IdealDriver::supports(DriverCommand command) const noexcept {
  return command != DriverCommand::kSetGains && command != DriverCommand::kSetMode &&
         command != DriverCommand::kSetTolerance;
}

DriverFactory parse_ideal_driver(config::MapReader& section) {
  std::vector<double> initial;
  double gripper_time_s = 0.5;
  section.optional("initial_joints", initial);
  section.optional("gripper_time_s", gripper_time_s);
  if (!(gripper_time_s >= 0 && gripper_time_s <= 10)) {
    section.fail("gripper_time_s", fmt::format("must be in [0, 10], got {}", gripper_time_s));
  }
  const std::string where = section.where("initial_joints");
  return [initial, gripper_time_s, where](
             const DriverSetup& setup) -> Result<std::unique_ptr<RobotDriver>> {
    const auto& model = setup.model;
    JointVector q0 = JointVector::Zero(model.dof());
    if (!initial.empty()) {
      if (static_cast<int>(initial.size()) != model.dof()) {
        return Error{Errc::kConfig,
                     fmt::format("{}: driver.initial_joints has {} values, robot '{}' has {} joints",
                                 where, initial.size(), model.id(), model.dof())};
      }
      for (int j = 0; j < model.dof(); ++j) {
        q0[j] = model.joints()[static_cast<std::size_t>(j)].from_display(
            initial[static_cast<std::size_t>(j)]);
      }
    }
    if (auto s = model.check_limits(q0); !s) {
      return with_context(s.error(), where + ": driver.initial_joints");
    }
    return std::unique_ptr<RobotDriver>(
        std::make_unique<IdealDriver>(model.dof(), q0, gripper_time_s, setup.cycle));
  };
}

std::string IdealDriver::describe_faults(std::uint32_t bits) const {
  return bits == 0 ? std::string() : "ideal robot has no faults";
}

}  // namespace cell::gateway
