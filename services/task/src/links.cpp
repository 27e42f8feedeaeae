#include "links.hpp"

#include <algorithm>
#include <cmath>
#include <thread>

#include <fmt/format.h>

#include "cell/bus/topics.hpp"
#include "cell/bus/view.hpp"
#include "cell/common/time.hpp"
#include "cell/geometry/idl_pose.hpp"

namespace cell::task_service {
namespace {

using namespace std::chrono_literals;

constexpr auto kPoll = 20ms;

bool terminal(cell_motion_MotionState s) {
  return s == cell_motion_MOTION_DONE || s == cell_motion_MOTION_FAILED ||
         s == cell_motion_MOTION_REFUSED || s == cell_motion_MOTION_PREVIEW;
}

MotionOutcome outcome_of(const cell_motion_MotionStatus& s) {
  MotionOutcome o;
  o.state = s.state;
  o.reason = std::string(bus::str(s.reason));
  o.error_code = std::string(bus::str(s.error_code));
  o.final_joints = bus::to_vector(s.final_joints_rad_or_mm);
  return o;
}

}  // namespace

Interrupt interrupt_of(const Control& control) noexcept {
  if (control.cancel.load()) {
    return Interrupt::kCancel;
  }
  if (control.stop.load()) {
    return Interrupt::kStop;
  }
  return Interrupt::kNone;
}

Links::Links(const bus::Participant& participant, const std::string& client)
    : participant_(participant),
      motions_(participant, bus::topics::kMotionRequest, bus::topics::kMotionStatus,
               bus::make_client_id(client)),
      images_(participant, bus::topics::kImageRequest, bus::topics::kDetections,
              bus::make_client_id(client + ".vision")),
      commands_(participant, bus::topics::kRobotCommand, bus::topics::kRobotCommandReply,
                bus::make_client_id(client + ".robot")),
      status_topic_(participant, bus::topics::kMotionStatus),
      status_reader_(participant, status_topic_, bus::topics::kMotionStatus),
      state_topic_(participant, bus::topics::kRobotState),
      state_reader_(participant, state_topic_, bus::topics::kRobotState),
      belt_topic_(participant, bus::topics::kBeltState),
      belt_reader_(participant, belt_topic_, bus::topics::kBeltState),
      alter_topic_(participant, bus::topics::kAlter),
      alter_writer_(participant, alter_topic_, bus::topics::kAlter),
      belt_cal_topic_(participant, bus::topics::kBeltCalibration),
      belt_cal_reader_(participant, belt_cal_topic_, bus::topics::kBeltCalibration),
      peers_(participant, client + ".peers") {}

Peers::Peers(const bus::Participant& participant, const std::string& client)
    : directory_(participant, client) {}

void Peers::refresh(bool force) {
  const auto now = Clock::now();
  if (!force && settled_ && now - last_ < 100ms) {
    return;
  }
  last_ = now;
  auto entries = settled_ ? directory_.snapshot() : directory_.wait_settled(3000ms);
  settled_ = true;
  if (!entries) {
    return;  // a read error: keep what we knew (the next refresh tries again)
  }
  for (auto& [id, seen] : seen_) {
    seen.present = false;
  }
  for (const service::ServiceEntry& e : *entries) {
    Seen& seen = seen_[e.service_id];
    const bool was_alive = seen.pid != 0 && !seen.lost;
    if (was_alive && (e.lost || e.pid != seen.pid)) {
      ++seen.generation;
    }
    seen.present = true;
    seen.lost = e.lost;
    seen.pid = e.pid;
  }
  for (auto& [id, seen] : seen_) {
    if (!seen.present && seen.pid != 0) {
      if (!seen.lost) {
        ++seen.generation;  // vanished (stopped): whatever it held is gone
      }
      seen.pid = 0;
      seen.lost = false;
    }
  }
}

std::string Peers::missing(const std::vector<std::string>& ids) const {
  std::string out;
  for (const std::string& id : ids) {
    auto it = seen_.find(id);
    const char* why = nullptr;
    if (it == seen_.end() || !it->second.present) {
      why = "not on the bus";
    } else if (it->second.lost) {
      why = "no heartbeat";
    }
    if (why != nullptr) {
      out += fmt::format("{}{}: {}", out.empty() ? "" : ", ", id, why);
    }
  }
  return out;
}

std::uint64_t Peers::generation(const std::string& id) const {
  auto it = seen_.find(id);
  return it != seen_.end() ? it->second.generation : 0;
}

std::vector<std::uint64_t> Peers::generations(const std::vector<std::string>& ids) const {
  std::vector<std::uint64_t> out;
  out.reserve(ids.size());
  for (const auto& id : ids) {
    out.push_back(generation(id));
  }
  return out;
}

std::optional<Links::BeltCalibrationView> Links::belt_calibration(const std::string& belt_id) {
  auto batch = belt_cal_reader_.take_copies(8);
  if (batch) {
    for (const auto& b : *batch) {
      BeltCalibrationView v;
      v.robot_id = std::string(bus::str(b->robot_id));
      v.mm_per_count = b->mm_per_count;
      v.direction = Eigen::Vector3d(b->direction.x, b->direction.y, b->direction.z);
      v.origin_mm = Eigen::Vector3d(b->origin_mm.x, b->origin_mm.y, b->origin_mm.z);
      v.version = std::string(bus::str(b->version));
      if (v.mm_per_count > 0 && std::isfinite(v.mm_per_count) && v.direction.allFinite() &&
          v.direction.norm() > 1e-9) {
        v.direction.normalize();
        belt_cals_[std::string(bus::str(b->belt_id))] = v;
      }
    }
  }
  auto it = belt_cals_.find(belt_id);
  if (it == belt_cals_.end()) {
    return std::nullopt;
  }
  return it->second;
}

void Links::take_states() {
  for (;;) {
    auto batch = state_reader_.take_copies(64);
    if (!batch || batch->empty()) {
      return;
    }
    for (const auto& s : *batch) {
      RobotView& v = robots_[std::string(bus::str(s->robot_id))];
      const auto q = bus::span(s->position_rad_or_mm);
      v.known = true;
      v.q = Eigen::Map<const Eigen::VectorXd>(q.data(), static_cast<Eigen::Index>(q.size()));
      if (auto pose = geometry::pose_from_idl(s->base_T_tool); pose) {
        v.base_T_tool = *pose;
      }
      v.mode = s->mode;
      v.gripper = s->gripper;
      v.homed = s->homed;
      v.moving = s->moving;
      v.tracking = s->tracking;
      v.trajectory_id = std::string(bus::str(s->trajectory_id));
      v.fault_text = std::string(bus::str(s->fault_text));
      v.stop_code = std::string(bus::str(s->stop_code));
      v.stamp_ns = s->header.stamp_ns;
      v.received = Clock::now();
    }
  }
}

RobotView Links::robot(const std::string& robot_id) {
  take_states();
  auto it = robots_.find(robot_id);
  return it != robots_.end() ? it->second : RobotView{};
}

bool Links::wait_robot(const std::string& robot_id,
                       const std::function<bool(const RobotView&)>& pred,
                       std::chrono::milliseconds timeout, const Control& control) {
  const auto deadline = Clock::now() + timeout;
  for (;;) {
    const RobotView v = robot(robot_id);
    if (v.known && pred(v)) {
      return true;
    }
    if (Clock::now() >= deadline || control.interrupted()) {
      return false;
    }
    (void)state_reader_.wait_for_data(kPoll);
  }
}

Result<MotionOutcome> Links::move(cell_motion_MotionRequest& request, const Control& control,
                                  std::chrono::milliseconds timeout,
                                  const std::function<void(double)>& on_progress,
                                  const std::function<std::string()>& abandon) {
  const std::string robot_id(bus::str(request.robot_id));
  const std::string motion_id(bus::str(request.motion_id));
  auto seq = motions_.send(request, 5000ms);
  if (!seq) {
    return Error{Errc::kProtocol,
                 fmt::format("motion '{}': {}", motion_id, seq.error().message)};
  }
  const auto deadline = Clock::now() + timeout;
  bool stop_sent = false;
  for (;;) {
    auto batch = motions_.replies().take_copies(32);
    if (batch) {
      for (const auto& s : *batch) {
        if (!bus::same_request(s->request_id, motions_.client_id(), *seq)) {
          continue;
        }
        if (s->state == cell_motion_MOTION_RUNNING && on_progress) {
          on_progress(s->progress);
        }
        if (terminal(s->state)) {
          MotionOutcome o = outcome_of(s.get());
          o.interrupted = stop_sent ? Interrupt::kCancel : Interrupt::kNone;
          // Failed, or refused before it started (the motion service will not plan for a
          // robot in fault): either way the robot's fault, and the job pauses for it.
          if (o.state == cell_motion_MOTION_FAILED || o.state == cell_motion_MOTION_REFUSED) {
            const RobotView v = robot(robot_id);
            o.robot_fault = v.mode == cell_robot_MODE_FAULT ||
                            v.mode == cell_robot_MODE_STOPPED;
          }
          return o;
        }
      }
    }
    take_states();
    if (control.cancel.load() && !stop_sent) {
      // Cancel: stop the robot now; the motion then ends (failed) and we report that.
      cell_motion_MotionRequest stop{};
      const std::string stop_id = motion_id + ".stop";
      stop.motion_id = bus::borrow(stop_id);
      stop.robot_id = bus::borrow(robot_id);
      stop.kind = cell_motion_MOTION_STOP;
      (void)motions_.send(stop, 1000ms);
      stop_sent = true;
    }
    if (control.stop.load()) {
      MotionOutcome o;
      o.state = cell_motion_MOTION_RUNNING;
      o.interrupted = Interrupt::kStop;
      return o;
    }
    if (abandon) {
      if (std::string why = abandon(); !why.empty()) {
        MotionOutcome o;
        o.state = cell_motion_MOTION_FAILED;
        o.unseen = true;
        o.reason = fmt::format("motion '{}': outcome not seen ({})", motion_id, why);
        return o;
      }
    }
    if (Clock::now() >= deadline) {
      return Error{Errc::kProtocol, fmt::format("motion '{}' did not end within {} s", motion_id,
                                                static_cast<double>(timeout.count()) / 1000.0)};
    }
    (void)motions_.replies().wait_for_data(kPoll);
  }
}

Result<std::uint64_t> Links::send_motion(cell_motion_MotionRequest& request) {
  auto seq = motions_.send(request, 5000ms);
  if (!seq) {
    return Error{Errc::kProtocol, fmt::format("motion '{}': {}", bus::str(request.motion_id),
                                              seq.error().message)};
  }
  return seq;
}

std::optional<Links::MotionUpdate> Links::poll_motion(std::uint64_t seq) {
  std::optional<MotionUpdate> latest;
  auto batch = motions_.replies().take_copies(32);
  if (!batch) {
    return latest;
  }
  for (const auto& s : *batch) {
    if (!bus::same_request(s->request_id, motions_.client_id(), seq)) {
      continue;
    }
    MotionUpdate u;
    u.state = s->state;
    u.progress = s->progress;
    u.duration_s = s->duration_s;
    u.reason = std::string(bus::str(s->reason));
    u.error_code = std::string(bus::str(s->error_code));
    u.terminal = terminal(s->state);
    if (s->meet_stamp_ns != 0) {
      if (auto meet = geometry::pose_from_idl(s->meet_target); meet) {
        u.meet_target = *meet;
        u.meet_stamp_ns = s->meet_stamp_ns;
        u.meet_ramp_mm = std::isfinite(s->meet_ramp_mm) ? std::max(0.0, s->meet_ramp_mm) : 0.0;
      }
    }
    if (!latest || !latest->terminal) {
      latest = u;
    }
  }
  return latest;
}

std::optional<MotionOutcome> Links::motion_status(const std::string& motion_id,
                                                  std::chrono::milliseconds wait) {
  const auto deadline = Clock::now() + wait;
  for (;;) {
    auto batch = status_reader_.take_copies(64);
    if (batch) {
      for (const auto& s : *batch) {
        statuses_[std::string(bus::str(s->motion_id))] = outcome_of(s.get());
      }
    }
    auto it = statuses_.find(motion_id);
    if (it != statuses_.end() && terminal(it->second.state)) {
      return it->second;
    }
    if (Clock::now() >= deadline) {
      if (it != statuses_.end()) {
        return it->second;
      }
      return std::nullopt;
    }
    (void)status_reader_.wait_for_data(kPoll);
  }
}

Frame to_frame(const cell_vision_Detections& d) {
  Frame f;
  f.exposure_ns = d.header.stamp_ns;
  f.belt_count = d.belt_count;
  f.image_sequence = d.image_sequence;
  f.error = std::string(bus::str(d.error));
  f.calibration = std::string(bus::str(d.calibration));
  f.processing_ms = d.processing_ms;
  f.received = Clock::now();
  f.received_ns = wall_time_ns();
  for (const auto& item : bus::span(d.items)) {
    Located l;
    l.class_name = std::string(bus::str(item.class_name));
    l.x_mm = item.base_pose.x_mm;
    l.y_mm = item.base_pose.y_mm;
    l.yaw_rad = item.base_pose.rz_rad;
    l.has_pose = item.has_base_pose;
    l.quality = item.quality;
    l.grip = item.grip;
    l.grip_style = item.grip_style;
    l.grip_detail = std::string(bus::str(item.grip_detail));
    l.touching = item.touching;
    for (const auto& g : bus::span(item.clear_grasps)) {
      l.grasps.push_back({g.style, std::string(bus::str(g.name)), g.base_pose.x_mm,
                          g.base_pose.y_mm, g.base_pose.rz_rad});
    }
    f.parts.push_back(std::move(l));
  }
  return f;
}

std::vector<Frame> Links::take_frames(const std::string& camera_id) {
  std::vector<Frame> out;
  auto batch = images_.replies().take_copies(16);
  if (batch) {
    for (const auto& d : *batch) {
      if (bus::str(d->camera_id) == camera_id) {
        out.push_back(to_frame(*d));
      }
    }
  }
  return out;
}

bool Links::wait_frames(std::chrono::milliseconds timeout) {
  return images_.replies().wait_for_data(timeout);
}

Result<Frame> Links::locate(const std::string& camera_id, cell_vision_TriggerKind trigger,
                            std::chrono::milliseconds timeout, const Control& control) {
  cell_vision_ImageRequest request{};
  request.camera_id = bus::borrow(camera_id);
  request.trigger = trigger;
  request.with_truth = false;
  auto seq = images_.send(request, 3000ms);
  if (!seq) {
    return Error{Errc::kProtocol,
                 fmt::format("camera '{}': {}", camera_id, seq.error().message)};
  }
  const auto deadline = Clock::now() + timeout;
  for (;;) {
    auto batch = images_.replies().take_copies(16);
    if (batch) {
      for (const auto& d : *batch) {
        if (!bus::same_request(d->request_id, images_.client_id(), *seq)) {
          continue;
        }
        return to_frame(*d);
      }
    }
    take_states();
    if (control.interrupted()) {
      return Error{Errc::kNotReady, "interrupted while waiting for the camera"};
    }
    if (Clock::now() >= deadline) {
      return Error{Errc::kProtocol,
                   fmt::format("no detections of camera '{}' within {:.1f} s (camera or vision "
                               "service not answering)",
                               camera_id, static_cast<double>(timeout.count()) / 1000.0)};
    }
    (void)images_.replies().wait_for_data(kPoll);
  }
}

void Links::take_belts() {
  auto batch = belt_reader_.take_copies(64);
  if (!batch) {
    return;
  }
  for (const auto& b : *batch) {
    BeltReading& r = belts_[std::string(bus::str(b->belt_id))];
    r.count = b->encoder_count;
    r.speed_mm_per_s = b->speed_mm_per_s;
    r.stamp_ns = b->header.stamp_ns;
    r.received = Clock::now();
  }
}

std::optional<BeltReading> Links::belt(const std::string& belt_id) {
  take_belts();
  auto it = belts_.find(belt_id);
  if (it == belts_.end()) {
    return std::nullopt;
  }
  return it->second;
}

Status Links::alter(const std::string& robot_id, const std::string& trajectory_id,
                    std::uint64_t cycle, const Eigen::Vector3d& translation_mm,
                    const Eigen::Vector3d& velocity_mm_per_s, std::int64_t stamp_ns,
                    double extrapolate_s) {
  cell_motion_AlterCorrection c{};
  c.robot_id = bus::borrow(robot_id);
  c.header.stamp_ns = stamp_ns > 0 ? stamp_ns : wall_time_ns();
  c.trajectory_id = bus::borrow(trajectory_id);
  c.cycle = cycle;
  c.translation_mm = {translation_mm.x(), translation_mm.y(), translation_mm.z()};
  c.rotation_rad = {0, 0, 0};
  c.velocity_mm_per_s = {velocity_mm_per_s.x(), velocity_mm_per_s.y(), velocity_mm_per_s.z()};
  c.extrapolate_s = extrapolate_s;
  return alter_writer_.write(c);
}

Status Links::command(const std::string& robot_id, cell_robot_RobotCommandKind kind,
                      std::chrono::milliseconds timeout) {
  cell_robot_RobotCommand c{};
  c.robot_id = bus::borrow(robot_id);
  c.kind = kind;
  return command(c, timeout);
}

Status Links::command(const std::string& robot_id, cell_robot_RobotCommandKind kind,
                      std::chrono::milliseconds timeout, const std::function<void()>& between) {
  cell_robot_RobotCommand c{};
  c.robot_id = bus::borrow(robot_id);
  c.kind = kind;
  const auto deadline = Clock::now() + timeout;
  auto seq = commands_.send(c, timeout);
  if (!seq) {
    return Error{Errc::kProtocol,
                 fmt::format("robot '{}' command: {}", robot_id, seq.error().message)};
  }
  for (;;) {
    // A deadline of now: take what has arrived, never block (between() paces the loop).
    auto reply = commands_.wait_reply(*seq, Clock::now());
    if (reply) {
      return command_answer(robot_id, *reply);
    }
    if (reply.error().code != Errc::kTimeout || Clock::now() >= deadline) {
      return Error{Errc::kProtocol,
                   fmt::format("robot '{}' command: {}", robot_id, reply.error().message)};
    }
    between();
  }
}

Status Links::command_answer(const std::string& robot_id,
                             const bus::Owned<cell_robot_RobotCommandReply>& reply) {
  if (!reply->status.accepted) {
    return Error{Errc::kNotReady, fmt::format("robot '{}' refused the command: {}", robot_id,
                                              bus::str(reply->status.reason))};
  }
  return ok_status();
}

Status Links::command(cell_robot_RobotCommand& c, std::chrono::milliseconds timeout) {
  const std::string robot_id(bus::str(c.robot_id));
  auto reply = commands_.call(c, timeout);
  if (!reply) {
    return Error{Errc::kProtocol,
                 fmt::format("robot '{}' command: {}", robot_id, reply.error().message)};
  }
  return command_answer(robot_id, *reply);
}

}  // namespace cell::task_service
