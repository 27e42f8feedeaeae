#include "cell/teach/bus_runner.hpp"

#include <vector>

#include <fmt/format.h>

#include "cell/bus/view.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/motion/wire.hpp"

namespace cell::teach {
namespace {

using Clock = std::chrono::steady_clock;
constexpr dds_attach_t kReply = 1;
constexpr dds_attach_t kWake = 2;
constexpr dds_attach_t kState = 3;
constexpr auto kGripperTimeout = std::chrono::seconds(10);

bool terminal(cell_motion_MotionState s) {
  return s == cell_motion_MOTION_REFUSED || s == cell_motion_MOTION_DONE ||
         s == cell_motion_MOTION_FAILED || s == cell_motion_MOTION_PREVIEW;
}

Errc refusal_code(std::string_view code) {
  if (code == "out_of_range") {
    return Errc::kOutOfRange;
  }
  if (code == "not_ready") {
    return Errc::kNotReady;
  }
  return Errc::kInvalidArgument;
}

}  // namespace

BusRunner::BusRunner(const bus::Participant& participant, std::string robot_id,
                     BusRunnerOptions options)
    : participant_(participant),
      robot_id_(std::move(robot_id)),
      options_(std::move(options)),
      motion_(std::make_unique<bus::Requester<cell_motion_MotionRequest, cell_motion_MotionStatus>>(
          participant, bus::topics::kMotionRequest, bus::topics::kMotionStatus,
          bus::make_client_id(options_.client_name))),
      robot_(std::make_unique<bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply>>(
          participant, bus::topics::kRobotCommand, bus::topics::kRobotCommandReply,
          bus::make_client_id(options_.client_name))),
      wake_(participant) {}

BusRunner::~BusRunner() = default;

void BusRunner::cancel() noexcept {
  cancelled_ = true;
  wake_.trigger();
}

void BusRunner::reset_cancel() noexcept {
  wake_.reset();
  stop_sent_ = false;
  cancelled_ = false;
}

Result<StepOutcome> BusRunner::run(const Action& action) {
  if (cancelled_) {
    return Error{Errc::kNotReady, "cancelled"};
  }
  switch (action.kind) {
    case Action::Kind::kMove:
      return move(action);
    case Action::Kind::kGripper:
      return gripper(action);
    case Action::Kind::kWait:
      return wait(action);
    case Action::Kind::kNone:
      break;
  }
  return StepOutcome{};
}

Result<StepOutcome> BusRunner::move(const Action& action) {
  const std::string motion_id =
      fmt::format("{}-{}-{}", options_.client_name, wall_time_ns(), ++counter_);
  std::vector<double> joints(action.joints.data(), action.joints.data() + action.joints.size());
  cell_motion_MotionRequest request{};
  request.motion_id = bus::borrow(motion_id);
  request.robot_id = bus::borrow(robot_id_);
  request.speed_scale = action.speed_scale;
  request.preview_only = options_.preview;
  request.alter_world_frame = true;
  if (action.move == MoveKind::kLine) {
    request.kind = cell_motion_MOTION_MOVE_LINEAR;
    request.target = motion::to_idl(action.base_T_tool);
  } else {
    request.kind = cell_motion_MOTION_MOVE_JOINTS;
    bus::borrow(request.joints_rad_or_mm, joints);
  }
  auto seq = motion_->send(request, options_.match_timeout);
  if (!seq) {
    return Error{Errc::kTimeout,
                 fmt::format("{} (is the motion service running?)", seq.error().message)};
  }
  bus::WaitSet waitset(participant_);
  waitset.attach(motion_->replies().condition(), kReply);
  waitset.attach(wake_.get(), kWake);
  const auto sent = Clock::now();
  auto deadline = sent + options_.match_timeout;
  for (;;) {
    if (cancelled_ && !stop_sent_) {
      stop_sent_ = true;
      cell_motion_MotionRequest stop{};
      const std::string stop_id = motion_id + "-stop";
      stop.motion_id = bus::borrow(stop_id);
      stop.robot_id = bus::borrow(robot_id_);
      stop.kind = cell_motion_MOTION_STOP;
      (void)motion_->send(stop, options_.match_timeout);
      return Error{Errc::kNotReady, fmt::format("cancelled: motion '{}' stopped", motion_id)};
    }
    auto batch = motion_->replies().take_copies(32);
    if (!batch) {
      return std::move(batch).error();
    }
    for (auto& status : *batch) {
      const cell_motion_MotionStatus& s = status.get();
      if (!bus::same_request(s.request_id, motion_->client_id(), *seq)) {
        continue;
      }
      if (s.duration_s > 0.0) {
        deadline = std::max(deadline, sent + std::chrono::duration_cast<Clock::duration>(
                                                 std::chrono::duration<double>(s.duration_s)) +
                                          options_.move_margin);
      }
      if (!terminal(s.state)) {
        continue;
      }
      if (s.state == cell_motion_MOTION_REFUSED) {
        return Error{refusal_code(bus::str(s.error_code)),
                     fmt::format("refused: {}", bus::str(s.reason))};
      }
      if (s.state == cell_motion_MOTION_FAILED) {
        return Error{Errc::kProtocol, fmt::format("failed: {}", bus::str(s.reason))};
      }
      StepOutcome outcome;
      outcome.duration_s = s.duration_s;
      const auto q = bus::span(s.final_joints_rad_or_mm);
      if (!q.empty()) {
        kinematics::JointVector final_q(static_cast<Eigen::Index>(q.size()));
        for (std::size_t j = 0; j < q.size(); ++j) {
          final_q[static_cast<Eigen::Index>(j)] = q[j];
        }
        outcome.final_joints = final_q;
      }
      for (const auto& p : bus::span(s.path)) {
        if (auto pose = motion::from_idl(p)) {
          outcome.path.push_back(*pose);
        }
      }
      return outcome;
    }
    if (Clock::now() >= deadline) {
      cell_motion_MotionRequest stop{};
      const std::string stop_id = motion_id + "-stop";
      stop.motion_id = bus::borrow(stop_id);
      stop.robot_id = bus::borrow(robot_id_);
      stop.kind = cell_motion_MOTION_STOP;
      (void)motion_->send(stop, options_.match_timeout);
      return Error{Errc::kTimeout,
                   fmt::format("motion '{}' did not finish in time: the robot was stopped",
                               motion_id)};
    }
    (void)waitset.wait_until(deadline);
  }
}

Result<StepOutcome> BusRunner::gripper(const Action& action) {
  if (options_.preview) {
    return StepOutcome{};
  }
  const bool close = action.gripper == GripperAction::kClose;
  // The state reader first, so that no sample after the command can be missed.
  bus::Topic<cell_robot_RobotState> topic(participant_, bus::topics::kRobotState);
  bus::Reader<cell_robot_RobotState> states(participant_, topic, bus::topics::kRobotState);
  cell_robot_RobotCommand command{};
  command.robot_id = bus::borrow(robot_id_);
  command.kind = close ? cell_robot_CMD_GRIPPER_CLOSE : cell_robot_CMD_GRIPPER_OPEN;
  command.operator_id = bus::borrow(options_.operator_id);
  const auto start = Clock::now();
  auto reply = robot_->call(command, options_.match_timeout);
  if (!reply) {
    return Error{Errc::kTimeout, fmt::format("gripper {}: {} (is gateway.{} running?)",
                                             to_string(action.gripper), reply.error().message,
                                             robot_id_)};
  }
  if (!(*reply)->status.accepted) {
    return Error{refusal_code(bus::str((*reply)->status.error_code)),
                 fmt::format("gripper {} refused: {}", to_string(action.gripper),
                             bus::str((*reply)->status.reason))};
  }
  const cell_robot_GripperState want = close ? cell_robot_GRIPPER_CLOSED : cell_robot_GRIPPER_OPEN;
  bus::WaitSet waitset(participant_);
  waitset.attach(states.condition(), kState);
  waitset.attach(wake_.get(), kWake);
  const auto deadline = start + kGripperTimeout;
  for (;;) {
    if (cancelled_) {
      return Error{Errc::kNotReady, "cancelled"};
    }
    bool reached = false;
    auto taken = states.take_each([&](const cell_robot_RobotState& s, const dds_sample_info_t&) {
      if (bus::str(s.robot_id) == robot_id_ && s.gripper == want) {
        reached = true;
      }
    });
    if (!taken) {
      return std::move(taken).error();
    }
    if (reached) {
      StepOutcome outcome;
      outcome.duration_s = std::chrono::duration<double>(Clock::now() - start).count();
      return outcome;
    }
    if (Clock::now() >= deadline) {
      return Error{Errc::kTimeout, fmt::format("the gripper of '{}' did not {} within {} s",
                                               robot_id_, to_string(action.gripper),
                                               kGripperTimeout.count())};
    }
    (void)waitset.wait_until(deadline);
  }
}

Result<StepOutcome> BusRunner::wait(const Action& action) {
  StepOutcome outcome;
  outcome.duration_s = action.wait_s;
  if (options_.preview) {
    return outcome;
  }
  bus::WaitSet waitset(participant_);
  waitset.attach(wake_.get(), kWake);
  const auto deadline = Clock::now() + std::chrono::duration_cast<Clock::duration>(
                                           std::chrono::duration<double>(action.wait_s));
  while (Clock::now() < deadline) {
    if (cancelled_) {
      return Error{Errc::kNotReady, "cancelled"};
    }
    (void)waitset.wait_until(deadline);
  }
  return outcome;
}

}  // namespace cell::teach
