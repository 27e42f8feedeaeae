#include "motion_service.hpp"

#include <cmath>
#include <chrono>
#include <optional>
#include <stdexcept>
#include <thread>

#include <fmt/format.h>

#include "cell/bus/request_reply.hpp"
#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/motion/wire.hpp"

namespace cell::motion_service {
namespace {

constexpr dds_attach_t kStop = 1;
constexpr dds_attach_t kRequest = 2;
constexpr dds_attach_t kState = 3;
constexpr dds_attach_t kReply = 4;

using std::chrono::steady_clock;

double seconds_since(steady_clock::time_point t) {
  return std::chrono::duration<double>(steady_clock::now() - t).count();
}

/// Samples base_T_tool along a plan for previews: every 20 ms, at most 500 poses.
std::vector<Eigen::Isometry3d> sample_path(const motion::Plan& plan,
                                           const kinematics::RobotModel& model) {
  std::vector<Eigen::Isometry3d> path;
  const double d = plan.trajectory.duration_s();
  const int n = std::clamp(static_cast<int>(std::ceil(d / 0.02)), 1, 499);
  for (int i = 0; i <= n; ++i) {
    auto pose = model.forward(plan.trajectory.sample(d * i / n).q);
    if (pose) {
      path.push_back(*pose);
    }
  }
  return path;
}

Status finite_joints(std::span<const double> values, int dof, const char* what) {
  if (static_cast<int>(values.size()) != dof) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("{}: {} values given, the robot has {} joints", what, values.size(),
                             dof)};
  }
  for (std::size_t i = 0; i < values.size(); ++i) {
    if (!std::isfinite(values[i])) {
      return Error{Errc::kInvalidArgument, fmt::format("{}: value {} is not finite", what, i)};
    }
  }
  return ok_status();
}

}  // namespace

std::string_view to_string(cell_motion_MotionKind kind) noexcept {
  switch (kind) {
    case cell_motion_MOTION_MOVE_JOINTS:
      return "move_joints";
    case cell_motion_MOTION_MOVE_POSE:
      return "move_pose";
    case cell_motion_MOTION_MOVE_LINEAR:
      return "move_linear";
    case cell_motion_MOTION_VIA_PATH:
      return "via_path";
    case cell_motion_MOTION_APPROACH:
      return "approach";
    case cell_motion_MOTION_DEPART:
      return "depart";
    case cell_motion_MOTION_PICK:
      return "pick";
    case cell_motion_MOTION_PLACE:
      return "place";
    case cell_motion_MOTION_TRACK:
      return "track";
    case cell_motion_MOTION_STOP:
      return "stop";
    case cell_motion_MOTION_ALTER_OFF:
      return "alter_off";
  }
  return "unknown";
}

MotionService::MotionService(service::Context& ctx, const MotionConfig& config)
    : config_(config),
      client_id_(bus::make_client_id(config.common.service_id)),
      request_topic_(ctx.participant(), bus::topics::kMotionRequest),
      status_topic_(ctx.participant(), bus::topics::kMotionStatus),
      trajectory_topic_(ctx.participant(), bus::topics::kTrajectory),
      state_topic_(ctx.participant(), bus::topics::kRobotState),
      command_topic_(ctx.participant(), bus::topics::kRobotCommand),
      reply_topic_(ctx.participant(), bus::topics::kRobotCommandReply),
      request_reader_(ctx.participant(), request_topic_, bus::topics::kMotionRequest),
      status_writer_(ctx.participant(), status_topic_, bus::topics::kMotionStatus),
      trajectory_writer_(ctx.participant(), trajectory_topic_, bus::topics::kTrajectory),
      state_reader_(ctx.participant(), state_topic_, bus::topics::kRobotState),
      command_writer_(ctx.participant(), command_topic_, bus::topics::kRobotCommand),
      reply_reader_(ctx.participant(), reply_topic_, bus::topics::kRobotCommandReply) {
  for (const auto& entry : config_.robots) {
    auto model = kinematics::load_robot(entry.config);
    if (!model) {
      throw std::runtime_error(model.error().message);
    }
    if (model->id() != entry.id) {
      throw std::runtime_error(fmt::format("robots: id '{}' but {} describes robot '{}'",
                                           entry.id, entry.config, model->id()));
    }
    Robot robot;
    robot.planner = std::make_unique<motion::Planner>(std::move(*model), entry.planner);
    robots_.emplace(entry.id, std::move(robot));
  }
}

