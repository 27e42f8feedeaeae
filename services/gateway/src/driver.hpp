#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/kinematics/joints.hpp"
#include "robot.h"

namespace cell::gateway {

using kinematics::JointVector;
using Clock = std::chrono::steady_clock;

/// Result of one cycle's exchange with the controller.
enum class CycleStatus : std::uint8_t {
  kOk,     ///< state/command exchanged
  kRetry,  ///< transient: line error, missed handshake; the host tolerates a few in a row
  kFault,  ///< controller error bits or link lost; the host stops and needs a reset
};

/// What the driver measured this cycle. Units: rad / mm, per second.
struct JointState {
  JointVector q;
  JointVector qd;
  JointVector effort;                 ///< drive output in controller units (7545: DAC word)
  cell_robot_GripperState gripper = cell_robot_GRIPPER_UNKNOWN;
  bool homed = false;
  bool busy = false;                  ///< a driver-side procedure (homing, gripper dwell) runs
  std::uint32_t fault_bits = 0;       ///< controller error bits, 0 when none
  /// How far the controller's own clock advanced since the previous cycle's read [s], when
  /// the host can see that clock (a simulated 7545 board publishes it): the arm moved that
  /// long, so the path advances that much, whatever the host's clock did. 0: the path stands
  /// still (the 7545 in a cycle without a control-mode exchange: the arm follows no path).
  /// -1: unknown; the path follows the host's clock, bounded by
  /// DriverInfo::max_setpoint_advance.
  double clock_advance_s = -1.0;
};

/// What the host wants this cycle.
struct JointSetpoint {
  JointVector q;
  JointVector qd;
};

/// Non-cyclic requests, executed on the servo thread between cycles.
enum class DriverCommand : std::uint8_t {
  kHome,
  kGripperOpen,
  kGripperClose,
  kLights,        ///< uses halogen_on / fluorescent_on
  kReset,         ///< clear controller faults
  kSetGains,      ///< uses kp, kv (one per joint): servo gains editable at run time
  kSetMode,       ///< uses mode (Excalibur: host, manual, teach, playback)
  kSetTolerance,  ///< uses tolerance_rad (Excalibur position check)
};

/// Arguments of a DriverCommand (only those of the command are meaningful).
struct CommandArgs {
  bool halogen_on = false;
  bool fluorescent_on = false;
  std::vector<double> kp;
  std::vector<double> kv;
  cell_robot_RobotMode mode = cell_robot_MODE_IDLE;
  double tolerance_rad = 0.0;
};

/// Name, joint count and cycle of a driver.
struct DriverInfo {
  std::string name;
  int dof = 0;
  std::chrono::nanoseconds cycle{std::chrono::milliseconds(1)};
  /// How far after the cycle's instant the setpoint written then is held by the arm: the
  /// host samples the path that far ahead, so the arm is on the path when read, not behind
  /// it (the ideal robot: one cycle; a controller that takes its setpoint as the reference of
  /// its own loop at once: 0).
  std::chrono::nanoseconds setpoint_lead{0};
  /// The most a setpoint may move along its path from one cycle to the next, in path time
  /// (0: no bound, the path follows the wall clock). A host that stalls Δ would otherwise
  /// jump the setpoint Δ × speed at once: on the 7545's board (45 deg/s of J1 = 39 counts a
  /// millisecond, its torque word overflowing near 30 counts of error) a 5 ms stall is a
  /// torque fault. Bounded, the path slows down through a stall and ends that much later.
  std::chrono::nanoseconds max_setpoint_advance{0};
  /// Cycles in a row without an exchange before the link counts as failed (a fault). Three
  /// for a controller with its own timer; a simulated 7545 board that serves a late master
  /// within a grace is waited for as long (its own stalls: the host's scheduling, not a dead
  /// board; its clock and its arm stand still meanwhile).
  int link_retries = 3;
};

/// One controller: the 7545 servo board (DPR), the Excalibur (RS-232 ASCII), a simulator of
/// either, or the ideal robot. A driver knows its protocol only: no DDS, no policy, no
/// self-transitions. Lifecycle calls come from the gateway (not real-time), in order
/// configure -> activate -> (cycles) -> deactivate -> cleanup; read/write come from the
/// servo thread every cycle and must not allocate or block beyond the cycle.
class RobotDriver {
 public:
  RobotDriver() = default;
  RobotDriver(const RobotDriver&) = delete;  // one object per physical arm
  RobotDriver& operator=(const RobotDriver&) = delete;
  virtual ~RobotDriver() = default;

  virtual Status on_configure() = 0;           ///< open the transport; no power
  virtual Status on_activate() = 0;            ///< servo on / brakes off
  virtual void on_deactivate() noexcept = 0;   ///< to rest, power off; safe in any state
  virtual void on_cleanup() noexcept = 0;      ///< inverse of on_configure

  virtual CycleStatus read(Clock::time_point now, JointState& state) = 0;
  virtual CycleStatus write(Clock::time_point now, const JointSetpoint& setpoint) = 0;

  /// The setpoint the controller was given by the last write(), where the driver changed the
  /// host's (7545: moved to the board's sampling instant, plus the bumpless engage offset),
  /// in the host's joint units: the reference its loop followed, the same instant as the
  /// joints read(). False when the controller got the host's setpoint unchanged, or when the
  /// last write() made no exchange. Real-time safe (no allocation: `out` has fixed capacity).
  virtual bool applied_setpoint(JointVector& /*out*/) const noexcept { return false; }

  /// Where a finished homing leaves the arm's reference, in the host's joint units: the 7545's
  /// index-defined home (every counter 0), which its PD loop holds once control mode starts.
  /// The host's setpoint becomes it, so the loop does not pull the arm back to the pre-homing
  /// setpoint (which was read in counts the homing has since re-zeroed), nor hold a position
  /// the arm only passed while it still coasted onto the index. False when the controller
  /// holds the arm itself after homing (the setpoint is then left alone).
  virtual bool home_joints(JointVector& /*out*/) const { return false; }

  /// Starts a non-cyclic command; progress shows in JointState (busy, homed, gripper).
  /// Errors: kNotReady when the controller cannot take it now (moving, faulted), with why.
  virtual Status command(DriverCommand command, const CommandArgs& args) = 0;

  /// Whether the controller has this command at all (an unsupported one is refused at once,
  /// before it is queued).
  virtual bool supports(DriverCommand /*command*/) const noexcept { return true; }

  /// The controller's own limits on a command's arguments (e.g. the Excalibur's tolerance
  /// range), checked when the command is posted, before it is acknowledged: a command the
  /// controller would refuse is refused to its sender. Errors: kInvalidArgument with why.
  /// Thread-safe (reads configuration only).
  virtual Status check(DriverCommand /*command*/, const CommandArgs& /*args*/) const {
    return ok_status();
  }

  /// Meaning of fault bits, e.g. "J1 positive overrun; torques late (0x1000)".
  virtual std::string describe_faults(std::uint32_t bits) const = 0;

  virtual const DriverInfo& info() const noexcept = 0;
};

}  // namespace cell::gateway
