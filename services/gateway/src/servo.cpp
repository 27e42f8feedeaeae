#include "servo.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/common/time.hpp"
#include "cell/motion/robot_adapters.hpp"

namespace cell::gateway {
namespace {

std::string_view command_name(cell_robot_RobotCommandKind kind) {
  switch (kind) {
    case cell_robot_CMD_HOME:
      return "home";
    case cell_robot_CMD_GRIPPER_OPEN:
      return "gripper open";
    case cell_robot_CMD_GRIPPER_CLOSE:
      return "gripper close";
    case cell_robot_CMD_LIGHTS:
      return "lights";
    case cell_robot_CMD_STOP:
      return "stop";
    case cell_robot_CMD_RESET:
      return "reset";
    case cell_robot_CMD_SET_MODE:
      return "set mode";
    case cell_robot_CMD_SET_GAINS:
      return "set gains";
    case cell_robot_CMD_SET_TOLERANCE:
      return "set tolerance";
    case cell_robot_CMD_ALTER_OFF:
      return "alter off";
  }
  return "unknown";
}

/// The relative slack a plan's speeds and accelerations may take over the arm's limits and
/// still be accepted (check_limits: its knots' cubics overshoot a little where a profile
/// turns, by up to ~2 %).
constexpr double kPlanSlack = 0.02;

/// What the executor's setpoints keep (TrajectoryExecutor, JointLimiter): the speeds and
/// accelerations an accepted plan may take, so that it passes unchanged. At the bare limits a
/// joint move 1-2 % over them was lagged: by 12 mm/s at full speed (4 mm at its end), and with
/// accelerations within 1 %, a Z deceleration a little steeper than that by 4.6 mm, overshot
/// and brought back (tests/task, the conveyor picker).
trajectory::JointLimits setpoint_limits(trajectory::JointLimits limits) {
  limits.max_velocity *= 1.0 + kPlanSlack;
  limits.max_acceleration *= 1.0 + kPlanSlack;
  return limits;
}

}  // namespace

Servo::Servo(const kinematics::RobotModel& model, std::unique_ptr<RobotDriver> driver,
             double start_tolerance_rad, double start_tolerance_mm)
    : model_(model),
      driver_(std::move(driver)),
      start_tolerance_rad_(start_tolerance_rad),
      start_tolerance_mm_(start_tolerance_mm),
      limits_(motion::joint_limits(model)),
      executor_(motion::forward_fn(model), motion::inverse_fn(model), setpoint_limits(limits_)) {}

double Servo::seconds(Clock::time_point t) const {
  return std::chrono::duration<double>(t - epoch_).count();
}

Status Servo::start(Clock::time_point now) {
  epoch_ = now;
  CELL_TRY(driver_->on_configure());
  if (auto s = driver_->on_activate(); !s) {
    driver_->on_cleanup();
    return s;
  }
  if (driver_->read(now, measured_) == CycleStatus::kFault) {
    const std::string why = driver_->describe_faults(measured_.fault_bits);
    driver_->on_deactivate();
    driver_->on_cleanup();
    return Error{Errc::kProtocol, "the controller reports a fault at start: " + why};
  }
  setpoint_.q = measured_.q;
  setpoint_.qd = JointVector::Zero(measured_.q.size());
  cycle(now);
  return ok_status();
}

void Servo::shutdown() noexcept {
  driver_->on_deactivate();
  driver_->on_cleanup();
}

Status Servo::check_start(const trajectory::JointTrajectory& trajectory,
                          const JointVector& setpoint) const {
  const JointVector& start = trajectory.start();
  for (Eigen::Index j = 0; j < start.size(); ++j) {
    const bool prismatic = limits_.prismatic[static_cast<std::size_t>(j)];
    const double tolerance = prismatic ? start_tolerance_mm_ : start_tolerance_rad_;
    if (std::abs(start[j] - setpoint[j]) > tolerance) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("trajectory starts with joint {} at {} but the robot is at {} "
                               "(tolerance {})",
                               limits_.names[static_cast<std::size_t>(j)],
                               trajectory::format_joint(start[j], prismatic),
                               trajectory::format_joint(setpoint[j], prismatic),
                               trajectory::format_joint(tolerance, prismatic))};
    }
  }
  return ok_status();
}