void MotionService::publish(const std::string& motion_id, const cell_common_RequestId& request_id,
                            const std::string& robot_id, cell_motion_MotionState state,
                            const Error* error, double progress, double duration_s,
                            const std::vector<Eigen::Isometry3d>* path,
                            const std::vector<double>* final_joints, const Meeting* meeting) {
  const std::string code = error != nullptr ? std::string(to_string(error->code)) : "";
  const std::string reason = error != nullptr ? error->message : "";
  std::vector<cell_common_Pose> poses;
  if (path != nullptr) {
    for (const auto& p : *path) {
      poses.push_back(motion::to_idl(p));
    }
  }
  cell_motion_MotionStatus s{};
  s.motion_id = bus::borrow(motion_id);
  s.request_id = request_id;
  s.robot_id = bus::borrow(robot_id);
  s.state = state;
  s.error_code = bus::borrow(code);
  s.reason = bus::borrow(reason);
  s.progress = progress;
  s.duration_s = duration_s;
  bus::borrow(s.path, poses);
  if (final_joints != nullptr) {
    bus::borrow(s.final_joints_rad_or_mm, *final_joints);
  }
  s.meet_target = motion::to_idl(Eigen::Isometry3d::Identity());
  if (meeting != nullptr) {
    s.meet_target = motion::to_idl(meeting->pose);
    s.meet_stamp_ns = meeting->stamp_ns;
    s.meet_ramp_mm = meeting->ramp_mm;
  }
  if (auto st = status_writer_.write(s); !st) {
    log::warn("status", st.error().message, {{"motion", motion_id}});
  }
}

Result<motion::Plan> MotionService::plan(const cell_motion_MotionRequest& request,
                                         Robot& robot, std::optional<Meeting>& meeting) const {
  const motion::Planner& planner = *robot.planner;
  const int dof = planner.model().dof();
  const double scale = request.speed_scale == 0.0 ? 1.0 : request.speed_scale;
  // Planned from the measured joints, a joint read just past a limit put on it.
  const trajectory::JointVector q0 = planner.start_within_limits(robot.view.q);
  auto target = [&]() { return motion::from_idl(request.target); };
  switch (bus::raw(request.kind)) {  // any value may come off the wire
    case cell_motion_MOTION_MOVE_JOINTS: {
      const auto joints = bus::span(request.joints_rad_or_mm);
      CELL_TRY(finite_joints(joints, dof, "joints"));
      trajectory::JointVector q1(dof);
      for (int j = 0; j < dof; ++j) {
        q1[j] = joints[static_cast<std::size_t>(j)];
      }
      return planner.move_joints(q0, q1, scale);
    }
    case cell_motion_MOTION_MOVE_POSE: {
      auto t = target();
      if (!t) {
        return std::move(t).error();
      }
      return planner.move_pose(q0, *t, std::string(bus::str(request.branch)), scale);
    }
    case cell_motion_MOTION_MOVE_LINEAR: {
      auto t = target();
      if (!t) {
        return std::move(t).error();
      }
      return planner.move_linear(q0, *t, scale);
    }
    case cell_motion_MOTION_VIA_PATH: {
      auto t = target();
      if (!t) {
        return std::move(t).error();
      }
      std::vector<Eigen::Isometry3d> via;
      for (const auto& p : bus::span(request.via)) {
        auto v = motion::from_idl(p);
        if (!v) {
          return with_context(std::move(v).error(), "via point");
        }
        via.push_back(*v);
      }
      return planner.via_path(q0, via, *t, scale);
    }
    case cell_motion_MOTION_APPROACH: {
      auto t = target();
      if (!t) {
        return std::move(t).error();
      }
      return planner.approach(q0, *t, request.distance_mm, scale);
    }
    case cell_motion_MOTION_DEPART:
      return planner.depart(q0, request.distance_mm, scale);
    case cell_motion_MOTION_PICK:
    case cell_motion_MOTION_PLACE: {
      auto t = target();
      if (!t) {
        return std::move(t).error();
      }
      return planner.pick_or_place(q0, *t, request.distance_mm,
                                   request.kind == cell_motion_MOTION_PICK, scale);
    }
    case cell_motion_MOTION_TRACK: {
      auto t = target();
      if (!t) {
        return std::move(t).error();
      }
      const auto& v = request.target_velocity_mm_per_s;
      const Eigen::Vector3d velocity(v.x, v.y, v.z);
      if (!velocity.allFinite()) {
        return Error{Errc::kInvalidArgument, "target_velocity_mm_per_s is not finite"};
      }
      if (velocity.isZero()) {
        return planner.track(q0, *t, request.alter_cumulative, request.alter_world_frame, scale,
                             request.track_joint_interpolated);
      }
      // A moving target: meet it where the robot can first be in time. The clocks: the
      // target's stamp and this host's wall clock (the cell's hosts are synchronised).
      const double since_stamp_s =
          static_cast<double>(wall_time_ns() - request.target_stamp_ns) * 1e-9;
      if (!(std::abs(since_stamp_s) <= config_.max_target_age_s)) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("target_stamp_ns is {:.3f} s from this host's clock (at most "
                                 "{} s): a stale target, or clocks not synchronised",
                                 since_stamp_s, config_.max_target_age_s)};
      }
      if (!(request.meet_margin_s >= 0 && request.meet_margin_s <= 1.0)) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("meet_margin_s must be in [0, 1] s, got {}",
                                 request.meet_margin_s)};
      }
      if (!std::isfinite(request.meet_from_mm) || !std::isfinite(request.meet_to_mm) ||
          (request.meet_to_mm > 0 && request.meet_to_mm < request.meet_from_mm)) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("meet window [{}, {}] mm is not a window", request.meet_from_mm,
                                 request.meet_to_mm)};
      }
      motion::MovingTarget moving;
      moving.at_stamp = *t;
      moving.velocity_mm_s = velocity;
      moving.start_s = std::max(0.0, since_stamp_s) + config_.track_start_latency_s;
      moving.margin_s = request.meet_margin_s;
      moving.min_travel_mm = request.meet_from_mm;
      moving.max_travel_mm = request.meet_to_mm;
      moving.joint_interpolated = request.track_joint_interpolated;
      moving.follow_s = request.meet_follow_s > 0.0 && std::isfinite(request.meet_follow_s)
                            ? request.meet_follow_s
                            : planner.options().gripper_dwell_s;
      auto met = planner.intercept(q0, moving, request.alter_cumulative,
                                   request.alter_world_frame, scale);
      if (!met) {
        return std::move(met).error();
      }
      meeting = Meeting{
          met->meet,
          request.target_stamp_ns + static_cast<std::int64_t>(std::llround(met->meet_s * 1e9)),
          met->ramp_mm};
      return std::move(met->plan);
    }
    default:
      return Error{Errc::kInvalidArgument,
                   fmt::format("unknown motion kind {}", bus::raw(request.kind))};
  }
}

