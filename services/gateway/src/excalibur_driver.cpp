#include "excalibur_driver.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <numbers>

#include "cell/common/log.hpp"
#include "cell/common/realtime.hpp"
#include "cell/protocols/excalibur/angles.hpp"
#include "cell/service/paths.hpp"

namespace cell::gateway {
namespace {

namespace pe = protocols::excalibur;

constexpr double kDegPerRad = 180.0 / std::numbers::pi;
/// Joint vectors closer than this [rad] are the same target.
constexpr double kSameTarget = 1e-9;

double max_abs_diff(const JointVector& a, const JointVector& b) {
  return (a - b).cwiseAbs().maxCoeff();
}

std::string deg_list(const JointVector& q) {
  std::string out = "(";
  for (Eigen::Index j = 0; j < q.size(); ++j) {
    out += fmt::format("{}{:.2f}", j == 0 ? "" : ", ", q[j] * kDegPerRad);
  }
  return out + ") deg";
}

std::chrono::nanoseconds seconds(double s) {
  return std::chrono::nanoseconds(static_cast<std::int64_t>(s * 1e9));
}

std::string resolve(const std::string& path) {
  if (path.empty() || std::filesystem::path(path).is_absolute()) {
    return path;
  }
  return (std::filesystem::path(service::cell_home()) / path).lexically_normal().string();
}

}  // namespace

ExcaliburDriver::ExcaliburDriver(const kinematics::RobotModel& model,
                                 std::shared_ptr<const pe::Dialect> dialect,
                                 ExcaliburDriverOptions options,
                                 std::chrono::nanoseconds cycle)
    : model_(model), dialect_(std::move(dialect)), options_(std::move(options)) {
  info_.name = "excalibur";
  info_.dof = 6;
  info_.cycle = cycle;
  tolerance_deg_ = options_.tolerance_rad > 0 ? options_.tolerance_rad * kDegPerRad
                                              : dialect_->defaults().tolerance_deg;
  timeout_s_ = options_.controller_timeout_s > 0 ? options_.controller_timeout_s
                                                 : dialect_->defaults().timeout_s;
  const JointVector zero = JointVector::Zero(6);
  shared_.setpoint_q = zero;
  shared_.setpoint_qd = zero;
  shared_.handled = zero;
  shared_.q = zero;
  shared_.qd = zero;
  last_sent_ = zero;
  measured_ = zero;
  mode_ = options_.mode;
  line_buffer_.reserve(dialect_->longest_command_chars() + 8);
}

ExcaliburDriver::~ExcaliburDriver() { on_deactivate(); }

// --- lifecycle -------------------------------------------------------------------------------

Status ExcaliburDriver::on_configure() {
  if (model_.excalibur() == nullptr || model_.dof() != 6) {
    return Error{Errc::kConfig, fmt::format("the excalibur driver needs an Excalibur robot model; "
                                            "robot '{}' is {}",
                                            model_.id(), kinematics::to_string(model_.kind()))};
  }
  const auto& d = dialect_->defaults();
  if (tolerance_deg_ < d.min_tolerance_deg || tolerance_deg_ > d.max_tolerance_deg) {
    return Error{
        Errc::kConfig,
        fmt::format("driver.tolerance_deg = {} is outside the controller's range [{}, "
                    "{}] deg (dialect '{}')",
                    tolerance_deg_, d.min_tolerance_deg, d.max_tolerance_deg, dialect_->name())};
  }
  if (timeout_s_ < d.min_timeout_s || timeout_s_ > d.max_timeout_s) {
    return Error{Errc::kConfig,
                 fmt::format("driver.controller_timeout_s = {} is outside the controller's range "
                             "[{}, {}] s (dialect '{}')",
                             timeout_s_, d.min_timeout_s, d.max_timeout_s, dialect_->name())};
  }
  return ok_status();
}

Status ExcaliburDriver::on_activate() {
  const pe::Framing& framing = dialect_->framing();
  pe::SerialOptions serial;
  serial.device = options_.device;
  serial.baud = options_.baud;
  serial.emulate_baud = options_.emulate_baud;
  serial.char_delay_s = dialect_->timing().char_delay_s;
  serial.command_delay_s = dialect_->timing().command_delay_s;
  serial.end_chars = framing.end_chars;
  serial.max_line_chars = framing.max_line_chars;
  serial.realtime_priority = options_.realtime_priority;
  auto classify = [d = dialect_](std::string_view line) { return d->looks_unsolicited(line); };
  // The simulator (or a USB adapter) may appear after the gateway: retry for a bounded time.
  const auto deadline = Clock::now() + seconds(options_.open_timeout_s);
  for (;;) {
    auto port = pe::SerialPort::open(serial, classify);
    if (port) {
      port_ = std::move(*port);
      break;
    }
    if (port.error().code == Errc::kInvalidArgument || Clock::now() >= deadline) {
      return Error{port.error().code, fmt::format("{} (gave up after {} s)", port.error().message,
                                                  options_.open_timeout_s)};
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  reply_timeout_s_ =
      dialect_->timing().reply_timeout_s +
      static_cast<double>(dialect_->longest_command_chars()) * port_->char_period_s() +
      static_cast<double>(dialect_->longest_message_chars()) * port_->byte_time_s();
  // Whatever the controller had half-received or half-sent is garbage now: end it and drop it.
  (void)port_->write_line(framing.host_terminator);
  std::this_thread::sleep_for(seconds(std::min(reply_timeout_s_, 0.3)));
  port_->discard_replies();
  pe::ReceivedLine stale;
  while (port_->pop_unsolicited(stale)) {
  }
  stop_ = false;
  std::string why;
  bool ok = false;
  for (int attempt = 0; attempt <= options_.max_attempts && !ok; ++attempt) {
    if (attempt > 0) {
      ++line_errors_;
      log::warn("excalibur", "controller handshake failed, resetting the port",
                {{"attempt", std::to_string(attempt)}, {"error", why}});
      if (auto s = port_->reopen(); !s) {
        why = s.error().message;
        std::this_thread::sleep_for(std::chrono::milliseconds(100));
        continue;
      }
    }
    ok = restore(why, /*patient=*/true);
    if (ok) {
      Exchange e = exchange_once(pe::Command{}, pe::MessageKind::kJoints);
      ok = e.outcome == Outcome::kOk;
      if (ok) {
        measured_ = pe::from_wire(*model_.excalibur(), e.message.angles_deg);
      } else {
        why = e.error;
      }
    }
  }
  if (!ok) {
    port_.reset();
    return Error{Errc::kProtocol,
                 fmt::format("the controller on {} does not answer in dialect '{}' after {} "
                             "attempts: {}",
                             options_.device, dialect_->name(), options_.max_attempts, why)};
  }
  {
    std::lock_guard lock(mutex_);
    shared_.q = measured_;
    shared_.qd.setZero();
    shared_.handled = measured_;
    shared_.setpoint_q = measured_;
    shared_.setpoint_qd.setZero();
    shared_.busy = false;
    shared_.fault_bits = 0;
    shared_.host_mode = mode_ == pe::Mode::kHost;
    shared_.gripper = cell_robot_GRIPPER_UNKNOWN;  // the aperture is not fed back (thesis)
  }
  measured_at_ = Clock::now();
  next_poll_ = measured_at_ + seconds(options_.idle_poll_s);
  log::info("excalibur", "controller ready",
            {{"device", options_.device},
             {"dialect", dialect_->name()},
             {"joints_deg", deg_list(measured_)},
             {"tolerance_deg", fmt::format("{}", tolerance_deg_)},
             {"mode", std::string(pe::to_string(mode_))}});
  io_ = std::thread([this] {
    if (!set_thread_fifo(options_.realtime_priority)) {
      log::warn("excalibur", "cannot use SCHED_FIFO (not root?); the link runs with normal scheduling",
                {{"priority", std::to_string(options_.realtime_priority)}});
    }
    io_loop();
  });
  return ok_status();
}

void ExcaliburDriver::on_deactivate() noexcept {
  stop_ = true;
  if (port_) {
    port_->wake();
  }
  if (io_.joinable()) {
    io_.join();
  }
  port_.reset();
}

void ExcaliburDriver::on_cleanup() noexcept {}

// --- the servo thread ------------------------------------------------------------------------

CycleStatus ExcaliburDriver::read(Clock::time_point now, JointState& state) {
  std::lock_guard lock(mutex_);
  Shared& s = shared_;
  if (s.gripper_moving && now >= s.gripper_done) {
    s.gripper_moving = false;
    s.gripper = s.gripper == cell_robot_GRIPPER_CLOSING ? cell_robot_GRIPPER_CLOSED
                                                        : cell_robot_GRIPPER_OPEN;
  }
  state.q = s.q;
  state.qd = s.qd;
  state.effort = JointVector::Zero(6);
  state.gripper = s.gripper;
  state.homed = true;  // potentiometers: absolute joint angles, nothing to home
  state.busy = s.busy || s.gripper_moving || !s.host_mode;
  state.fault_bits = s.fault_bits;
  return s.fault_bits != 0 ? CycleStatus::kFault : CycleStatus::kOk;
}

CycleStatus ExcaliburDriver::write(Clock::time_point /*now*/, const JointSetpoint& setpoint) {
  bool kick = false;
  std::uint32_t faults = 0;
  {
    std::lock_guard lock(mutex_);
    Shared& s = shared_;
    s.setpoint_q = setpoint.q;
    s.setpoint_qd = setpoint.qd;
    faults = s.fault_bits;
    if (faults == 0 && !s.busy && max_abs_diff(setpoint.q, s.handled) > kSameTarget) {
      if (max_abs_diff(setpoint.q, s.q) <= kSameTarget) {
        s.handled = setpoint.q;  // the arm is reported exactly there: nothing to move
      } else {
        s.busy = true;  // until the I/O thread confirms (or fails) the new target
        kick = true;
      }
    }
  }
  if (kick && port_) {
    port_->wake();
  }
  return faults != 0 ? CycleStatus::kFault : CycleStatus::kOk;
}

Status ExcaliburDriver::check(DriverCommand command, const CommandArgs& args) const {
  if (command == DriverCommand::kSetTolerance) {
    const double tolerance_deg = args.tolerance_rad * kDegPerRad;
    const auto& d = dialect_->defaults();
    if (!(tolerance_deg >= d.min_tolerance_deg && tolerance_deg <= d.max_tolerance_deg)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("tolerance {:.4g} deg is outside the controller's range [{}, {}] "
                               "deg",
                               tolerance_deg, d.min_tolerance_deg, d.max_tolerance_deg)};
    }
  }
  return ok_status();
}

Status ExcaliburDriver::command(DriverCommand command, const CommandArgs& args) {
  Queued q;
  q.command = command;
  switch (command) {
    case DriverCommand::kHome:
      return ok_status();  // potentiometers: always homed
    case DriverCommand::kLights:
      return Error{Errc::kInvalidArgument, "the Excalibur cell has no lights on its controller"};
    case DriverCommand::kSetGains:
      return Error{Errc::kInvalidArgument,
                   "the Excalibur's servos are analog: it has no gains to set from the host"};
    case DriverCommand::kGripperOpen:
    case DriverCommand::kGripperClose:
      if (!dialect_->has(command == DriverCommand::kGripperOpen ? pe::CommandKind::kGripperOpen
                                                                : pe::CommandKind::kGripperClose)) {
        return Error{Errc::kNotReady,
                     fmt::format("dialect '{}' has no gripper commands", dialect_->name())};
      }
      break;
    case DriverCommand::kSetMode:
      switch (args.mode) {
        case cell_robot_MODE_IDLE:
          q.mode = pe::Mode::kHost;
          break;
        case cell_robot_MODE_MANUAL:
          q.mode = pe::Mode::kManual;
          break;
        case cell_robot_MODE_TEACH:
          q.mode = pe::Mode::kTeach;
          break;
        case cell_robot_MODE_PLAYBACK:
          q.mode = pe::Mode::kPlayback;
          break;
        default:
          return Error{Errc::kInvalidArgument,
                       fmt::format("the Excalibur controller has no mode for robot mode {} (use "
                                   "IDLE for host, MANUAL, TEACH or PLAYBACK)",
                                   static_cast<int>(args.mode))};
      }
      break;
    case DriverCommand::kSetTolerance:
      CELL_TRY(check(command, args));
      q.tolerance_deg = args.tolerance_rad * kDegPerRad;
      break;
    case DriverCommand::kReset:
      break;
  }
  {
    std::lock_guard lock(mutex_);
    Shared& s = shared_;
    if (s.queue_size == s.queue.size()) {
      return Error{Errc::kNotReady, "the Excalibur driver's command queue is full"};
    }
    s.queue[(s.queue_head + s.queue_size) % s.queue.size()] = q;
    ++s.queue_size;
    if (command == DriverCommand::kGripperOpen || command == DriverCommand::kGripperClose) {
      s.gripper = command == DriverCommand::kGripperClose ? cell_robot_GRIPPER_CLOSING
                                                          : cell_robot_GRIPPER_OPENING;
      s.gripper_moving = true;
      s.gripper_done = Clock::time_point::max();  // set once the controller has taken it
    }
    if (command == DriverCommand::kReset) {
      // The fault is acknowledged; the target that failed is not tried again.
      s.fault_bits = 0;
      s.handled = s.setpoint_q;
      s.busy = false;
      fault_text_.clear();
    }
  }
  if (port_) {
    port_->wake();
  }
  return ok_status();
}

bool ExcaliburDriver::supports(DriverCommand command) const noexcept {
  switch (command) {
    case DriverCommand::kSetGains:
    case DriverCommand::kLights:
      return false;
    case DriverCommand::kGripperOpen:
      return dialect_->has(pe::CommandKind::kGripperOpen);
    case DriverCommand::kGripperClose:
      return dialect_->has(pe::CommandKind::kGripperClose);
    default:
      return true;
  }
}

std::string ExcaliburDriver::describe_faults(std::uint32_t bits) const {
  if (bits == 0) {
    return {};
  }
  std::string names;
  const auto add = [&](std::uint32_t bit, const char* name) {
    if ((bits & bit) != 0) {
      names += fmt::format("{}{}", names.empty() ? "" : ", ", name);
    }
  };
  add(kFaultMoveNotAchieved, "move not achieved");
  add(kFaultPositionCheck, "position check failed");
  add(kFaultLink, "serial link lost");
  add(kFaultRefused, "command refused");
  std::lock_guard lock(mutex_);
  return fault_text_.empty() ? names : names + ": " + fault_text_;
}

ExcaliburDriverStats ExcaliburDriver::stats() const {
  ExcaliburDriverStats s;
  s.exchanges = exchanges_;
  s.line_errors = line_errors_;
  s.recoveries = recoveries_;
  s.escalations = escalations_;
  s.late_replies = late_replies_;
  s.worst_reply_s = worst_reply_s_.load(std::memory_order_relaxed);
  s.moves_sent = moves_sent_;
  s.targets_done = targets_done_;
  s.targets_failed = targets_failed_;
  s.resyncs = resyncs_;
  return s;
}

// --- the I/O thread: exchanges ---------------------------------------------------------------

ExcaliburDriver::Exchange ExcaliburDriver::exchange_once(const pe::Command& command,
                                                         pe::MessageKind expected,
                                                         bool patient) {
  Exchange e;
  if (stopping()) {
    e.outcome = Outcome::kStopped;
    e.error = "driver stopping";
    return e;
  }
  if (auto s = dialect_->format(command, line_buffer_); !s) {
    e.outcome = Outcome::kRefused;
    e.error = s.error().message;
    return e;
  }
  const std::string_view name = pe::to_string(command.kind);
  line_buffer_ += dialect_->framing().host_terminator;
  port_->discard_replies();  // a late answer to an earlier command is not this one's
  if (auto s = port_->write_line(line_buffer_); !s) {
    e.outcome = Outcome::kLineError;
    e.error = s.error().message;
    return e;
  }
  const Clock::time_point sent = Clock::now();
  auto reply = port_->wait_reply(seconds(reply_timeout_s_));
  bool late = false;
  if (!reply && reply.error().code == Errc::kTimeout && patient && options_.host_latency_s > 0) {
    reply = port_->wait_reply(seconds(options_.host_latency_s));
    late = true;
  }
  if (reply) {
    const double waited = std::chrono::duration<double>(Clock::now() - sent).count();
    if (late) {
      note_late_reply(name, waited);
    }
    if (waited > worst_reply_s_.load(std::memory_order_relaxed)) {
      worst_reply_s_.store(waited, std::memory_order_relaxed);
    }
  }
  if (!reply) {
    e.outcome = Outcome::kLineError;
    e.error = fmt::format("{} ({})", reply.error().message, name);
    return e;
  }
  if (reply->overlong) {
    e.outcome = Outcome::kLineError;
    e.error = fmt::format("reply to {} longer than {} characters: {}", name,
                          dialect_->framing().max_line_chars, pe::quote_line(reply->text));
    return e;
  }
  auto message = dialect_->parse(reply->text);
  if (!message) {
    e.outcome = Outcome::kLineError;
    e.error = fmt::format("garbled reply to {}: {}", name, message.error().message);
    return e;
  }
  if (message->kind == pe::MessageKind::kError) {
    pe::ErrorReason reason{};
    const bool known = dialect_->error_reason(message->code, reason);
    e.outcome = known && pe::is_line_error(reason) ? Outcome::kLineError : Outcome::kRefused;
    e.error = fmt::format("the controller answered {} with {}", name,
                          dialect_->describe_error(message->code));
    return e;
  }
  if (message->kind != expected) {
    e.outcome = Outcome::kLineError;
    e.error = fmt::format("expected a '{}' reply to {}, got '{}'", pe::to_string(expected), name,
                          pe::to_string(message->kind));
    return e;
  }
  ++exchanges_;
  e.message = *message;
  return e;
}

void ExcaliburDriver::note_late_reply(std::string_view command, double waited_s) {
  const std::uint64_t late = late_replies_.fetch_add(1, std::memory_order_relaxed) + 1;
  // One warning per 5 s at most, with the count since the last: a loaded host makes many.
  const Clock::time_point now = Clock::now();
  if (late_logged_ != 0 && now - late_logged_at_ < std::chrono::seconds(5)) {
    return;
  }
  log::warn("late_reply",
            fmt::format("the controller's reply to {} came {:.0f} ms after the command, past its "
                        "reply time of {:.0f} ms (the host delivered it late); taken",
                        command, waited_s * 1e3, reply_timeout_s_ * 1e3),
            {{"late_replies", std::to_string(late)},
             {"since_last_warning", std::to_string(late - late_logged_)}});
  late_logged_ = late;
  late_logged_at_ = now;
}

ExcaliburDriver::Exchange ExcaliburDriver::transact(const pe::Command& command,
                                                    pe::MessageKind expected) {
  Exchange e = exchange_once(command, expected);
  if (e.outcome != Outcome::kLineError) {
    return e;
  }
  for (int attempt = 1; attempt <= options_.max_attempts && !stopping(); ++attempt) {
    ++line_errors_;
    log::warn("line_error", e.error,
              {{"attempt", std::to_string(attempt)}, {"command", pe::to_string(command.kind)}});
    std::string why;
    if (!reset_and_restore(why)) {
      e.error = why;
      continue;
    }
    e = exchange_once(command, expected);
    if (e.outcome == Outcome::kOk) {
      ++recoveries_;
      log::info("link_recovered", "port reset and controller state restored",
                {{"attempts", std::to_string(attempt)}, {"command", pe::to_string(command.kind)}});
      return e;
    }
    if (e.outcome != Outcome::kLineError) {
      return e;
    }
  }
  if (e.outcome == Outcome::kLineError && !stopping()) {
    escalate(e.error);
  }
  return e;
}

bool ExcaliburDriver::reset_and_restore(std::string& why) {
  if (auto s = port_->reopen(); !s) {
    why = s.error().message;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the device may come back
    return false;
  }
  // End whatever the controller half-received; its answer to that (if any) is dropped.
  (void)port_->write_line(dialect_->framing().host_terminator);
  (void)port_->wait_reply(seconds(std::min(reply_timeout_s_, 0.1)));
  port_->discard_replies();
  return restore(why, /*patient=*/false);
}

bool ExcaliburDriver::restore(std::string& why, bool patient) {
  // Each step may meet a line error of its own: it is repeated a few times before the whole
  // restore counts as failed (and the caller resets the port again).
  constexpr int kTriesPerStep = 3;
  const auto step = [&](const pe::Command& c) {
    for (int i = 0; i < kTriesPerStep; ++i) {
      // The first try waits for a late reply: a host stall that made the exchange before a
      // line error may still be delaying this one. The later tries do not, so a dead link is
      // found within seconds.
      Exchange e = exchange_once(c, pe::MessageKind::kOk, patient || i == 0);
      if (e.outcome == Outcome::kOk) {
        return true;
      }
      why = fmt::format("restoring the controller: {}", e.error);
      if (e.outcome != Outcome::kLineError) {
        return false;
      }
      ++line_errors_;
    }
    return false;
  };
  if (!step(pe::Command{pe::CommandKind::kReset, {}, pe::Mode::kHost, 0, 0})) {
    return false;
  }
  ++ready_expected_;  // the reset makes the controller say "ready"
  if (!step(pe::Command{pe::CommandKind::kSetMode, {}, mode_, 0, 0}) ||
      !step(pe::Command{pe::CommandKind::kSetTolerance, {}, pe::Mode::kHost, tolerance_deg_, 0}) ||
      !step(pe::Command{pe::CommandKind::kSetTimeout, {}, pe::Mode::kHost, 0, timeout_s_})) {
    return false;
  }
  if (active_ && mode_ == pe::Mode::kHost) {
    if (!step(move_command(last_sent_))) {
      return false;
    }
    if (final_sent_) {
      final_sent_at_ = Clock::now();  // the controller's timeout starts again
    }
  }
  return true;
}

void ExcaliburDriver::escalate(const std::string& why) {
  ++escalations_;
  link_down_ = true;
  next_relink_ = Clock::now() + std::chrono::seconds(1);
  fail(kFaultLink,
       fmt::format("line errors persisted after {} port resets: {}", options_.max_attempts, why),
       false);
}

void ExcaliburDriver::fail(std::uint32_t bit, const std::string& why, bool resync, bool hold) {
  if (resync) {
    Exchange e = exchange_once(pe::Command{}, pe::MessageKind::kJoints);
    if (e.outcome == Outcome::kOk) {
      const JointVector here = pe::from_wire(*model_.excalibur(), e.message.angles_deg);
      set_reported(here, Clock::now());
      ++resyncs_;
      if (hold && mode_ == pe::Mode::kHost) {
        // A via point sent after the failure (the message came during that exchange) would
        // still carry the arm on: hold it where it was reported instead.
        (void)exchange_once(move_command(here), pe::MessageKind::kOk);
      }
    }
  }
  if (active_) {
    ++targets_failed_;
  }
  active_ = false;
  final_sent_ = false;
  std::string text;
  {
    std::lock_guard lock(mutex_);
    shared_.fault_bits |= bit;
    shared_.busy = false;
    shared_.handled = shared_.setpoint_q;  // never re-sent
    if (fault_text_.size() < 2000) {  // a fault that repeats before the reset: say it once more
      fault_text_ += fmt::format("{}{}; arm at {}", fault_text_.empty() ? "" : " | ", why,
                                 deg_list(shared_.q));
    }
    text = fault_text_;
  }
  log::error("excalibur_fault", text, {{"bits", fmt::format("0x{:x}", bit)}});
}

// --- the I/O thread: what to do --------------------------------------------------------------

pe::Command ExcaliburDriver::move_command(const JointVector& q) const {
  return pe::Command{pe::CommandKind::kMoveJoints, pe::to_wire(*model_.excalibur(), q),
                     pe::Mode::kHost, 0, 0};
}

JointVector ExcaliburDriver::lead(const JointVector& q, const JointVector& qd) const {
  JointVector out = q + qd * options_.stream_lead_s;
  const auto joints = model_.joints();
  for (Eigen::Index j = 0; j < out.size(); ++j) {
    const auto& spec = joints[static_cast<std::size_t>(j)];
    out[j] = std::clamp(out[j], spec.lower, spec.upper);
  }
  return out;
}

bool ExcaliburDriver::query(JointVector& q_out, std::string& why) {
  Exchange e = transact(pe::Command{}, pe::MessageKind::kJoints);
  if (e.outcome != Outcome::kOk) {
    why = e.error;
    return false;
  }
  q_out = pe::from_wire(*model_.excalibur(), e.message.angles_deg);
  measured_ = q_out;
  measured_at_ = Clock::now();
  return true;
}

void ExcaliburDriver::set_reported(const JointVector& q, Clock::time_point now) {
  std::lock_guard lock(mutex_);
  const double dt = std::chrono::duration<double>(now - reported_at_).count();
  if (dt > 1e-3 && dt < 1.0) {
    shared_.qd = (q - shared_.q) / dt;
  } else {
    shared_.qd.setZero();
  }
  shared_.q = q;
  reported_at_ = now;
}

bool ExcaliburDriver::send_move(const JointVector& q) {
  // The instant the command left, not when its reply was read: a "move not achieved" for this
  // very move can arrive between its OK and our return from the exchange, and must not be
  // mistaken for a message about an earlier move (handle_unsolicited, moved_since).
  const Clock::time_point sent_at = Clock::now();
  Exchange e = transact(move_command(q), pe::MessageKind::kOk);
  if (e.outcome == Outcome::kOk) {
    last_sent_ = q;
    last_move_at_ = sent_at;
    active_ = true;
    ++moves_sent_;
    return true;
  }
  if (e.outcome == Outcome::kRefused) {
    fail(kFaultRefused, fmt::format("move to {}: {}", deg_list(q), e.error), true);
  }
  return false;
}

void ExcaliburDriver::complete(const JointVector& target) {
  ++targets_done_;
  active_ = false;
  final_sent_ = false;
  std::lock_guard lock(mutex_);
  shared_.q = target;  // within tolerance: the requested value stands (digest 001 case 17)
  shared_.qd.setZero();
  shared_.handled = target;
  shared_.busy = max_abs_diff(shared_.setpoint_q, target) > kSameTarget;
}

void ExcaliburDriver::poll(Clock::time_point now, bool follow_arm) {
  if (now < next_poll_) {
    return;
  }
  next_poll_ = now + seconds(options_.idle_poll_s);
  JointVector q;
  std::string why;
  if (!query(q, why)) {
    return;
  }
  if (follow_arm) {
    set_reported(q, now);
    return;
  }
  JointVector reported;
  {
    std::lock_guard lock(mutex_);
    reported = shared_.q;
  }
  if (max_abs_diff(q, reported) * kDegPerRad > tolerance_deg_) {
    ++resyncs_;
    log::warn("excalibur", "the arm is no longer where it was reported: resynced",
              {{"reported", deg_list(reported)}, {"measured", deg_list(q)}});
    set_reported(q, now);
  }
}

bool ExcaliburDriver::step_host(Clock::time_point now) {
  JointVector sp_q;
  JointVector sp_qd;
  JointVector handled;
  std::uint32_t faults = 0;
  {
    std::lock_guard lock(mutex_);
    sp_q = shared_.setpoint_q;
    sp_qd = shared_.setpoint_qd;
    handled = shared_.handled;
    faults = shared_.fault_bits;
  }
  if (faults != 0) {
    poll(now, true);  // keep the state live; nothing is sent until a reset
    return false;
  }
  const bool moving = sp_qd.cwiseAbs().maxCoeff() > kSameTarget;
  const bool new_work = max_abs_diff(sp_q, handled) > kSameTarget;
  if (!new_work && !active_) {
    poll(now, false);
    return false;
  }
  if (moving) {
    if (options_.follow == ExcaliburFollow::kFinal) {
      poll(now, true);
      return false;  // wait for the setpoint to stop (a wake-up or the poll period)
    }
    const JointVector desired = lead(sp_q, sp_qd);
    if (!active_ || max_abs_diff(desired, last_sent_) * kDegPerRad > options_.stream_min_step_deg) {
      if (!send_move(desired)) {
        return false;
      }
      final_sent_ = false;
    }
    if (options_.query_while_moving) {
      JointVector q;
      std::string why;
      if (query(q, why)) {
        set_reported(q, Clock::now());
      }
    }
    return true;
  }
  // The setpoint stands still: it is the target.
  if (!active_ || !final_sent_ || max_abs_diff(sp_q, last_sent_) > kSameTarget) {
    if (!send_move(sp_q)) {
      return false;
    }
    final_sent_ = true;
    final_sent_at_ = Clock::now();
    have_previous_ = false;
  }
  if (!options_.position_check) {
    complete(sp_q);  // the requested value is assumed (digest 001 case 17)
    return false;
  }
  JointVector q;
  std::string why;
  if (!query(q, why)) {
    return false;
  }
  // In position: within the tolerance AND settled (two readings in a row agree), so that an
  // arm merely passing through the tolerance band on its way elsewhere is not taken as arrived.
  const double error_deg = max_abs_diff(q, sp_q) * kDegPerRad;
  const bool settled =
      have_previous_ && max_abs_diff(q, previous_) * kDegPerRad <= options_.settle_deg;
  previous_ = q;
  have_previous_ = true;
  if (error_deg <= tolerance_deg_ && settled) {
    complete(sp_q);
    return false;
  }
  set_reported(q, Clock::now());
  if (Clock::now() - final_sent_at_ > seconds(timeout_s_ + options_.arrival_margin_s)) {
    ++resyncs_;
    fail(kFaultPositionCheck,
         fmt::format("not within {} deg of the target {} {:.1f} s after it was sent (off by {:.2f} "
                     "deg)",
                     tolerance_deg_, deg_list(sp_q), timeout_s_ + options_.arrival_margin_s,
                     error_deg),
         false);
    return false;
  }
  return true;
}

void ExcaliburDriver::run_queued() {
  for (;;) {
    Queued q;
    {
      std::lock_guard lock(mutex_);
      if (shared_.queue_size == 0) {
        return;
      }
      q = shared_.queue[shared_.queue_head];
      shared_.queue_head = (shared_.queue_head + 1) % shared_.queue.size();
      --shared_.queue_size;
    }
    switch (q.command) {
      case DriverCommand::kSetMode: {
        Exchange e = transact(pe::Command{pe::CommandKind::kSetMode, {}, q.mode, 0, 0},
                              pe::MessageKind::kOk);
        if (e.outcome == Outcome::kOk) {
          mode_ = q.mode;
          active_ = false;
          final_sent_ = false;
          std::lock_guard lock(mutex_);
          shared_.host_mode = mode_ == pe::Mode::kHost;
          shared_.handled = shared_.setpoint_q;  // a stale setpoint is not a new target
          shared_.busy = false;
          log::info("excalibur", "controller mode set",
                    {{"mode", std::string(pe::to_string(mode_))}});
        } else if (e.outcome == Outcome::kRefused) {
          fail(kFaultRefused, e.error, false);
        }
        next_poll_ = Clock::now();
        break;
      }
      case DriverCommand::kSetTolerance: {
        Exchange e = transact(
            pe::Command{pe::CommandKind::kSetTolerance, {}, pe::Mode::kHost, q.tolerance_deg, 0},
            pe::MessageKind::kOk);
        if (e.outcome == Outcome::kOk) {
          tolerance_deg_ = q.tolerance_deg;
          log::info("excalibur", "tolerance set",
                    {{"tolerance_deg", fmt::format("{}", tolerance_deg_)}});
        } else if (e.outcome == Outcome::kRefused) {
          fail(kFaultRefused, e.error, false);
        }
        break;
      }
      case DriverCommand::kGripperOpen:
      case DriverCommand::kGripperClose: {
        const bool close = q.command == DriverCommand::kGripperClose;
        Exchange e = transact(
            pe::Command{close ? pe::CommandKind::kGripperClose : pe::CommandKind::kGripperOpen,
                        {},
                        pe::Mode::kHost,
                        0,
                        0},
            pe::MessageKind::kOk);
        std::lock_guard lock(mutex_);
        if (e.outcome == Outcome::kOk) {
          shared_.gripper_done = Clock::now() + seconds(options_.gripper_time_s);
        } else {
          shared_.gripper_moving = false;
          shared_.gripper = cell_robot_GRIPPER_UNKNOWN;
        }
        break;
      }
      case DriverCommand::kReset: {
        std::string why;
        active_ = false;
        final_sent_ = false;
        bool ok = false;
        for (int attempt = 0; attempt <= options_.max_attempts && !ok && !stopping(); ++attempt) {
          ok = link_down_ ? reset_and_restore(why) : restore(why, /*patient=*/true);
          link_down_ = link_down_ && !ok;
          if (!ok) {
            link_down_ = true;  // the next attempt starts with a port reset
          }
        }
        if (!ok) {
          if (!stopping()) {
            escalate(why);
          }
          break;
        }
        link_down_ = false;
        JointVector here;
        if (query(here, why)) {
          set_reported(here, Clock::now());
        }
        log::info("excalibur", "controller reset and restored");
        break;
      }
      default:
        break;
    }
  }
}

void ExcaliburDriver::handle_unsolicited() {
  pe::ReceivedLine line;
  std::string line_error;
  bool restarted = false;
  while (port_->pop_unsolicited(line)) {
    auto m = dialect_->parse(line.text);
    if (!m) {
      if (ready_expected_ > 0) {
        --ready_expected_;  // most likely the "ready" of our own reset, damaged
        continue;
      }
      line_error = fmt::format("garbled unsolicited message: {}", m.error().message);
      continue;
    }
    switch (m->kind) {
      case pe::MessageKind::kReady:
        if (ready_expected_ > 0) {
          --ready_expected_;
        } else {
          restarted = true;
        }
        break;
      case pe::MessageKind::kLineError:
        line_error = fmt::format("the controller reports a line error: {}",
                                 dialect_->describe_line_error(m->code));
        break;
      case pe::MessageKind::kMoveNotAchieved: {
        JointVector target;
        {
          std::lock_guard lock(mutex_);
          target = shared_.setpoint_q;
        }
        // The controller stopped the arm when it said so; a move sent since (the message came
        // in during that exchange) must be cancelled by holding the arm where it is.
        const bool moved_since = active_ && last_move_at_ > line.received;
        fail(kFaultMoveNotAchieved,
             fmt::format("{}; target {}", dialect_->describe_not_achieved(m->code),
                         deg_list(active_ ? last_sent_ : target)),
             true, moved_since);
        break;
      }
      default:
        break;
    }
  }
  if (line_error.empty() && !restarted) {
    return;
  }
  std::string why =
      line_error.empty() ? std::string("the controller restarted (ready)") : line_error;
  ++line_errors_;
  log::warn("line_error", why);
  for (int attempt = 1; attempt <= options_.max_attempts && !stopping(); ++attempt) {
    std::string reason;
    if (reset_and_restore(reason)) {
      ++recoveries_;
      log::info("link_recovered", "port reset and controller state restored",
                {{"attempts", std::to_string(attempt)}});
      return;
    }
    why = reason;
  }
  if (!stopping()) {
    escalate(why);
  }
}

void ExcaliburDriver::io_loop() {
  while (!stopping()) {
    run_queued();
    if (stopping()) {
      break;
    }
    handle_unsolicited();
    const Clock::time_point now = Clock::now();
    if (link_down_) {
      // An escalated link: the operator has been told; keep trying so that a RESET finds the
      // link working once the cause is gone.
      if (now >= next_relink_) {
        next_relink_ = now + std::chrono::seconds(1);
        std::string why;
        if (reset_and_restore(why)) {
          link_down_ = false;
          log::info("link_recovered", "serial link back; RESET clears the fault");
        }
      }
      port_->wait_unsolicited(std::chrono::milliseconds(100));
      continue;
    }
    bool more = false;
    if (mode_ == pe::Mode::kHost) {
      more = step_host(now);
    } else {
      poll(now, true);  // the master arm drives the slave: follow it
    }
    if (!more) {
      const auto wait =
          std::clamp(next_poll_ - Clock::now(), Clock::duration::zero(),
                     std::chrono::duration_cast<Clock::duration>(std::chrono::milliseconds(100)));
      port_->wait_unsolicited(wait);
    }
  }
}

// --- config ----------------------------------------------------------------------------------

DriverFactory parse_excalibur_driver(config::MapReader& section) {
  ExcaliburDriverOptions o;
  std::string device;
  std::string dialect_path = "config/controllers/excalibur.yaml";
  std::string follow = "stream";
  std::string mode = "host";
  double tolerance_deg = 0.0;
  section.required("device", device);
  section.optional("dialect", dialect_path);
  section.optional("baud", o.baud);
  section.optional("emulate_baud", o.emulate_baud);
  section.optional("open_timeout_s", o.open_timeout_s);
  section.optional("tolerance_deg", tolerance_deg);
  section.optional("controller_timeout_s", o.controller_timeout_s);
  section.optional("arrival_margin_s", o.arrival_margin_s);
  section.optional("position_check", o.position_check);
  section.optional("max_attempts", o.max_attempts);
  section.optional("idle_poll_s", o.idle_poll_s);
  section.optional("follow", follow);
  section.optional("stream_lead_s", o.stream_lead_s);
  section.optional("stream_min_step_deg", o.stream_min_step_deg);
  section.optional("query_while_moving", o.query_while_moving);
  section.optional("settle_deg", o.settle_deg);
  section.optional("gripper_time_s", o.gripper_time_s);
  section.optional("mode", mode);
  section.optional("realtime_priority", o.realtime_priority);
  section.optional("host_latency_s", o.host_latency_s);
  if (o.realtime_priority < 0 || o.realtime_priority > 99) {
    section.fail("realtime_priority",
                 fmt::format("must be 0 (none) or a SCHED_FIFO priority 1..99, got {}",
                             o.realtime_priority));
  }
  if (protocols::excalibur::baud_constant(o.baud) == 0) {
    section.fail("baud", fmt::format("must be one of 1200, 2400, 4800, 9600, 19200, 38400, "
                                     "57600, 115200, 230400; got {}",
                                     o.baud));
  }
  const auto range = [&](const char* key, double value, double lo, double hi) {
    if (!(value >= lo && value <= hi)) {
      section.fail(key, fmt::format("must be in [{}, {}], got {}", lo, hi, value));
    }
  };
  range("open_timeout_s", o.open_timeout_s, 0.0, 600.0);
  range("arrival_margin_s", o.arrival_margin_s, 0.0, 600.0);
  range("idle_poll_s", o.idle_poll_s, 0.01, 60.0);
  range("stream_lead_s", o.stream_lead_s, 0.0, 2.0);
  range("stream_min_step_deg", o.stream_min_step_deg, 0.0, 90.0);
  range("settle_deg", o.settle_deg, 0.0, 10.0);
  range("gripper_time_s", o.gripper_time_s, 0.0, 10.0);
  range("host_latency_s", o.host_latency_s, 0.0, 10.0);
  if (tolerance_deg != 0.0) {
    range("tolerance_deg", tolerance_deg, 0.001, 90.0);
  }
  if (o.controller_timeout_s != 0.0) {
    range("controller_timeout_s", o.controller_timeout_s, 0.01, 3600.0);
  }
  if (o.max_attempts < 1 || o.max_attempts > 100) {
    section.fail("max_attempts", fmt::format("must be in [1, 100], got {}", o.max_attempts));
  }
  if (follow == "stream") {
    o.follow = ExcaliburFollow::kStream;
  } else if (follow == "final") {
    o.follow = ExcaliburFollow::kFinal;
  } else {
    section.fail("follow", fmt::format("must be 'stream' or 'final', got '{}'", follow));
  }
  bool mode_ok = false;
  for (std::size_t m = 0; m < protocols::excalibur::kModes; ++m) {
    if (protocols::excalibur::to_string(static_cast<protocols::excalibur::Mode>(m)) == mode) {
      o.mode = static_cast<protocols::excalibur::Mode>(m);
      mode_ok = true;
    }
  }
  if (!mode_ok) {
    section.fail("mode", fmt::format("must be host, manual, teach or playback; got '{}'", mode));
  }
  o.tolerance_rad = tolerance_deg / kDegPerRad;
  o.device = resolve(device);
  std::shared_ptr<const protocols::excalibur::Dialect> dialect;
  auto loaded = protocols::excalibur::Dialect::load(resolve(dialect_path));
  if (!loaded) {
    section.fail("dialect", loaded.error().message);
  } else {
    dialect = std::make_shared<const protocols::excalibur::Dialect>(std::move(*loaded));
    const auto& d = dialect->defaults();
    if (tolerance_deg != 0.0 &&
        !(tolerance_deg >= d.min_tolerance_deg && tolerance_deg <= d.max_tolerance_deg)) {
      section.fail("tolerance_deg", fmt::format("{} is outside the controller's range [{}, {}] deg "
                                                "(dialect '{}')",
                                                tolerance_deg, d.min_tolerance_deg,
                                                d.max_tolerance_deg, dialect->name()));
    }
    if (o.controller_timeout_s != 0.0 &&
        !(o.controller_timeout_s >= d.min_timeout_s && o.controller_timeout_s <= d.max_timeout_s)) {
      section.fail(
          "controller_timeout_s",
          fmt::format("{} is outside the controller's range [{}, {}] s (dialect '{}')",
                      o.controller_timeout_s, d.min_timeout_s, d.max_timeout_s, dialect->name()));
    }
  }
  return [o, dialect](const DriverSetup& setup) -> Result<std::unique_ptr<RobotDriver>> {
    if (!dialect) {
      return Error{Errc::kConfig, "the excalibur driver has no dialect"};
    }
    if (setup.model.excalibur() == nullptr) {
      return Error{Errc::kConfig,
                   fmt::format("driver 'excalibur' needs an Excalibur robot model; robot '{}' is "
                               "{}",
                               setup.model.id(), kinematics::to_string(setup.model.kind()))};
    }
    return std::unique_ptr<RobotDriver>(
        std::make_unique<ExcaliburDriver>(setup.model, dialect, o, setup.cycle));
  };
}

}  // namespace cell::gateway
