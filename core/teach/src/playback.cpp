#include "cell/teach/playback.hpp"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

namespace cell::teach {
namespace {

/// The last pose step strictly before `index`, or nullptr.
const PoseStep* pose_before(const Task& task, std::size_t index) {
  for (std::size_t i = index; i > 0; --i) {
    if (const auto* p = std::get_if<PoseStep>(&task.steps[i - 1])) {
      return p;
    }
  }
  return nullptr;
}

Result<Action> move_to(const Task& task, const kinematics::RobotModel& model, std::size_t index,
                       const PoseStep& pose, MoveKind move) {
  auto fk = model.forward(pose.joints);
  if (!fk) {
    return Error{fk.error().code, fmt::format("step {} (pose '{}'): {}", index + 1, pose.name,
                                              fk.error().message)};
  }
  Action a;
  a.kind = Action::Kind::kMove;
  a.step_index = index;
  a.pose_name = pose.name;
  a.move = move;
  a.joints = pose.joints;
  a.base_T_tool = *fk;
  a.speed_scale = pose.speed_scale > 0.0 ? pose.speed_scale : task.speed_scale;
  return a;
}

/// The actions of a run, in the order they are taken.
Result<std::vector<Action>> actions_of(const Task& task, const kinematics::RobotModel& model,
                                       const PlaybackOptions& options) {
  CELL_TRY(task.validate(model));
  const std::size_t to = options.to.value_or(task.steps.size());
  if (to > task.steps.size() || options.from > to) {
    return Error{Errc::kOutOfRange,
                 fmt::format("steps {}..{} are not a range of the task's {} steps",
                             options.from + 1, to, task.steps.size())};
  }
  if (options.speed_override != 0.0 &&
      !(options.speed_override > 0.0 && options.speed_override <= 1.0)) {
    return Error{Errc::kOutOfRange,
                 fmt::format("speed override must be in (0, 1], got {}", options.speed_override)};
  }
  std::vector<Action> actions;
  auto add = [&](std::size_t i) -> Status {
    auto a = action_for(task, model, i, options.direction);
    if (!a) {
      return std::move(a).error();
    }
    if (a->kind == Action::Kind::kMove && options.speed_override > 0.0) {
      a->speed_scale = options.speed_override;
    }
    actions.push_back(std::move(*a));
    return ok_status();
  };
  if (options.direction == Direction::kForward) {
    for (std::size_t i = options.from; i < to; ++i) {
      CELL_TRY(add(i));
    }
  } else {
    for (std::size_t i = to; i > options.from; --i) {
      CELL_TRY(add(i - 1));
    }
  }
  return actions;
}

}  // namespace

std::string Action::describe() const {
  switch (kind) {
    case Kind::kMove:
      return fmt::format("step {}: move ({}) to '{}'", step_index + 1, to_string(move),
                         pose_name);
    case Kind::kGripper:
      return fmt::format("step {}: gripper {}", step_index + 1, to_string(gripper));
    case Kind::kWait:
      return fmt::format("step {}: wait {:.2f} s", step_index + 1, wait_s);
    case Kind::kNone:
      break;
  }
  return fmt::format("step {}: nothing to do", step_index + 1);
}

Result<Action> action_for(const Task& task, const kinematics::RobotModel& model, std::size_t index,
                          Direction direction) {
  if (index >= task.steps.size()) {
    return Error{Errc::kOutOfRange, fmt::format("step {} is past the end: the task has {} steps",
                                                index + 1, task.steps.size())};
  }
  const Step& step = task.steps[index];
  Action a;
  a.step_index = index;
  if (const auto* p = std::get_if<PoseStep>(&step)) {
    if (direction == Direction::kForward) {
      return move_to(task, model, index, *p, p->move);
    }
    // Undo: back to the pose before, the way this step came (a line back along the line).
    if (const PoseStep* before = pose_before(task, index)) {
      auto back = move_to(task, model, index, *before, p->move);
      if (back) {
        back->step_index = index;
      }
      return back;
    }
    return a;  // the first pose: nothing to go back to
  }
  if (const auto* g = std::get_if<GripperStep>(&step)) {
    a.kind = Action::Kind::kGripper;
    a.gripper = g->action;
    if (direction == Direction::kBackward) {
      a.gripper = g->action == GripperAction::kOpen ? GripperAction::kClose : GripperAction::kOpen;
    }
    return a;
  }
  if (direction == Direction::kForward) {
    a.kind = Action::Kind::kWait;
    a.wait_s = std::get<WaitStep>(step).duration_s;
  }
  return a;
}

Result<Action> Cursor::peek_forward(const Task& task, const kinematics::RobotModel& model) const {
  if (position_ >= task.steps.size()) {
    return Error{Errc::kOutOfRange,
                 fmt::format("at the end of the task (after step {})", task.steps.size())};
  }
  return action_for(task, model, position_, Direction::kForward);
}

Result<Action> Cursor::peek_backward(const Task& task,
                                     const kinematics::RobotModel& model) const {
  if (position_ == 0) {
    return Error{Errc::kOutOfRange, "at the start of the task (before step 1)"};
  }
  if (position_ > task.steps.size()) {
    return Error{Errc::kOutOfRange, fmt::format("cursor {} is past the task's {} steps",
                                                position_, task.steps.size())};
  }
  return action_for(task, model, position_ - 1, Direction::kBackward);
}

void Cursor::clamp(const Task& task) noexcept {
  position_ = std::min(position_, task.steps.size());
}

Status Cursor::seek(const Task& task, std::size_t position) {
  if (position > task.steps.size()) {
    return Error{Errc::kOutOfRange, fmt::format("position {} is past the task's {} steps",
                                                position, task.steps.size())};
  }
  position_ = position;
  return ok_status();
}

std::string PlaybackReport::brief() const {
  if (ok()) {
    return fmt::format("{}/{} steps in {:.2f} s", steps_done, steps_total, duration_s);
  }
  if (failed_step) {
    return fmt::format("stopped at step {} after {}/{} steps: {}", *failed_step + 1, steps_done,
                       steps_total, message);
  }
  return fmt::format("stopped after {}/{} steps: {}", steps_done, steps_total, message);
}

Result<PlaybackReport> play(const Task& task, const kinematics::RobotModel& model,
                            StepRunner& runner, const PlaybackOptions& options,
                            const PlaybackObserver& observer) {
  auto actions = actions_of(task, model, options);
  if (!actions) {
    return std::move(actions).error();
  }
  PlaybackReport report;
  report.steps_total = actions->size();
  for (const Action& action : *actions) {
    if (observer) {
      observer(action, report.steps_done, report.steps_total);
    }
    if (action.kind != Action::Kind::kNone) {
      auto outcome = runner.run(action);
      if (!outcome) {
        report.failed_step = action.step_index;
        report.message = fmt::format("{}: {}", action.describe(), outcome.error().message);
        return report;
      }
      report.duration_s += outcome->duration_s;
      if (outcome->final_joints) {
        report.final_joints = outcome->final_joints;
      }
    }
    ++report.steps_done;
  }
  return report;
}

Result<std::vector<SimulatedStep>> simulate(const Task& task, const kinematics::RobotModel& model,
                                            const kinematics::JointVector& q_start,
                                            const PlaybackOptions& options,
                                            const motion::PlannerOptions& planner_options,
                                            double sample_period_s) {
  if (!(sample_period_s > 0.0)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("sample period must be > 0 s, got {}", sample_period_s)};
  }
  CELL_TRY(kinematics::check_joint_vector(model.joints(), q_start));
  auto actions = actions_of(task, model, options);
  if (!actions) {
    return std::move(actions).error();
  }
  const motion::Planner planner(model, planner_options);
  std::vector<SimulatedStep> out;
  kinematics::JointVector q = q_start;
  double t = 0.0;
  for (const Action& action : *actions) {
    SimulatedStep s;
    s.action = action;
    s.start_s = t;
    if (action.kind == Action::Kind::kMove) {
      auto plan = action.move == MoveKind::kLine
                      ? planner.move_linear(q, action.base_T_tool, action.speed_scale)
                      : planner.move_joints(q, action.joints, action.speed_scale);
      if (!plan) {
        return Error{plan.error().code,
                     fmt::format("{}: {}", action.describe(), plan.error().message)};
      }
      const double d = plan->trajectory.duration_s();
      const int n = std::max(1, static_cast<int>(std::ceil(d / sample_period_s)));
      s.samples.reserve(static_cast<std::size_t>(n) + 1);
      for (int i = 0; i <= n; ++i) {
        s.samples.push_back(plan->trajectory.sample(d * i / n).q);
      }
      s.duration_s = d;
      q = plan->trajectory.end();
    } else {
      s.samples.push_back(q);
      if (action.kind == Action::Kind::kGripper) {
        s.gripper = action.gripper;
        s.duration_s = planner_options.gripper_dwell_s;
      } else if (action.kind == Action::Kind::kWait) {
        s.duration_s = action.wait_s;
      }
    }
    t += s.duration_s;
    out.push_back(std::move(s));
  }
  return out;
}

}  // namespace cell::teach