void MotionService::send_command(const std::string& robot_id, cell_robot_RobotCommandKind kind) {
  const std::string operator_id = config_.common.service_id;
  cell_robot_RobotCommand c{};
  c.request_id.client_id = bus::borrow(client_id_);
  c.request_id.seq = ++seq_;
  c.robot_id = bus::borrow(robot_id);
  c.kind = kind;
  c.operator_id = bus::borrow(operator_id);
  if (auto s = command_writer_.write(c); !s) {
    log::warn("command", s.error().message);
  }
}

void MotionService::handle_request(const cell_motion_MotionRequest& request) {
  const std::string motion_id(bus::str(request.motion_id));
  const std::string robot_id(bus::str(request.robot_id));
  const std::string kind(to_string(request.kind));
  auto refuse = [&](const Error& error) {
    log::warn("refuse", error.message, {{"motion", motion_id}, {"robot", robot_id}, {"kind", kind}});
    publish(motion_id, request.request_id, robot_id, cell_motion_MOTION_REFUSED, &error);
  };
  if (motion_id.empty()) {
    refuse(Error{Errc::kInvalidArgument, "motion_id is empty"});
    return;
  }
  auto it = robots_.find(robot_id);
  if (it == robots_.end()) {
    std::string known;
    for (const auto& [id, r] : robots_) {
      known += (known.empty() ? "" : ", ") + id;
    }
    refuse(Error{Errc::kInvalidArgument,
                 fmt::format("unknown robot '{}' (this motion service plans for: {})", robot_id,
                             known)});
    return;
  }
  Robot& robot = it->second;
  if (request.kind == cell_motion_MOTION_STOP || request.kind == cell_motion_MOTION_ALTER_OFF) {
    send_command(robot_id, request.kind == cell_motion_MOTION_STOP ? cell_robot_CMD_STOP
                                                                    : cell_robot_CMD_ALTER_OFF);
    publish(motion_id, request.request_id, robot_id, cell_motion_MOTION_DONE);
    return;
  }
  if (!(request.speed_scale >= 0 && request.speed_scale <= 1)) {
    refuse(Error{Errc::kInvalidArgument,
                 fmt::format("speed_scale must be in (0, 1] (0 means 1), got {}",
                             request.speed_scale)});
    return;
  }
  if (robot.view.received == SteadyTime{} || seconds_since(robot.view.received) > config_.state_timeout_s) {
    refuse(Error{Errc::kNotReady,
                 fmt::format("no state from robot '{}' for {:.1f} s: is its gateway running?",
                             robot_id,
                             robot.view.received == SteadyTime{} ? INFINITY
                                                                 : seconds_since(robot.view.received))});
    return;
  }
  if (robot.active && !request.preview_only) {
    refuse(Error{Errc::kNotReady, fmt::format("robot '{}' is busy with motion '{}'", robot_id,
                                              robot.active->motion_id)});
    return;
  }
  if (robot.view.mode == cell_robot_MODE_FAULT && !request.preview_only) {
    refuse(Error{Errc::kNotReady,
                 fmt::format("robot '{}' is in fault: {}", robot_id, robot.view.fault_text)});
    return;
  }
  std::optional<Meeting> meeting;
  auto planned = [&]() -> Result<motion::Plan> {
    try {
      return plan(request, robot, meeting);
    } catch (const std::exception& e) {  // the boundary: nothing escapes into the loop
      return Error{Errc::kInvalidArgument, std::string("planning failed: ") + e.what()};
    }
  }();
  if (!planned) {
    refuse(std::move(planned).error());
    return;
  }
  const double duration = planned->trajectory.duration_s();
  if (request.preview_only) {
    const auto path = sample_path(*planned, robot.planner->model());
    const auto& end = planned->trajectory.end();
    const std::vector<double> final_joints(end.data(), end.data() + end.size());
    publish(motion_id, request.request_id, robot_id, cell_motion_MOTION_PREVIEW, nullptr, 0.0,
            duration, &path, &final_joints, meeting ? &*meeting : nullptr);
    log::info("preview", "planned", {{"motion", motion_id}, {"kind", kind},
                                     {"duration_s", fmt::format("{:.3f}", duration)}});
    return;
  }
  Active active;
  active.motion_id = motion_id;
  active.robot_id = robot_id;
  active.client_id = std::string(bus::str(request.request_id.client_id));
  active.request_id = request.request_id;
  active.request_id.client_id = nullptr;  // re-pointed at active.client_id when publishing
  active.trajectory_id = fmt::format("{}#{}", motion_id, ++seq_);
  active.gateway_seq = seq_;
  active.sent = steady_clock::now();
  active.duration_s = duration;
  const auto& end = planned->trajectory.end();
  active.final_joints.assign(end.data(), end.data() + end.size());
  active.meeting = meeting;

  motion::TrajectoryWire wire;
  motion::to_idl(*planned, robot_id, active.trajectory_id, motion_id, wire);
  wire.message.request_id.client_id = bus::borrow(client_id_);
  wire.message.request_id.seq = active.gateway_seq;
  wire.message.header.stamp_ns = wall_time_ns();
  // A reliable write blocks while a reader that died (a gateway killed a moment ago, its
  // successor already up) still holds unacknowledged samples, until the write's 1 s blocking
  // time: a few tries before the motion is refused (a table job's place was once refused so
  // and its part left in the gripper).
  Status written = trajectory_writer_.write(wire.message);
  for (int attempt = 1; !written && attempt < 4; ++attempt) {
    log::warn("accept", "trajectory write failed: trying again",
              {{"motion", motion_id}, {"attempt", std::to_string(attempt)},
               {"error", written.error().message}});
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    wire.message.header.stamp_ns = wall_time_ns();
    written = trajectory_writer_.write(wire.message);
  }
  if (!written) {
    refuse(Error{Errc::kBus, written.error().message});
    return;
  }
  robot.active = std::move(active);
  cell_common_RequestId id = robot.active->request_id;
  id.client_id = bus::borrow(robot.active->client_id);
  publish(motion_id, id, robot_id, cell_motion_MOTION_ACCEPTED, nullptr, 0.0, duration, nullptr,
          nullptr, robot.active->meeting ? &*robot.active->meeting : nullptr);
  log::info("accept", "trajectory sent",
            {{"motion", motion_id}, {"kind", kind}, {"robot", robot_id},
             {"duration_s", fmt::format("{:.3f}", duration)}});
}