Status Servo::post_trajectory(motion::Plan plan, std::string trajectory_id) {
  if (plan.trajectory.dof() != model_.dof()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("trajectory has {} joints, robot '{}' has {}", plan.trajectory.dof(),
                             model_.id(), model_.dof())};
  }
  CELL_TRY(trajectory::check_limits(plan.trajectory, limits_, kPlanSlack));
  std::lock_guard lock(mutex_);
  switch (snapshot_.mode) {
    case cell_robot_MODE_FAULT:
      return Error{Errc::kNotReady, "robot is in fault (" + snapshot_.fault_text +
                                        "): send reset first"};
    case cell_robot_MODE_STOPPED:
      return Error{Errc::kNotReady, "robot was stopped: send reset first"};
    case cell_robot_MODE_HOMING:
      return Error{Errc::kNotReady, "robot is homing"};
    default:
      break;
  }
  if (!snapshot_.measured.homed) {
    return Error{Errc::kNotReady, "robot is not homed: send home first"};
  }
  if (snapshot_.moving || pending_.plan) {
    return Error{Errc::kNotReady, "robot is busy with trajectory '" +
                                      (pending_.plan ? pending_.plan_id : snapshot_.trajectory_id) +
                                      "'"};
  }
  if (snapshot_.measured.busy) {
    return Error{Errc::kNotReady, "robot is busy (gripper or homing in progress)"};
  }
  CELL_TRY(check_start(plan.trajectory, snapshot_.setpoint.q));
  pending_.plan = std::move(plan);
  pending_.plan_id = std::move(trajectory_id);
  return ok_status();
}

void Servo::post_alter(trajectory::AlterCorrection correction, Clock::time_point stamp,
                       const std::string& trajectory_id) {
  correction.stamp_s = seconds(stamp);
  std::lock_guard lock(mutex_);
  const bool ours = pending_.plan ? trajectory_id == pending_.plan_id
                                  : trajectory_id == snapshot_.trajectory_id;
  if (!ours) {
    return;  // a late correction for an earlier trajectory, or for another robot's
  }
  pending_.alter = correction;  // last one wins
  pending_.alter_id = trajectory_id;
}

