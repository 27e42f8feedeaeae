#include "gateway_service.hpp"

#include <fmt/format.h>
#include <fmt/ranges.h>

#include <cmath>
#include <ctime>
#include <stdexcept>

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/realtime.hpp"
#include "cell/common/time.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/motion/wire.hpp"

namespace cell::gateway {
namespace {

constexpr dds_attach_t kStop = 1;
constexpr dds_attach_t kTrajectory = 2;
constexpr dds_attach_t kAlter = 3;
constexpr dds_attach_t kCommand = 4;

kinematics::RobotModel load_model(const GatewayConfig& config) {
  auto model = kinematics::load_robot(config.robot_config);
  if (!model) {
    throw std::runtime_error(model.error().message);
  }
  return std::move(*model);
}

timespec to_timespec(std::int64_t ns) {
  return timespec{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
}

}  // namespace

GatewayService::GatewayService(service::Context& ctx, const GatewayConfig& config)
    : ctx_(ctx),
      config_(config),
      model_(load_model(config)),
      trajectory_topic_(ctx.participant(), bus::topics::kTrajectory),
      alter_topic_(ctx.participant(), bus::topics::kAlter),
      command_topic_(ctx.participant(), bus::topics::kRobotCommand),
      reply_topic_(ctx.participant(), bus::topics::kRobotCommandReply),
      state_topic_(ctx.participant(), bus::topics::kRobotState),
      latest_topic_(ctx.participant(), bus::topics::kRobotStateLatest),
      trajectory_reader_(ctx.participant(), trajectory_topic_, bus::topics::kTrajectory),
      alter_reader_(ctx.participant(), alter_topic_, bus::topics::kAlter),
      command_reader_(ctx.participant(), command_topic_, bus::topics::kRobotCommand),
      reply_writer_(ctx.participant(), reply_topic_, bus::topics::kRobotCommandReply),
      state_writer_(ctx.participant(), state_topic_, bus::topics::kRobotState),
      latest_writer_(ctx.participant(), latest_topic_, bus::topics::kRobotStateLatest) {
  const auto cycle = std::chrono::nanoseconds(static_cast<std::int64_t>(1e9 / config_.cycle_hz));
  auto driver = config_.make_driver(DriverSetup{model_, cycle});
  if (!driver) {
    throw std::runtime_error(driver.error().message);
  }
  servo_ = std::make_unique<Servo>(model_, std::move(*driver), config_.start_tolerance_rad,
                                   config_.start_tolerance_mm);
  if (auto s = servo_->start(Clock::now()); !s) {
    throw std::runtime_error(
        fmt::format("driver '{}' failed to start: {}", config_.driver_kind, s.error().message));
  }
  if (!config_.supervisors.empty()) {
    directory_.emplace(ctx.participant(), ctx.common().service_id + ".supervisors");
  }
  publisher_thread_ = std::thread([this] { publisher_loop(); });
  servo_thread_ = std::thread([this] { servo_loop(); });
}

GatewayService::~GatewayService() {
  stop_servo_ = true;
  if (servo_thread_.joinable()) {
    servo_thread_.join();
  }
  publish_request_.fetch_or(kPublishStop);
  publish_request_.notify_one();
  if (publisher_thread_.joinable()) {
    publisher_thread_.join();
  }
  servo_->shutdown();
}

void GatewayService::publisher_loop() {
  cell_robot_RobotMode last_mode = cell_robot_MODE_UNCONFIGURED;
  for (;;) {
    publish_request_.wait(0);
    const std::uint32_t request = publish_request_.exchange(0);
    if ((request & kPublishStop) != 0) {
      return;
    }
    const ServoSnapshot snapshot = servo_->snapshot();
    if ((request & kPublishStream) != 0) {
      publish_state(snapshot, state_writer_);
      servo_->reset_jitter();
    }
    if ((request & kPublishLatest) != 0 || snapshot.mode != last_mode) {
      publish_state(snapshot, latest_writer_);
      last_mode = snapshot.mode;
    }
  }
}

void GatewayService::servo_loop() {
  if (!set_thread_fifo(config_.realtime_priority)) {
    log::warn("servo", "cannot use SCHED_FIFO (not root?); running with normal scheduling",
              {{"priority", std::to_string(config_.realtime_priority)}});
  }
  const std::int64_t period_ns = static_cast<std::int64_t>(1e9 / config_.cycle_hz);
  const auto publish_every = static_cast<std::uint64_t>(
      std::max(1.0, std::round(config_.cycle_hz / config_.state_rate_hz)));
  const auto latest_every =
      static_cast<std::uint64_t>(std::max(1.0, std::round(config_.cycle_hz / 10.0)));
  std::int64_t next = monotonic_ns() + period_ns;
  std::uint64_t n = 0;
  while (!stop_servo_.load(std::memory_order_relaxed)) {
    const timespec wake = to_timespec(next);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &wake, nullptr) == EINTR) {
    }
    const std::int64_t woke = monotonic_ns();
    servo_->cycle(Clock::now());
    const std::int64_t done = monotonic_ns();
    servo_->record_timing(static_cast<double>(woke - next) * 1e-3, done > next + period_ns);
    ++n;
    const std::uint32_t request = (n % publish_every == 0 ? kPublishStream : 0U) |
                                  (n % latest_every == 0 ? kPublishLatest : 0U);
    if (request != 0) {
      publish_request_.fetch_or(request);
      publish_request_.notify_one();  // a futex wake when the publisher waits; no lock
    }
    next += period_ns;
    if (done > next) {  // fell behind by more than a period: skip, do not burst
      next = done + period_ns - (done - next) % period_ns;
    }
  }
}