void MotionService::finish(Robot& robot, cell_motion_MotionState state, const Error* error) {
  Active& a = *robot.active;
  cell_common_RequestId id = a.request_id;
  id.client_id = bus::borrow(a.client_id);
  publish(a.motion_id, id, a.robot_id, state, error, state == cell_motion_MOTION_DONE ? 1.0 : robot.view.progress,
          a.duration_s, nullptr, &a.final_joints, a.meeting ? &*a.meeting : nullptr);
  log::info("finish", state == cell_motion_MOTION_DONE ? "done" : "failed",
            {{"motion", a.motion_id}, {"reason", error != nullptr ? error->message : ""}});
  finished_.push_back(a.motion_id);
  while (static_cast<int>(finished_.size()) > config_.keep_finished) {
    // Forget old motions so the transient-local status topic does not grow without bound.
    const std::string old = finished_.front();
    finished_.pop_front();
    cell_motion_MotionStatus key{};
    key.motion_id = bus::borrow(old);
    (void)status_writer_.unregister(key);
  }
  robot.active.reset();
}

void MotionService::handle_state(const cell_robot_RobotState& state) {
  auto it = robots_.find(std::string(bus::str(state.robot_id)));
  if (it == robots_.end()) {
    return;
  }
  Robot& robot = it->second;
  const auto q = bus::span(state.position_rad_or_mm);
  if (static_cast<int>(q.size()) != robot.planner->model().dof()) {
    return;  // a gateway configured for another model: ignore rather than plan from garbage
  }
  RobotView& v = robot.view;
  v.q.resize(static_cast<Eigen::Index>(q.size()));
  for (std::size_t j = 0; j < q.size(); ++j) {
    v.q[static_cast<Eigen::Index>(j)] = q[j];
  }
  v.mode = state.mode;
  v.homed = state.homed;
  v.moving = state.moving;
  v.tracking = state.tracking;
  v.trajectory_id = bus::str(state.trajectory_id);
  v.progress = state.trajectory_progress;
  v.fault_text = bus::str(state.fault_text);
  v.received = steady_clock::now();
}

