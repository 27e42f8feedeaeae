#include "job_run.hpp"

#include <thread>

#include <fmt/format.h>

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"

namespace cell::task_service {
namespace {

using namespace std::chrono_literals;

}  // namespace

nlohmann::json to_json(const PartRecord& p) {
  return nlohmann::json{{"index", p.index},
                        {"class", p.class_name},
                        {"picked", {p.picked_x_mm, p.picked_y_mm, p.picked_yaw_rad}},
                        {"placed", {p.placed_x_mm, p.placed_y_mm, p.placed_yaw_rad}},
                        {"outcome", static_cast<int>(p.outcome)},
                        {"detail", p.detail}};
}

PartRecord part_from_json(const nlohmann::json& j) {
  PartRecord p;
  p.index = j.value("index", 0U);
  p.class_name = j.value("class", std::string());
  const auto picked = j.value("picked", std::vector<double>{0, 0, 0});
  const auto placed = j.value("placed", std::vector<double>{0, 0, 0});
  if (picked.size() == 3) {
    p.picked_x_mm = picked[0];
    p.picked_y_mm = picked[1];
    p.picked_yaw_rad = picked[2];
  }
  if (placed.size() == 3) {
    p.placed_x_mm = placed[0];
    p.placed_y_mm = placed[1];
    p.placed_yaw_rad = placed[2];
  }
  p.outcome = static_cast<cell_task_PartOutcome>(j.value("outcome", 0));
  p.detail = j.value("detail", std::string());
  return p;
}

JobRun::JobRun(std::string job_id, const task::JobSpec& spec, const kinematics::RobotModel& robot,
               const TaskConfig& config, const world::Catalogue& catalogue, Links& links,
               Control& control, nlohmann::json progress, Hooks hooks)
    : job_id_(std::move(job_id)),
      spec_(spec),
      robot_(robot),
      config_(config),
      catalogue_(catalogue),
      links_(links),
      control_(control),
      progress_(progress.is_object() ? std::move(progress) : nlohmann::json::object()),
      hooks_(std::move(hooks)) {
  // Parts and counters travel inside the journaled progress.
  if (auto it = progress_.find("_parts"); it != progress_.end() && it->is_array()) {
    for (const auto& p : *it) {
      parts_.push_back(part_from_json(p));
    }
  }
  if (auto it = progress_.find("_counters"); it != progress_.end() && it->is_object()) {
    for (const auto& [k, v] : it->items()) {
      counters_[k] = v.get<std::uint32_t>();
    }
  }
}

Status JobRun::step(const std::string& name, const nlohmann::json& detail) {
  nlohmann::json parts = nlohmann::json::array();
  for (const auto& p : parts_) {
    parts.push_back(to_json(p));
  }
  progress_["_parts"] = std::move(parts);
  progress_["_counters"] = counters_;
  step_text_ = name;
  if (hooks_.journal) {
    CELL_TRY(hooks_.journal(name, detail, progress_));
  }
  if (hooks_.publish) {
    hooks_.publish(*this);
  }
  return ok_status();
}

void JobRun::report(const std::string& step_text, double fraction) {
  step_text_ = step_text;
  fraction_ = std::clamp(fraction, 0.0, 1.0);
  if (hooks_.publish) {
    hooks_.publish(*this);
  }
}

Interrupt JobRun::hold_if_paused() {
  if (!control_.pause.load()) {
    return interrupt_of(control_);
  }
  paused_ = true;
  pause_reason_ = "paused by an operator";
  report(step_text_, fraction_);
  while (control_.pause.load() && !control_.interrupted()) {
    std::this_thread::sleep_for(20ms);
  }
  paused_ = false;
  pause_reason_.clear();
  report(step_text_, fraction_);
  return interrupt_of(control_);
}

Interrupt JobRun::pause_for_robot(const std::string& reason) {
  paused_ = true;
  pause_reason_ = fmt::format("robot '{}': {}; reset the robot to resume", robot_.id(), reason);
  log::warn("job", "paused for the robot", {{"job", job_id_}, {"reason", pause_reason_}});
  report(step_text_, fraction_);
  for (;;) {
    const bool ok = links_.wait_robot(
        robot_.id(),
        [](const RobotView& v) {
          return v.mode != cell_robot_MODE_FAULT && v.mode != cell_robot_MODE_STOPPED &&
                 v.mode != cell_robot_MODE_UNCONFIGURED;
        },
        200ms, control_);
    if (control_.interrupted()) {
      break;
    }
    if (ok) {
      break;
    }
  }
  paused_ = false;
  pause_reason_.clear();
  log::info("job", "resumed: the robot was reset", {{"job", job_id_}});
  report(step_text_, fraction_);
  return interrupt_of(control_);
}

Interrupt JobRun::sleep(double seconds) {
  const auto until = Clock::now() + std::chrono::duration<double>(seconds);
  while (Clock::now() < until) {
    if (control_.interrupted()) {
      return interrupt_of(control_);
    }
    std::this_thread::sleep_for(std::min<Clock::duration>(
        std::chrono::duration_cast<Clock::duration>(until - Clock::now()), 20ms));
  }
  return interrupt_of(control_);
}

Result<MotionOutcome> JobRun::move(cell_motion_MotionRequest& request,
                                   const std::string& step_text) {
  const std::string robot_id = robot_.id();
  request.robot_id = bus::borrow(robot_id);
  report(step_text, fraction_);
  const auto timeout = std::chrono::milliseconds(
      static_cast<std::int64_t>(config_.motion_timeout_s * 1000.0));
  // Refused as busy: a motion this service sent before it was restarted still runs (or was
  // just accepted). Wait for the robot to finish it, then send again.
  for (int attempt = 0;; ++attempt) {
    auto o = links_.move(request, control_, timeout, {});
    if (!o || o->state != cell_motion_MOTION_REFUSED ||
        o->reason.find("is busy with motion") == std::string::npos || attempt == 5) {
      return o;
    }
    log::info("job", "robot busy with an earlier motion: waiting for it",
              {{"job", job_id_}, {"why", o->reason}});
    std::this_thread::sleep_for(200ms);
    (void)links_.wait_robot(robot_id, [](const RobotView& v) { return !v.moving; }, timeout,
                            control_);
    if (control_.interrupted()) {
      return o;
    }
  }
}

std::optional<ExecResult> interrupted_result(Interrupt i) {
  if (i == Interrupt::kCancel) {
    return ExecResult::cancelled();
  }
  if (i == Interrupt::kStop) {
    return ExecResult::stopped();
  }
  return std::nullopt;
}

/// A motion the task service sent before it restarted may still run: wait for the robot to
/// rest (and to be out of a fault) before anything new is sent.
std::optional<ExecResult> JobRun::ready_robot() {
  for (;;) {
    const bool idle = links_.wait_robot(
        robot_.id(),
        [](const RobotView& v) {
          return !v.moving && v.mode == cell_robot_MODE_IDLE && v.homed;
        },
        std::chrono::milliseconds(
            static_cast<std::int64_t>(config_.robot_state_timeout_s * 1000)),
        control_);
    if (auto r = interrupted_result(interrupt_of(control_)); r) {
      return r;
    }
    if (idle) {
      return std::nullopt;
    }
    const RobotView v = links_.robot(robot_.id());
    if (!v.known) {
      return ExecResult::failed(fmt::format("no state from robot '{}' within {} s",
                                            robot_.id(),
                                            config_.robot_state_timeout_s));
    }
    if (v.mode == cell_robot_MODE_FAULT || v.mode == cell_robot_MODE_STOPPED) {
      if (auto r = interrupted_result(pause_for_robot(v.fault_text.empty() ? "stopped"
                                                                          : v.fault_text));
          r) {
        return r;
      }
    } else if (!v.homed && !v.moving && v.mode != cell_robot_MODE_HOMING) {
      // The thesis's first menu entry, done by the job: find home, then go on.
      report("homing the robot", 0.0);
      if (auto s = links_.command(robot_.id(), cell_robot_CMD_HOME, 5000ms); !s) {
        return ExecResult::failed(fmt::format("robot '{}' is not homed and homing failed: {}",
                                              robot_.id(), s.error().message));
      }
      const bool homed = links_.wait_robot(
          robot_.id(),
          [](const RobotView& r) { return r.homed && r.mode == cell_robot_MODE_IDLE; }, 180s,
          control_);
      if (auto r = interrupted_result(interrupt_of(control_)); r) {
        return r;
      }
      if (!homed) {
        return ExecResult::failed(fmt::format("robot '{}' did not finish homing in 180 s",
                                              robot_.id()));
      }
      if (auto s = step("homed"); !s) {
        return ExecResult::failed(s.error().message);
      }
    }
  }
}


}  // namespace cell::task_service
