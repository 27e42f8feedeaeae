#pragma once

#include "driver.hpp"
#include "drivers.hpp"

namespace cell::gateway {

/// The ideal robot: its joints are exactly the last setpoint (no dynamics, no faults), held
/// from the next cycle on: its DriverInfo::setpoint_lead is one cycle, so the host writes the
/// path's point for the next cycle and the arm is on the path at every read. It
/// stands in for a controller in tests and in the simulated cell where nothing else is
/// modelled; the gripper opens or closes after `gripper_time_s`; homing moves nothing and
/// only marks the robot homed (its joints start where configured).
class IdealDriver final : public RobotDriver {
 public:
  IdealDriver(int dof, JointVector initial_q, double gripper_time_s,
              std::chrono::nanoseconds cycle);

  Status on_configure() override;
  Status on_activate() override;
  void on_deactivate() noexcept override;
  void on_cleanup() noexcept override;
  CycleStatus read(Clock::time_point now, JointState& state) override;
  CycleStatus write(Clock::time_point now, const JointSetpoint& setpoint) override;
  Status command(DriverCommand command, const CommandArgs& args) override;
  bool supports(DriverCommand command) const noexcept override;
  std::string describe_faults(std::uint32_t bits) const override;
  const DriverInfo& info() const noexcept override { return info_; }

 private:
  DriverInfo info_;
  JointVector q_;
  JointVector qd_;
  double gripper_time_s_;
  cell_robot_GripperState gripper_ = cell_robot_GRIPPER_OPEN;
  Clock::time_point gripper_done_{};
  Clock::time_point last_now_{};
  bool homed_ = false;
};

/// `driver: {kind: ideal, initial_joints: [deg or mm per joint], gripper_time_s: 0.5}`.
DriverFactory parse_ideal_driver(config::MapReader& section);

}  // namespace cell::gateway