void MotionService::handle_gateway_reply(const cell_robot_RobotCommandReply& reply) {
  if (bus::str(reply.request_id.client_id) != client_id_) {
    return;
  }
  for (auto& [id, robot] : robots_) {
    if (!robot.active || robot.active->gateway_seq != reply.request_id.seq) {
      continue;
    }
    if (reply.status.accepted) {
      robot.active->gateway_accepted = true;
    } else {
      const Error error{Errc::kNotReady, fmt::format("gateway of '{}' refused the trajectory: {}",
                                                     id, bus::str(reply.status.reason))};
      finish(robot, cell_motion_MOTION_FAILED, &error);
    }
  }
}

void MotionService::supervise() {
  for (auto& [id, robot] : robots_) {
    if (!robot.active) {
      continue;
    }
    Active& a = *robot.active;
    const RobotView& v = robot.view;
    if (!a.gateway_accepted) {
      if (seconds_since(a.sent) > config_.gateway_timeout_s) {
        const Error error{Errc::kTimeout,
                          fmt::format("gateway of '{}' did not accept the trajectory within "
                                      "{:.1f} s",
                                      id, config_.gateway_timeout_s)};
        finish(robot, cell_motion_MOTION_FAILED, &error);
      }
      continue;
    }
    if (seconds_since(v.received) > config_.state_timeout_s) {
      const Error error{Errc::kTimeout, fmt::format("lost the state of robot '{}' for {:.1f} s",
                                                    id, seconds_since(v.received))};
      finish(robot, cell_motion_MOTION_FAILED, &error);
      continue;
    }
    // A robot in fault or stopped: the reason its motion fails (none while it may run).
    // (An init-capture: clang before 16 cannot capture a structured binding.)
    const auto halted_error = [&v, &robot_id = id]() -> std::optional<Error> {
      if (v.mode == cell_robot_MODE_FAULT) {
        return Error{Errc::kProtocol,
                     fmt::format("robot '{}' faulted: {}", robot_id, v.fault_text)};
      }
      if (v.mode == cell_robot_MODE_STOPPED) {
        return Error{Errc::kNotReady, fmt::format("robot '{}' was stopped", robot_id)};
      }
      return std::nullopt;
    };
    if (v.trajectory_id != a.trajectory_id) {
      if (!a.started) {
        // Not started yet. A robot in fault or stopped runs no trajectory (the gateway's servo
        // drops a plan that finds it so): this one never will. Without this the motion waited
        // for ever, and the task failed the job after its 120 s (the README's run, a deadline
        // fault 30 ms after the gateway accepted a place). 0.3 s of it is a verdict, as below.
        if (const auto halted = halted_error(); halted) {
          if (a.mismatch_since == SteadyTime{}) {
            a.mismatch_since = steady_clock::now();
          } else if (seconds_since(a.mismatch_since) > 0.3) {
            finish(robot, cell_motion_MOTION_FAILED, &*halted);
          }
        } else {
          a.mismatch_since = SteadyTime{};
        }
        continue;  // the gateway has not started it yet
      }
      // It ran and the robot now names another (or none): its gateway restarted or dropped it.
      // A state or two out of order is no verdict; 0.3 s of it is.
      if (a.mismatch_since == SteadyTime{}) {
        a.mismatch_since = steady_clock::now();
      } else if (seconds_since(a.mismatch_since) > 0.3) {
        const Error error{Errc::kProtocol,
                          fmt::format("robot '{}' stopped running trajectory '{}' (its state names "
                                      "'{}'): the gateway restarted or dropped it",
                                      id, a.trajectory_id, v.trajectory_id)};
        finish(robot, cell_motion_MOTION_FAILED, &error);
      }
      continue;
    }
    a.started = true;
    a.mismatch_since = SteadyTime{};
    if (const auto halted = halted_error(); halted) {
      finish(robot, cell_motion_MOTION_FAILED, &*halted);
    } else if (!v.moving || v.tracking) {
      finish(robot, cell_motion_MOTION_DONE, nullptr);
    } else if (seconds_since(a.last_status) >= 1.0 / config_.status_rate_hz) {
      cell_common_RequestId rid = a.request_id;
      rid.client_id = bus::borrow(a.client_id);
      publish(a.motion_id, rid, a.robot_id, cell_motion_MOTION_RUNNING, nullptr, v.progress,
              a.duration_s, nullptr, nullptr, a.meeting ? &*a.meeting : nullptr);
      a.last_status = steady_clock::now();
    }
  }
}

