#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/common/pi_mutex.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/motion/wire.hpp"
#include "cell/trajectory/executor.hpp"
#include "driver.hpp"

namespace cell::gateway {

/// A consistent picture of the robot after one cycle (what RobotState carries).
struct ServoSnapshot {
  JointState measured;
  JointSetpoint setpoint;
  /// What the controller's loop followed this cycle (RobotState.setpoint_rad_or_mm): the
  /// driver's applied setpoint where it changed the host's (RobotDriver::applied_setpoint),
  /// else setpoint.q.
  JointVector commanded;
  Eigen::Isometry3d base_T_tool = Eigen::Isometry3d::Identity();  ///< FK of measured joints
  cell_robot_RobotMode mode = cell_robot_MODE_IDLE;
  bool moving = false;
  bool halogen_on = false;
  bool fluorescent_on = false;
  std::uint32_t fault_bits = 0;
  std::string fault_text;  ///< FAULT: the fault's meaning; STOPPED: why, when the gateway knows
  std::string stop_code;   ///< STOPPED: "command" or "supervisor_lost" (RobotState.stop_code)
  std::string trajectory_id;
  double progress = 0.0;
  bool tracking = false;  ///< ALTER on and arrived: following the moving destination
  std::uint64_t cycle = 0;
  std::int64_t stamp_ns = 0;
  double jitter_max_us = 0.0;
  std::uint64_t overruns = 0;
  /// Path time given up to late cycles so far [s]: how much later than planned the moves
  /// ended because the host stalled (DriverInfo::max_setpoint_advance), or, where the driver
  /// reads the controller's clock (JointState::clock_advance_s), because that clock fell
  /// behind the host's (a simulated board absorbing stalls).
  double path_delay_s = 0.0;
};

/// Something the operator should hear about (becomes a CellEvent).
struct ServoEvent {
  cell_health_Severity severity = cell_health_SEVERITY_INFO;
  std::string code;
  std::string text;
};

/// The gateway's real-time core, independent of the bus: it owns the driver and the
/// trajectory executor and runs one cycle per call. Other threads hand it work through the
/// post_* methods, which validate against the latest cycle's state and answer at once (a
/// request is never silently dropped); the work takes effect at the start of the next cycle.
/// post_*, snapshot() and take_events() are thread-safe; cycle() runs on one thread only.
class Servo {
 public:
  Servo(const kinematics::RobotModel& model, std::unique_ptr<RobotDriver> driver,
        double start_tolerance_rad, double start_tolerance_mm);

  /// Configures and activates the driver and reads the first state. Setup errors come back.
  Status start(Clock::time_point now);
  /// Deactivates and cleans up the driver. noexcept.
  void shutdown() noexcept;

  /// Queues a trajectory. Refused (kNotReady / kOutOfRange / kInvalidArgument, with the reason)
  /// when the robot is faulted, stopped, busy, not homed, or the trajectory breaks a limit or
  /// does not start at the current setpoint.
  Status post_trajectory(motion::Plan plan, std::string trajectory_id);
  /// Queues an ALTER correction for `trajectory_id` (ignored for another trajectory); its
  /// values hold at `stamp`.
  void post_alter(trajectory::AlterCorrection correction, Clock::time_point stamp,
                  const std::string& trajectory_id);
  /// Queues a command. STOP is always accepted and takes effect within one cycle.
  Status post_command(cell_robot_RobotCommandKind kind, const CommandArgs& args);

  /// Stops the robot as a STOP command does (from the next cycle on, needs a RESET), with a
  /// machine-readable `code` (RobotState.stop_code, e.g. "supervisor_lost") and the `text`
  /// the state's fault_text carries while it is stopped. Always accepted; thread-safe.
  void post_stop(std::string code, std::string text);

  /// One servo cycle at time `now`.
  void cycle(Clock::time_point now);

  /// Records timing of a cycle (for the snapshot): wake-up error and overrun.
  void record_timing(double wake_error_us, bool overrun) noexcept;

  ServoSnapshot snapshot() const;
  /// Starts a new jitter window (after the snapshot was published).
  void reset_jitter() noexcept;
  std::vector<ServoEvent> take_events();
  const DriverInfo& driver_info() const noexcept { return driver_->info(); }

 private:
  struct Pending {
    std::optional<motion::Plan> plan;
    std::string plan_id;
    std::optional<trajectory::AlterCorrection> alter;
    std::string alter_id;
    std::vector<std::pair<cell_robot_RobotCommandKind, CommandArgs>> commands;
    std::string stop_code;  ///< post_stop: non-empty when the gateway stops the robot itself
    std::string stop_text;
  };

  double seconds(Clock::time_point t) const;
  void apply_commands(std::vector<std::pair<cell_robot_RobotCommandKind, CommandArgs>>& commands);
  void fault(std::uint32_t bits, const std::string& text);
  void event(cell_health_Severity severity, std::string code, std::string text);
  Status check_start(const trajectory::JointTrajectory& trajectory,
                     const JointVector& setpoint) const;

  const kinematics::RobotModel& model_;
  std::unique_ptr<RobotDriver> driver_;
  double start_tolerance_rad_;
  double start_tolerance_mm_;
  trajectory::JointLimits limits_;
  trajectory::TrajectoryExecutor executor_;
  std::uint64_t limited_reported_ = 0;  ///< executor_.limited_cycles() already reported
  Clock::time_point epoch_;

  // Servo-thread state.
  JointState measured_;
  JointSetpoint setpoint_;
  JointVector applied_;  ///< the driver's applied setpoint this cycle (ServoSnapshot::commanded)
  trajectory::JointSample sample_;
  std::vector<motion::GripperEvent> events_;
  std::size_t next_event_ = 0;
  double hold_until_s_ = -1;
  std::string trajectory_id_;
  cell_robot_RobotMode mode_ = cell_robot_MODE_IDLE;
  std::string stop_code_;  ///< why mode_ is STOPPED
  std::string stop_text_;
  std::uint64_t cycle_ = 0;
  int retries_in_a_row_ = 0;
  double last_cycle_s_ = -1.0;  ///< the previous cycle's instant [s since epoch_] (-1: none)
  double path_delay_s_ = 0.0;   ///< ServoSnapshot::path_delay_s

  // Guards pending_, snapshot_, events_out_. Shared by the servo thread (SCHED_FIFO) and the
  // bus threads: priority inheritance bounds how long the servo thread can wait for it.
  mutable PiMutex mutex_;
  Pending pending_;
  ServoSnapshot snapshot_;
  std::vector<ServoEvent> events_out_;
  double jitter_max_us_ = 0;
  std::uint64_t overruns_ = 0;
};

}  // namespace cell::gateway
