#include "job_run.hpp"

#include <random>
#include <thread>

#include <fmt/format.h>

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"

namespace cell::task_service {

std::vector<std::string> split_lines(const std::string& text) {
  std::vector<std::string> out;
  std::size_t start = 0;
  while (start <= text.size()) {
    const std::size_t end = text.find('\n', start);
    std::string line = text.substr(start, end == std::string::npos ? std::string::npos
                                                                   : end - start);
    if (!line.empty()) {
      out.push_back(std::move(line));
    }
    if (end == std::string::npos) {
      break;
    }
    start = end + 1;
  }
  return out;
}

std::string fresh_tag(const char* what, int seq) {
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  return fmt::format("{}{}-{:06x}", what, seq, rng() & 0xFFFFFF);
}
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

Status read_progress(const nlohmann::json& progress,
                     std::vector<PartRecord>& parts,
                     std::map<std::string, std::uint32_t>& counters) {
  if (!progress.is_object()) {
    return Error{Errc::kInvalidArgument, "the progress is not a JSON object"};
  }
  std::vector<PartRecord> read_parts;
  std::map<std::string, std::uint32_t> read_counters;
  try {
    if (auto it = progress.find("_parts"); it != progress.end()) {
      for (const auto& p : *it) {
        read_parts.push_back(part_from_json(p));
      }
    }
    if (auto it = progress.find("_counters"); it != progress.end()) {
      for (const auto& [k, v] : it->items()) {
        read_counters[k] = v.get<std::uint32_t>();
      }
    }
  } catch (const nlohmann::json::exception& e) {
    return Error{Errc::kInvalidArgument, fmt::format("its parts or counters: {}", e.what())};
  }
  parts = std::move(read_parts);
  counters = std::move(read_counters);
  return Ok{};
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
  gateway_id_ = "gateway." + robot_.id();
  for (const auto& r : config_.robots) {
    if (r.id == robot_.id()) {
      gateway_id_ = r.gateway;
    }
  }
  // Parts and counters travel inside the journaled progress. The service read them once
  // before it resumed the job (TaskService::resume_from_journal) and failed a job whose
  // progress it could not read: this read succeeds.
  (void)read_progress(progress_, parts_, counters_);
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
  const RobotView first = links_.robot(robot_.id());
  const bool ours = first.mode == cell_robot_MODE_STOPPED && first.stop_code == "supervisor_lost";
  pause_reason_ =
      ours ? fmt::format("robot '{}': {}; resetting it once it is reachable", robot_.id(),
                         first.fault_text.empty() ? reason : first.fault_text)
           : fmt::format("robot '{}': {}; reset the robot to resume", robot_.id(), reason);
  log::warn("job", "paused for the robot", {{"job", job_id_}, {"reason", pause_reason_}});
  report(step_text_, fraction_);
  auto next_reset = Clock::now();
  for (;;) {
    // Stopped by its gateway because this service was lost (a partition, a slow restart): not
    // an operator's decision, so the job resets it itself as soon as the gateway answers.
    const RobotView v = links_.robot(robot_.id());
    if (v.mode == cell_robot_MODE_STOPPED && v.stop_code == "supervisor_lost" &&
        Clock::now() >= next_reset) {
      next_reset = Clock::now() + 1s;
      if (interrupt_of(control_) != Interrupt::kNone) {
        break;
      }
      (void)wait_for_peers({gateway_id_});
      const Status s = links_.command(robot_.id(), cell_robot_CMD_RESET, 3000ms);
      log::info("job", s ? "reset the robot its gateway stopped when it lost this service"
                         : "reset of the robot failed; trying again",
                {{"job", job_id_}, {"robot", robot_.id()},
                 {"error", s ? std::string() : s.error().message}});
    }
    const bool ok = links_.wait_robot(
        robot_.id(),
        [](const RobotView& r) {
          return r.mode != cell_robot_MODE_FAULT && r.mode != cell_robot_MODE_STOPPED &&
                 r.mode != cell_robot_MODE_UNCONFIGURED;
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

std::vector<std::string> JobRun::motion_peers() const {
  return {gateway_id_, config_.motion_service};
}

std::vector<std::string> JobRun::locate_peers(const std::string& camera_id) const {
  std::string camera = "camera." + camera_id;
  for (const auto& c : config_.cameras) {
    if (c.id == camera_id) {
      camera = c.service;
    }
  }
  return {camera, config_.vision_service};
}

Interrupt JobRun::wait_for_peers(const std::vector<std::string>& ids) {
  Peers& peers = links_.peers();
  peers.refresh();
  std::string missing = peers.missing(ids);
  if (missing.empty()) {
    return interrupt_of(control_);
  }
  const bool was_paused = paused_;
  const std::string was_reason = pause_reason_;
  const auto since = Clock::now();
  paused_ = true;
  pause_reason_ = "waiting for " + missing;
  log::warn("job", "paused: a service the job needs is lost",
            {{"job", job_id_}, {"missing", missing}});
  report(step_text_, fraction_);
  while (!missing.empty() && !control_.interrupted()) {
    std::this_thread::sleep_for(100ms);
    peers.refresh();
    const std::string now_missing = peers.missing(ids);
    if (!now_missing.empty() && now_missing != missing) {
      pause_reason_ = "waiting for " + now_missing;
      report(step_text_, fraction_);
    }
    missing = now_missing;
  }
  paused_ = was_paused;
  pause_reason_ = was_reason;
  log::info("job", "resumed: the services it needs are back",
            {{"job", job_id_},
             {"after_s", fmt::format("{:.1f}", std::chrono::duration<double>(Clock::now() - since)
                                                   .count())}});
  report(step_text_, fraction_);
  return interrupt_of(control_);
}

bool JobRun::peers_changed(const std::vector<std::string>& ids,
                           const std::vector<std::uint64_t>& generations) {
  Peers& peers = links_.peers();
  peers.refresh(true);
  return peers.generations(ids) != generations || !peers.missing(ids).empty();
}

MotionOutcome JobRun::recover_unseen(const std::string& motion_id, const std::string& why) {
  log::warn("job", "the outcome of a motion was not seen: verifying",
            {{"job", job_id_}, {"motion", motion_id}, {"why", why}});
  MotionOutcome o;
  o.state = cell_motion_MOTION_FAILED;
  o.unseen = true;
  o.reason = why;
  const auto timeout = std::chrono::milliseconds(
      static_cast<std::int64_t>(config_.motion_timeout_s * 1000.0));
  for (;;) {
    if (wait_for_peers(motion_peers()) != Interrupt::kNone) {
      o.interrupted = interrupt_of(control_);
      return o;
    }
    // The gateway may still be running the trajectory it was given: let it finish.
    const auto gens = links_.peers().generations(motion_peers());
    (void)links_.wait_robot(robot_.id(),
                            [](const RobotView& v) {
                              return !v.moving && v.mode != cell_robot_MODE_HOMING;
                            },
                            timeout, control_);
    if (control_.interrupted()) {
      o.interrupted = interrupt_of(control_);
      return o;
    }
    if (!peers_changed(motion_peers(), gens)) {
      break;
    }
  }
  // A motion service that lived through it still knows (its status is transient-local).
  if (auto status = links_.motion_status(motion_id, 1500ms);
      status && status->state == cell_motion_MOTION_DONE) {
    log::info("job", "the motion had completed after all", {{"job", job_id_},
                                                             {"motion", motion_id}});
    return *status;
  }
  const RobotView v = links_.robot(robot_.id());
  o.robot_fault = v.mode == cell_robot_MODE_FAULT || v.mode == cell_robot_MODE_STOPPED;
  return o;
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
  const std::string motion_id(bus::str(request.motion_id));
  const std::vector<std::string> needed = motion_peers();
  // Not-ready refusals waited out before the job pauses for the robot: 10 x 0.5 s, past the
  // motion service's state_timeout_s (1 s) and a gateway's restart (~0.5 s).
  constexpr int kNotReadyRetries = 10;
  int not_ready_refusals = 0;
  for (int attempt = 0;; ++attempt) {
    if (const Interrupt i = wait_for_peers(needed); i != Interrupt::kNone) {
      MotionOutcome o;
      o.state = cell_motion_MOTION_RUNNING;
      o.interrupted = i;
      return o;
    }
    Peers& peers = links_.peers();
    const std::vector<std::uint64_t> gens = peers.generations(needed);
    const auto abandon = [&]() -> std::string {
      peers.refresh();
      if (peers.generations(needed) != gens) {
        return "the motion service or the gateway was lost or restarted";
      }
      return peers.missing(needed);
    };
    auto o = links_.move(request, control_, timeout, {}, abandon);
    if (o && o->unseen) {
      return recover_unseen(motion_id, o->reason);
    }
    // A failure (no reader for the request, a motion service that lost the robot's state, a
    // timeout) while a service it needs went away is not the motion's verdict either.
    if ((!o || (o->state == cell_motion_MOTION_FAILED && !o->robot_fault)) &&
        peers_changed(needed, gens)) {
      return recover_unseen(motion_id, o ? o->reason : o.error().message);
    }
    // The motion service gave up watching (it lost the robot's state, e.g. across a network
    // partition just healed): that says nothing of what the arm did. Verify, never assume.
    if (o && o->state == cell_motion_MOTION_FAILED && !o->robot_fault &&
        (o->reason.find("lost the state of robot") != std::string::npos ||
         o->reason.find("did not accept the trajectory") != std::string::npos)) {
      return recover_unseen(motion_id, o->reason);
    }
    // Planned from a state older than the robot (its gateway just restarted and came back
    // elsewhere): the gateway refuses the start; plan again from the fresh state.
    if (o && o->state == cell_motion_MOTION_FAILED &&
        o->reason.find("trajectory starts with") != std::string::npos && attempt < 5) {
      log::info("job", "planned from a stale robot state: planning again",
                {{"job", job_id_}, {"why", o->reason}});
      std::this_thread::sleep_for(500ms);
      continue;
    }
    // Busy: refused by the motion service (a motion of ours from before a restart still runs)
    // or by the gateway (a restarted motion service re-ran a request it had taken before).
    const bool busy = o && ((o->state == cell_motion_MOTION_REFUSED &&
                             o->reason.find("is busy with motion") != std::string::npos) ||
                            (o->state == cell_motion_MOTION_FAILED &&
                             o->reason.find("is busy with trajectory") != std::string::npos));
    // Refused because the robot was not ready by the motion service's view (a fault, its
    // state lost or stale) while this service's view of the robot is fine: the two views
    // disagree for a moment after a gateway restarts (the motion service still held the dead
    // gateway's last state, a fault, when the successor's first states reached this service).
    // Not the part's verdict: an "unreachable" here failed every part left in a CI run's job.
    // Wait for the views to agree and send again; past that the job pauses for the robot.
    if (o && !busy && !o->robot_fault && o->state == cell_motion_MOTION_REFUSED &&
        o->error_code == "not_ready") {
      if (not_ready_refusals++ < kNotReadyRetries) {
        log::info("job", "refused as not ready: waiting for the robot's state, then again",
                  {{"job", job_id_}, {"why", o->reason}});
        if (const Interrupt i = sleep(0.5); i != Interrupt::kNone) {
          o->interrupted = i;
          return o;
        }
        --attempt;  // not one of the busy retries
        continue;
      }
      o->robot_fault = true;  // the job pauses for the robot instead of skipping the part
      return o;
    }
    if (!busy || attempt == 5) {
      return o;
    }
    // Busy with this very motion: a motion service restarted while its trajectory ran took the
    // request again, and the gateway still runs (or just ran) the first run's trajectory (the
    // robot's state names it "<motion id>#<n>"). That run's outcome is the motion's, and
    // nobody watches it now: let it finish and verify what it did, as for any unseen outcome.
    // Sending the request again would do it twice (a second pick from above a part already
    // held, and the part reported unreachable while it is in the gripper).
    if (links_.robot(robot_id).trajectory_id.rfind(motion_id + "#", 0) == 0) {
      return recover_unseen(motion_id, o->reason);
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
    if (auto r = interrupted_result(wait_for_peers(motion_peers())); r) {
      return r;
    }
    const auto gens = links_.peers().generations(motion_peers());
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
    if (peers_changed(motion_peers(), gens)) {
      continue;  // the gateway went away meanwhile: wait for it, then look again
    }
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
      // Homing takes a while: a gateway restarted meanwhile comes back unhomed (home again).
      Peers& peers = links_.peers();
      const auto home_gens = peers.generations(motion_peers());
      bool restarted = false;
      const bool homed = links_.wait_robot(
          robot_.id(),
          [&](const RobotView& r) {
            peers.refresh();
            restarted = peers.generations(motion_peers()) != home_gens;
            return restarted || (r.homed && r.mode == cell_robot_MODE_IDLE);
          },
          180s, control_);
      if (auto r = interrupted_result(interrupt_of(control_)); r) {
        return r;
      }
      if (restarted) {
        continue;
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