void MotionService::take_requests() {
  auto fresh = request_reader_.take_copies(64);
  if (fresh) {
    for (auto& r : *fresh) {
      waiting_.push_back(Waiting{std::move(r), steady_clock::now()});
    }
  }
  std::vector<Waiting> still;
  for (auto& w : waiting_) {
    const cell_motion_MotionRequest& r = w.request.get();
    auto it = robots_.find(std::string(bus::str(r.robot_id)));
    const bool no_state_yet = it != robots_.end() && it->second.view.received == SteadyTime{};
    if (no_state_yet && seconds_since(w.since) < config_.state_timeout_s &&
        r.kind != cell_motion_MOTION_STOP && r.kind != cell_motion_MOTION_ALTER_OFF) {
      still.push_back(std::move(w));
      continue;
    }
    handle_request(r);
  }
  waiting_ = std::move(still);
}

void MotionService::run(service::Context& ctx) {
  bus::WaitSet waitset(ctx.participant());
  waitset.attach(ctx.stop_guard().get(), kStop);
  waitset.attach(request_reader_.condition(), kRequest);
  waitset.attach(state_reader_.condition(), kState);
  waitset.attach(reply_reader_.condition(), kReply);
  ctx.health().set(cell_health_HEALTH_SERVING);
  for (;;) {
    const bus::Fired fired = waitset.wait(std::chrono::milliseconds(50));
    if (fired.contains(kStop)) {
      break;
    }
    (void)state_reader_.take_each(
        [&](const cell_robot_RobotState& s, const dds_sample_info_t&) { handle_state(s); });
    (void)reply_reader_.take_each([&](const cell_robot_RobotCommandReply& r,
                                      const dds_sample_info_t&) { handle_gateway_reply(r); });
    take_requests();
    supervise();
    ctx.health().tick();
  }
  // Answer what is still running: the robot goes on, but this service stops watching it.
  for (auto& [id, robot] : robots_) {
    if (robot.active) {
      const Error error{Errc::kNotReady, "motion service stopped while the motion ran"};
      finish(robot, cell_motion_MOTION_FAILED, &error);
    }
  }
}

}  // namespace cell::motion_service