void GatewayService::publish_state(const ServoSnapshot& s,
                                   const bus::Writer<cell_robot_RobotState>& writer) {
  const std::vector<double> q(s.measured.q.data(), s.measured.q.data() + s.measured.q.size());
  const std::vector<double> qd(s.measured.qd.data(), s.measured.qd.data() + s.measured.qd.size());
  const std::vector<double> sp(s.commanded.data(), s.commanded.data() + s.commanded.size());
  const std::vector<double> effort(s.measured.effort.data(),
                                   s.measured.effort.data() + s.measured.effort.size());
  const std::string frame = model_.id() + "/base";
  cell_robot_RobotState m{};
  m.robot_id = bus::borrow(model_.id());
  m.header.stamp_ns = s.stamp_ns;
  m.header.frame_id = bus::borrow(frame);
  m.header.seq = ++state_seq_;
  bus::borrow(m.position_rad_or_mm, q);
  bus::borrow(m.velocity_rad_or_mm_per_s, qd);
  bus::borrow(m.setpoint_rad_or_mm, sp);
  bus::borrow(m.effort_raw, effort);
  m.base_T_tool = motion::to_idl(s.base_T_tool);
  m.gripper = s.measured.gripper;
  m.mode = s.mode;
  m.homed = s.measured.homed;
  m.moving = s.moving;
  m.halogen_on = s.halogen_on;
  m.fluorescent_on = s.fluorescent_on;
  m.fault_bits = s.fault_bits;
  m.fault_text = bus::borrow(s.fault_text);
  m.stop_code = bus::borrow(s.stop_code);
  m.trajectory_id = bus::borrow(s.trajectory_id);
  m.trajectory_progress = s.progress;
  m.tracking = s.tracking;
  m.cycle_count = s.cycle;
  m.cycle_period_s = 1.0 / config_.cycle_hz;
  m.cycle_jitter_max_us = s.jitter_max_us;
  m.cycle_overruns = s.overruns;
  (void)writer.write(m);  // best-effort stream; a failure is counted by DDS, not fatal
}

void GatewayService::reply(const cell_common_RequestId& id, const Status& status) {
  const std::string code = status ? std::string() : std::string(to_string(status.error().code));
  const std::string reason = status ? std::string() : status.error().message;
  cell_robot_RobotCommandReply r{};
  r.request_id = id;
  r.robot_id = bus::borrow(model_.id());
  r.status.accepted = status.has_value();
  r.status.error_code = bus::borrow(code);
  r.status.reason = bus::borrow(reason);
  if (auto s = reply_writer_.write(r); !s) {
    log::warn("reply", s.error().message);
  }
}