Status Servo::post_command(cell_robot_RobotCommandKind kind, const CommandArgs& args) {
  const auto unsupported = [&](DriverCommand c) -> Status {
    if (!driver_->supports(c)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("'{}' is not supported by the {} driver", command_name(kind),
                               driver_->info().name)};
    }
    return ok_status();
  };
  switch (kind) {
    case cell_robot_CMD_SET_GAINS:
      CELL_TRY(unsupported(DriverCommand::kSetGains));
      break;
    case cell_robot_CMD_SET_MODE:
      CELL_TRY(unsupported(DriverCommand::kSetMode));
      break;
    case cell_robot_CMD_SET_TOLERANCE:
      CELL_TRY(unsupported(DriverCommand::kSetTolerance));
      if (args.tolerance_rad > 0 && std::isfinite(args.tolerance_rad)) {
        CELL_TRY(driver_->check(DriverCommand::kSetTolerance, args));
      }
      break;
    default:
      break;
  }
  std::lock_guard lock(mutex_);
  const bool moving = snapshot_.moving || pending_.plan.has_value();
  switch (kind) {
    case cell_robot_CMD_STOP:
    case cell_robot_CMD_LIGHTS:
    case cell_robot_CMD_ALTER_OFF:
      break;
    case cell_robot_CMD_RESET:
      if (snapshot_.mode != cell_robot_MODE_FAULT && snapshot_.mode != cell_robot_MODE_STOPPED) {
        return ok_status();  // nothing to reset: harmless
      }
      break;
    case cell_robot_CMD_HOME:
    case cell_robot_CMD_GRIPPER_OPEN:
    case cell_robot_CMD_GRIPPER_CLOSE: {
      // Tracking (arrived, following a belt with ALTER) is where a conveyor pick closes its
      // gripper (digest 002 §2.4: grip while tracking, ALTER off after).
      const bool gripping_while_tracking = kind != cell_robot_CMD_HOME && snapshot_.tracking &&
                                           !pending_.plan.has_value();
      if (moving && !gripping_while_tracking) {
        return Error{Errc::kNotReady,
                     fmt::format("cannot {} while the robot moves", command_name(kind))};
      }
      if (snapshot_.mode == cell_robot_MODE_FAULT) {
        return Error{Errc::kNotReady, fmt::format("cannot {}: robot is in fault ({})",
                                                  command_name(kind), snapshot_.fault_text)};
      }
      break;
    }
    case cell_robot_CMD_SET_GAINS:
      if (static_cast<int>(args.kp.size()) != model_.dof() ||
          static_cast<int>(args.kv.size()) != model_.dof()) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("set gains needs {} kp and {} kv values, got {} and {}",
                                 model_.dof(), model_.dof(), args.kp.size(), args.kv.size())};
      }
      for (std::size_t j = 0; j < args.kp.size(); ++j) {
        if (!std::isfinite(args.kp[j]) || !std::isfinite(args.kv[j]) || args.kp[j] < 0 ||
            args.kv[j] < 0) {
          return Error{Errc::kInvalidArgument,
                       fmt::format("gains of joint {} must be finite and >= 0", j)};
        }
      }
      break;
    case cell_robot_CMD_SET_TOLERANCE:
      if (!(args.tolerance_rad > 0) || !std::isfinite(args.tolerance_rad)) {
        return Error{Errc::kInvalidArgument, "tolerance must be > 0"};
      }
      break;
    case cell_robot_CMD_SET_MODE:
      if (moving) {
        return Error{Errc::kNotReady, "cannot change mode while the robot moves"};
      }
      break;
    default:
      return Error{Errc::kInvalidArgument,
                   fmt::format("unknown command kind {}", static_cast<int>(kind))};
  }
  pending_.commands.emplace_back(kind, args);
  return ok_status();
}

void Servo::post_stop(std::string code, std::string text) {
  std::lock_guard lock(mutex_);
  pending_.stop_code = code.empty() ? std::string("command") : std::move(code);
  pending_.stop_text = std::move(text);
}

void Servo::event(cell_health_Severity severity, std::string code, std::string text) {
  std::lock_guard lock(mutex_);
  if (events_out_.size() < 256) {
    events_out_.push_back(ServoEvent{severity, std::move(code), std::move(text)});
  }
}

std::vector<ServoEvent> Servo::take_events() {
  std::lock_guard lock(mutex_);
  return std::exchange(events_out_, {});
}

void Servo::fault(std::uint32_t bits, const std::string& text) {
  executor_.stop();
  mode_ = cell_robot_MODE_FAULT;
  {
    // The fault's own text from now on, not the text of a stop it may have ended.
    std::lock_guard lock(mutex_);
    snapshot_.fault_text = text;
  }
  event(cell_health_SEVERITY_ERROR, "robot.fault",
        fmt::format("robot '{}' faulted (bits 0x{:04x}): {}", model_.id(), bits, text));
}

void Servo::apply_commands(
    std::vector<std::pair<cell_robot_RobotCommandKind, CommandArgs>>& commands) {
  for (auto& [kind, args] : commands) {
    Status status = ok_status();
    switch (kind) {
      case cell_robot_CMD_STOP:
        executor_.stop();
        events_.clear();
        if (mode_ != cell_robot_MODE_FAULT) {
          mode_ = cell_robot_MODE_STOPPED;
          stop_code_ = "command";
          stop_text_.clear();
        }
        event(cell_health_SEVERITY_WARNING, "robot.stopped",
              fmt::format("robot '{}' stopped on command", model_.id()));
        break;
      case cell_robot_CMD_RESET:
        // A reset clears a fault or a stop. The controller itself is reset only out of a fault
        // (its error register, the Excalibur's restart and restore): a stop is the servo's own
        // state, and a reset of a robot with neither is acknowledged and changes nothing (a
        // stray or repeated RESET must not restart a healthy controller, nor halt a move).
        if (mode_ != cell_robot_MODE_FAULT && mode_ != cell_robot_MODE_STOPPED) {
          break;
        }
        if (mode_ == cell_robot_MODE_FAULT) {
          status = driver_->command(DriverCommand::kReset, args);
        }
        if (status) {
          // After a fault or stop the arm may rest elsewhere than the last setpoint (a move
          // not achieved, a drift, a servo board that let go): hold where it is, so the next
          // plan (made from the measured joints) starts here. The executor holds nothing
          // more (its hold was the last setpoint: 281 counts off on the 7545 after a torque
          // fault, which faulted it again the cycle after the reset).
          executor_.clear();
          setpoint_.q = measured_.q;
          setpoint_.qd.setZero();
          mode_ = cell_robot_MODE_IDLE;
          stop_code_.clear();
          stop_text_.clear();
          event(cell_health_SEVERITY_INFO, "robot.reset",
                fmt::format("robot '{}' reset", model_.id()));
        }
        break;
      case cell_robot_CMD_HOME:
        status = driver_->command(DriverCommand::kHome, args);
        break;
      case cell_robot_CMD_GRIPPER_OPEN:
        status = driver_->command(DriverCommand::kGripperOpen, args);
        break;
      case cell_robot_CMD_GRIPPER_CLOSE:
        status = driver_->command(DriverCommand::kGripperClose, args);
        break;
      case cell_robot_CMD_LIGHTS:
        status = driver_->command(DriverCommand::kLights, args);
        if (status) {
          std::lock_guard lock(mutex_);
          snapshot_.halogen_on = args.halogen_on;
          snapshot_.fluorescent_on = args.fluorescent_on;
        }
        break;
      case cell_robot_CMD_ALTER_OFF:
        executor_.alter_off();
        if (const std::uint64_t n = executor_.limited_cycles(); n != limited_reported_) {
          // The corrections asked more than the arm can do: the setpoints kept its limits and
          // lagged the altered path. Under a millimetre: the steps of a correction's rate
          // between corrections, smoothed (information); more: a tracking that may have
          // missed its part (a warning).
          const double lag = executor_.max_lag_mm();
          event(lag < 1.0 ? cell_health_SEVERITY_INFO : cell_health_SEVERITY_WARNING,
                "robot.alter_limited",
                fmt::format("robot '{}': the ALTER corrections asked more than the joint "
                            "limits in {} cycles; the setpoints kept the limits and lagged the "
                            "altered path by up to {:.3f} mm",
                            model_.id(), n - limited_reported_, lag));
          limited_reported_ = n;
        }
        break;
      case cell_robot_CMD_SET_GAINS:
        status = driver_->command(DriverCommand::kSetGains, args);
        break;
      case cell_robot_CMD_SET_MODE:
        status = driver_->command(DriverCommand::kSetMode, args);
        if (status) {  // back from manual or teach: the arm is wherever the operator left it
          executor_.clear();
          setpoint_.q = measured_.q;
          setpoint_.qd.setZero();
        }
        break;
      case cell_robot_CMD_SET_TOLERANCE:
        status = driver_->command(DriverCommand::kSetTolerance, args);
        break;
      default:
        break;
    }
    if (!status) {
      event(cell_health_SEVERITY_WARNING, "robot.command_failed",
            fmt::format("robot '{}': {} failed: {}", model_.id(), command_name(kind),
                        status.error().message));
    }
  }
  commands.clear();
}