void GatewayService::handle_trajectory(const cell_motion_Trajectory& message) {
  if (bus::str(message.robot_id) != model_.id()) {
    return;
  }
  const std::string id(bus::str(message.trajectory_id));
  // A trajectory sent before this gateway started went to its predecessor (the topic keeps
  // recent requests for late joiners), which died running it or before it could: the arm is
  // not where it started. It is neither run nor answered: its sender learns from this
  // gateway's state that nobody runs it (the predecessor's outcome is unseen) and verifies
  // what the arm did. A restarted gateway never resumes a stale trajectory.
  if (message.header.stamp_ns > 0 && message.header.stamp_ns < started_wall_ns_) {
    log::info("trajectory", "sent to the gateway before this one: not run",
              {{"id", id},
               {"sent_before_start_s",
                fmt::format("{:.2f}", static_cast<double>(started_wall_ns_ -
                                                          message.header.stamp_ns) *
                                          1e-9)}});
    return;
  }
  Status status = [&]() -> Status {
    if (id.empty()) {
      return Error{Errc::kInvalidArgument, "trajectory has no trajectory_id"};
    }
    auto plan = motion::from_idl(message, model_.dof());
    if (!plan) {
      return std::move(plan).error();
    }
    return servo_->post_trajectory(std::move(*plan), id);
  }();
  if (status) {
    log::info("trajectory", "accepted", {{"id", id}, {"motion", bus::str(message.motion_id)}});
  } else {
    log::warn("trajectory", status.error().message, {{"id", id}});
    ctx_.events().publish(cell_health_SEVERITY_WARNING, "trajectory.refused",
                          fmt::format("trajectory '{}' refused: {}", id, status.error().message),
                          model_.id());
  }
  reply(message.request_id, status);
}

void GatewayService::handle_command(const cell_robot_RobotCommand& message) {
  if (bus::str(message.robot_id) != model_.id()) {
    return;
  }
  CommandArgs args;
  args.halogen_on = message.halogen_on;
  args.fluorescent_on = message.fluorescent_on;
  args.kp = bus::to_vector(message.kp);
  args.kv = bus::to_vector(message.kv);
  args.mode = message.mode;
  args.tolerance_rad = message.tolerance_rad;
  const Status status = servo_->post_command(message.kind, args);
  log::info("command", status ? "accepted" : status.error().message,
            {{"kind", std::to_string(static_cast<int>(message.kind))},
             {"operator", bus::str(message.operator_id)}});
  reply(message.request_id, status);
}

void GatewayService::handle_alter(const cell_motion_AlterCorrection& message) {
  if (bus::str(message.robot_id) != model_.id()) {
    return;
  }
  trajectory::AlterCorrection c;
  c.translation_mm = {message.translation_mm.x, message.translation_mm.y, message.translation_mm.z};
  c.rotation_rad = {message.rotation_rad.x, message.rotation_rad.y, message.rotation_rad.z};
  c.velocity_mm_s = {message.velocity_mm_per_s.x, message.velocity_mm_per_s.y,
                     message.velocity_mm_per_s.z};
  c.horizon_s = message.extrapolate_s;
  if (!c.translation_mm.allFinite() || !c.rotation_rad.allFinite() ||
      !c.velocity_mm_s.allFinite() || !std::isfinite(c.horizon_s)) {
    log::warn("alter", "dropped a correction with non-finite values");
    return;
  }
  if (c.horizon_s < 0.0) {
    log::warn("alter", fmt::format("dropped a correction with a negative extrapolate_s ({} s)",
                                   c.horizon_s));
    return;
  }
  // The correction holds at the wall-clock time it was stamped; the servo runs on the steady
  // clock, so convert through its age (bounded: a stamp from a badly synchronised host
  // must not throw the extrapolation far off).
  const double age_s =
      std::clamp(static_cast<double>(wall_time_ns() - message.header.stamp_ns) * 1e-9, 0.0, 0.5);
  const auto stamp = Clock::now() - std::chrono::duration_cast<Clock::duration>(
                                        std::chrono::duration<double>(age_s));
  servo_->post_alter(c, stamp, std::string(bus::str(message.trajectory_id)));
}