void Servo::cycle(Clock::time_point now) {
  const double t = seconds(now);
  const double host_gap_s = last_cycle_s_ >= 0.0 ? t - last_cycle_s_ : 0.0;
  last_cycle_s_ = t;
  Pending pending;
  {
    std::lock_guard lock(mutex_);
    std::swap(pending, pending_);
  }
  apply_commands(pending.commands);
  if (!pending.stop_code.empty()) {
    // The gateway's own stop (its supervisors were lost): exactly a STOP command's effect.
    executor_.stop();
    events_.clear();
    if (mode_ != cell_robot_MODE_FAULT) {
      mode_ = cell_robot_MODE_STOPPED;
      stop_code_ = std::move(pending.stop_code);
      stop_text_ = std::move(pending.stop_text);
    }
  }
  bool loaded = false;  // a path loaded now starts now: no earlier cycle's time is its own
  if (pending.plan && mode_ != cell_robot_MODE_FAULT && mode_ != cell_robot_MODE_STOPPED) {
    motion::Plan& plan = *pending.plan;
    events_ = std::move(plan.events);
    next_event_ = 0;
    hold_until_s_ = -1;
    trajectory_id_ = pending.plan_id;
    executor_.load(std::move(plan.trajectory), t, plan.alter_enabled,
                   {.cumulative = plan.alter_cumulative, .world_frame = plan.alter_world_frame});
    mode_ = cell_robot_MODE_MOVING;
    loaded = true;
  }
  if (pending.alter && pending.alter_id == trajectory_id_) {
    trajectory::AlterCorrection c = *pending.alter;
    executor_.submit_alter(c);
  }

  // Read the controller. RobotState's stamp is this instant (idl/robot.idl: when the joints
  // were read), not the end of the cycle: at 2 m/s of tracking, a stamp 1 ms late puts the
  // tool 2 mm behind where the state says it was.
  const std::int64_t read_ns = wall_time_ns() - std::chrono::duration_cast<std::chrono::nanoseconds>(
                                                    Clock::now() - now)
                                                    .count();
  const CycleStatus read_status = driver_->read(now, measured_);
  if (read_status == CycleStatus::kFault && mode_ != cell_robot_MODE_FAULT) {
    fault(measured_.fault_bits, driver_->describe_faults(measured_.fault_bits));
  } else if (read_status == CycleStatus::kRetry &&
             ++retries_in_a_row_ > driver_->info().link_retries &&
             mode_ != cell_robot_MODE_FAULT) {  // one fault, not one a cycle while it lasts
    fault(0, fmt::format("link to the controller failed {} cycles in a row", retries_in_a_row_));
  } else if (read_status == CycleStatus::kOk) {
    retries_in_a_row_ = 0;
  }

  // Path time. The arm moved as long as the controller's clock advanced, when the driver can
  // see it (a simulated 7545 board: through its own stalls and a late master's, which it
  // absorbed, its clock and its arm stood still); the path advances exactly that much. Else the
  // host's clock stands for it, but after a late cycle (the host stalled, or the controller's
  // handshake did) the path moves on at most max_setpoint_advance; the rest of the stall
  // delays it (DriverInfo).
  if (!loaded && host_gap_s > 0.0) {
    const double max_advance =
        std::chrono::duration<double>(driver_->info().max_setpoint_advance).count();
    double excess = 0.0;
    if (measured_.clock_advance_s >= 0.0) {
      excess = host_gap_s - measured_.clock_advance_s;
    } else if (max_advance > 0.0 && host_gap_s > max_advance) {
      excess = host_gap_s - max_advance;
    }
    if (excess != 0.0) {
      executor_.delay(excess);
      if (mode_ == cell_robot_MODE_MOVING) {
        path_delay_s_ += excess;
      }
    }
  }

  // Next setpoint: the path where the arm is to hold it (the driver's setpoint lead ahead).
  const trajectory::ExecState state = executor_.step(
      t + std::chrono::duration<double>(driver_->info().setpoint_lead).count(), sample_);
  if (state != trajectory::ExecState::kIdle) {
    setpoint_.q = sample_.q;
    setpoint_.qd = sample_.qd;
  } else {
    setpoint_.qd.setZero();
  }
  if (state == trajectory::ExecState::kFailed && mode_ == cell_robot_MODE_MOVING) {
    mode_ = cell_robot_MODE_FAULT;
    event(cell_health_SEVERITY_ERROR, "robot.alter_failed",
          fmt::format("robot '{}': tracking left the workspace: {}", model_.id(),
                      executor_.failure().message));
  }
  // Gripper events fire at their time along the trajectory.
  while (mode_ == cell_robot_MODE_MOVING && next_event_ < events_.size() &&
         executor_.progress() * executor_.trajectory().duration_s() + 1e-9 >=
             events_[next_event_].t_s) {
    const auto& e = events_[next_event_++];
    auto status = driver_->command(e.close ? DriverCommand::kGripperClose
                                           : DriverCommand::kGripperOpen,
                                   CommandArgs{});
    if (!status) {
      event(cell_health_SEVERITY_WARNING, "robot.command_failed", status.error().message);
    }
  }
  const bool arrived = state == trajectory::ExecState::kArrived;
  const bool tracking = arrived && executor_.alter_active();
  if (mode_ == cell_robot_MODE_MOVING && arrived && !tracking && !measured_.busy) {
    mode_ = cell_robot_MODE_IDLE;
  }
  if (mode_ == cell_robot_MODE_IDLE && measured_.busy && !measured_.homed) {
    mode_ = cell_robot_MODE_HOMING;
  } else if (mode_ == cell_robot_MODE_HOMING && !measured_.busy) {
    // The homing re-zeroed the counters: the old setpoint is in a frame that no longer
    // exists. Hold the home the controller defines (not the measured joints: the arm may
    // still be coasting onto the index when the controller reports the homing done).
    if (measured_.homed && driver_->home_joints(setpoint_.q)) {
      setpoint_.qd = JointVector::Zero(setpoint_.q.size());
    }
    mode_ = cell_robot_MODE_IDLE;
  }

  // Write the controller.
  bool applied = false;
  if (mode_ != cell_robot_MODE_FAULT) {
    const CycleStatus write_status = driver_->write(now, setpoint_);
    if (write_status == CycleStatus::kFault) {
      fault(measured_.fault_bits, driver_->describe_faults(measured_.fault_bits));
    }
    applied = driver_->applied_setpoint(applied_);
  }
  if (!applied) {
    applied_ = setpoint_.q;
  }

  ++cycle_;
  std::lock_guard lock(mutex_);
  snapshot_.measured = measured_;
  snapshot_.setpoint = setpoint_;
  snapshot_.commanded = applied_;
  auto pose = model_.forward(measured_.q);
  snapshot_.base_T_tool = pose ? *pose : Eigen::Isometry3d::Identity();
  snapshot_.mode = mode_;
  snapshot_.moving = mode_ == cell_robot_MODE_MOVING;
  snapshot_.fault_bits = measured_.fault_bits;
  if (mode_ == cell_robot_MODE_FAULT && snapshot_.fault_text.empty()) {
    snapshot_.fault_text = measured_.fault_bits != 0 ? driver_->describe_faults(measured_.fault_bits)
                                                     : executor_.failure().message;
  } else if (mode_ == cell_robot_MODE_STOPPED) {
    snapshot_.fault_text = stop_text_;
  } else if (mode_ != cell_robot_MODE_FAULT) {
    snapshot_.fault_text.clear();
  }
  if (mode_ == cell_robot_MODE_STOPPED) {
    snapshot_.stop_code = stop_code_;
  } else {
    snapshot_.stop_code.clear();
  }
  snapshot_.trajectory_id = trajectory_id_;
  snapshot_.progress = executor_.progress();
  snapshot_.tracking = tracking;
  snapshot_.cycle = cycle_;
  snapshot_.stamp_ns = read_ns;
  snapshot_.jitter_max_us = jitter_max_us_;
  snapshot_.overruns = overruns_;
  snapshot_.path_delay_s = path_delay_s_;
}

void Servo::reset_jitter() noexcept {
  std::lock_guard lock(mutex_);
  jitter_max_us_ = 0;
}

void Servo::record_timing(double wake_error_us, bool overrun) noexcept {
  std::lock_guard lock(mutex_);
  jitter_max_us_ = std::max(jitter_max_us_, std::abs(wake_error_us));
  if (overrun) {
    ++overruns_;
  }
}

ServoSnapshot Servo::snapshot() const {
  std::lock_guard lock(mutex_);
  return snapshot_;
}

}  // namespace cell::gateway