void GatewayService::watch_supervisors(const ServoSnapshot& snapshot) {
  if (!directory_) {
    return;
  }
  auto entries = directory_->snapshot();
  if (!entries) {
    log::warn("supervisor", "cannot read heartbeats", {{"error", entries.error().message}});
    return;
  }
  // Lost: the heartbeat's liveliness lapsed (killed, hung or cut off by a partition). A
  // supervisor that never appeared, or stopped cleanly, is not lost: a gateway without a
  // running task service is driven by hand as before.
  std::vector<std::string> lost;
  for (const std::string& id : config_.supervisors) {
    for (const service::ServiceEntry& e : *entries) {
      if (e.service_id == id && e.lost) {
        lost.push_back(id);
      }
    }
  }
  if (lost.size() < config_.supervisors.size()) {
    if (supervisors_lost_) {
      log::info("supervisor", "a supervisor is back", {{"robot", model_.id()}});
    }
    supervisors_lost_ = false;
    return;
  }
  // One stop per loss: once the robot was stopped (and perhaps reset and moved by an
  // operator), it is not stopped again until a supervisor came back and was lost again.
  if (supervisors_lost_) {
    return;
  }
  supervisors_lost_ = true;
  const std::string names = fmt::format("'{}'", fmt::join(lost, "', '"));
  // A robot already halted keeps its reason (a fault, an operator's STOP: that one waits for
  // the operator, not for the task). Any other is stopped, moving or not: a move that ended
  // within the lease leaves the robot idle but still open to whatever its motion service
  // sends next, and the cell that decides what comes next is gone. STOPPED says so, and
  // nothing moves until a RESET (the task's, once it sees the robot again, or an operator's).
  if (snapshot.mode == cell_robot_MODE_FAULT || snapshot.mode == cell_robot_MODE_STOPPED) {
    log::warn("supervisor", "every supervisor lost; the robot was already halted",
              {{"robot", model_.id()}, {"supervisors", names}});
    return;
  }
  const std::string text = fmt::format("stopped: supervisor {} lost", names);
  servo_->post_stop("supervisor_lost", text);
  log::warn(
      "supervisor",
      snapshot.moving || snapshot.tracking ? "every supervisor lost while the robot moves: "
                                             "stopping it"
                                           : "every supervisor lost: holding the robot "
                                             "stopped",
      {{"robot", model_.id()}, {"supervisors", names}, {"trajectory", snapshot.trajectory_id}});
  ctx_.events().publish(cell_health_SEVERITY_WARNING, "gateway.supervisor_lost",
                        fmt::format("robot '{}' {}", model_.id(), text), model_.id());
}

void GatewayService::run(service::Context& ctx) {
  bus::WaitSet waitset(ctx.participant());
  waitset.attach(ctx.stop_guard().get(), kStop);
  waitset.attach(trajectory_reader_.condition(), kTrajectory);
  waitset.attach(alter_reader_.condition(), kAlter);
  waitset.attach(command_reader_.condition(), kCommand);
  ctx.health().set(cell_health_HEALTH_SERVING);
  log::info("gateway", "serving robot",
            {{"robot", model_.id()},
             {"driver", servo_->driver_info().name},
             {"cycle_hz", fmt::format("{}", config_.cycle_hz)}});
  for (;;) {
    const bus::Fired fired = waitset.wait(std::chrono::milliseconds(100));
    if (fired.contains(kStop)) {
      break;
    }
    (void)command_reader_.take_each(
        [&](const cell_robot_RobotCommand& m, const dds_sample_info_t&) { handle_command(m); });
    (void)trajectory_reader_.take_each(
        [&](const cell_motion_Trajectory& m, const dds_sample_info_t&) { handle_trajectory(m); });
    (void)alter_reader_.take_each(
        [&](const cell_motion_AlterCorrection& m, const dds_sample_info_t&) { handle_alter(m); });
    for (auto& e : servo_->take_events()) {
      ctx.events().publish(e.severity, e.code, e.text, model_.id());
    }
    const ServoSnapshot s = servo_->snapshot();
    watch_supervisors(s);
    if (s.mode == cell_robot_MODE_FAULT) {
      ctx.health().set(cell_health_HEALTH_DEGRADED, "robot in fault: " + s.fault_text);
    } else {
      ctx.health().set(cell_health_HEALTH_SERVING);
    }
    ctx.health().tick();
  }
}

}  // namespace cell::gateway
