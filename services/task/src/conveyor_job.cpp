// conveyor_pick: the conveyor chapter's two-stage scheme (digest 002 §1.3, §2), fixing the two
// timing details its §2.4 names: the encoder count is the one latched at the exposure (not read
// after recognition), and tracking goes on while the gripper closes (ALTOFF after the grip).
//
// Stage 1: the photocell triggers the belt camera; the vision service locates the parts and
// tests their clear grips; the task predicts where each part will be when the robot can reach
// it and refuses it if that is outside the conveyor belt window (downstream limit checked
// before moving). Stage 2: the robot moves toward the part's position at exposure with ALTER
// enabled (non-cumulative, world frame) and the task sends, every alter_period_s, the total
// correction dir * mm_per_count * (count(t) - count at exposure) with its rate (the belt speed),
// so the destination moves with the part; at arrival the gripper closes while tracking, then
// ALTER off, depart, place.
#include <cmath>
#include <deque>
#include <limits>
#include <numbers>
#include <random>
#include <thread>

#include <fmt/format.h>

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/common/time.hpp"
#include "cell/geometry/idl_pose.hpp"
#include "cell/trajectory/alter.hpp"
#include "job_run.hpp"

namespace cell::task_service {
namespace {

using json = nlohmann::json;
using namespace std::chrono_literals;

struct Belt {
  double mm_per_count = 0.0;
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();  // base frame, unit
  Eigen::Vector3d nearest = Eigen::Vector3d::Zero();     // base frame [mm]
  std::string source;
};

std::string fresh(const JobRun& run, const char* what, int seq) {
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  return run.motion_id(fmt::format("{}{}-{:06x}", what, seq, rng() & 0xFFFFFF));
}

class ConveyorJob {
 public:
  explicit ConveyorJob(JobRun& run) : run_(run), spec_(*run.spec().conveyor()) {
    for (const auto& b : run.config().belts) {
      if (b.id == spec_.belt) {
        nominal_.mm_per_count = b.mm_per_count;
        nominal_.direction = b.direction;
        nominal_.nearest = b.nearest_mm;
        nominal_.source = "nominal (config/task.yaml)";
      }
    }
    for (const auto& c : run.config().cameras) {
      if (c.id == spec_.camera) {
        plane_z_ = c.working_plane_z_mm;
      }
    }
  }

  ExecResult run() {
    json& p = run_.progress();
    if (!p.contains("started_ns")) {
      p["started_ns"] = wall_time_ns();
      p["elapsed_s"] = 0.0;
      p["seq"] = 0;
      p["slot"] = 0;
      p["holding"] = nullptr;
    }
    elapsed_before_ = p["elapsed_s"].get<double>();
    resumed_at_ = Clock::now();
    if (auto r = stop_if_result(run_.ready_robot()); r) {
      return *r;
    }
    if (!p["holding"].is_null()) {
      if (auto r = finish_holding(); r) {
        return *r;
      }
    }
    // Stage 1 runs on its own: the belt camera exposes at every photocell edge (the encoder
    // count latched then) and the vision service locates each frame; every frame of the job
    // is queued here, so a part that passes while the robot is busy is still seen, and still
    // accounted for (taken, or counted by why not).
    (void)run_.links().take_frames(spec_.camera);  // frames from before the job: not ours
    // Every service a pick needs: while one is lost (a partition, a crash) the job pauses and
    // the parts that pass meanwhile are counted (outside the window when it resumes).
    std::vector<std::string> needed = run_.motion_peers();
    for (auto& id : run_.locate_peers(spec_.camera)) {
      needed.push_back(std::move(id));
    }
    bool ready = false;
    for (;;) {
      if (auto r = stop_if(run_.hold_if_paused()); r) {
        return *r;
      }
      if (auto r = stop_if(run_.wait_for_peers(needed)); r) {
        return *r;
      }
      if (finished()) {
        break;
      }
      const Belt belt = current_belt();
      if (!ready) {
        if (auto r = go_ready(belt); r) {
          return *r;
        }
        ready = true;
      }
      pump_eye();
      if (queue_.empty()) {
        run_.report(fmt::format("waiting for a part on {} ({} picked)", spec_.belt, picked()),
                    fraction());
        if (auto r = stop_if(run_.sleep(0.002)); r) {
          return *r;
        }
        continue;
      }
      const Queued next = std::move(queue_.front());
      queue_.pop_front();
      moved_ = false;
      if (auto r = take(next.part, next.frame, belt); r) {
        return *r;
      }
      ready = !moved_;
    }
    // Parts seen but not tried before the job's end: counted, so the causes add up.
    pump_eye();
    if (!queue_.empty()) {
      run_.count("not_tried_job_ended", static_cast<std::uint32_t>(queue_.size()));
      for (const Queued& q : queue_) {
        record(q.part, cell_task_PART_PENDING, "the job ended before it was tried");
      }
      queue_.clear();
    }
    p["elapsed_s"] = elapsed();
    if (auto s = run_.step("done"); !s) {
      return ExecResult::failed(s.error().message);
    }
    return ExecResult::done();
  }

 private:
  struct Queued {
    Located part;
    Frame frame;  ///< its frame's exposure, latched count and vision time (parts not copied)
  };

  double grasp_yaw(const Located& part, double z, int symmetry, const RobotView& now) const {
    if (symmetry <= 0 || !now.known) {
      return part.yaw_rad;
    }
    const auto& robot = run_.robot();
    const Eigen::Index roll = robot.dof() - 1;
    const auto& spec = robot.joints()[static_cast<std::size_t>(roll)];
    const double margin = std::numbers::pi / 2;
    const double step = 2 * std::numbers::pi / symmetry;
    double best = part.yaw_rad;
    double best_cost = std::numeric_limits<double>::infinity();
    for (int k = -symmetry; k <= symmetry; ++k) {
      const double yaw = part.yaw_rad + step * k;
      auto q = robot.inverse(task::grasp_pose(robot, part.x_mm, part.y_mm, z, yaw), now.q);
      if (!q) {
        continue;
      }
      const double r = (*q)[roll];
      const bool inside = r >= spec.lower + margin && r <= spec.upper - margin;
      const double cost = std::abs(r - now.q[roll]) + (inside ? 0.0 : 100.0);
      if (cost < best_cost) {
        best_cost = cost;
        best = yaw;
      }
    }
    return best;
  }

  /// The tracking motion's planned duration (the motion service's preview of `r`).
  Result<double> preview_duration(cell_motion_MotionRequest r) {
    const std::string id = std::string(bus::str(r.motion_id)) + "-preview";
    r.motion_id = bus::borrow(id);
    r.preview_only = true;
    auto sent = run_.links().send_motion(r);
    if (!sent) {
      return std::move(sent).error();
    }
    const auto until = Clock::now() + 1000ms;
    while (Clock::now() < until) {
      if (auto u = run_.links().poll_motion(*sent); u) {
        if (u->state == cell_motion_MOTION_PREVIEW) {
          return u->duration_s;
        }
        if (u->terminal) {
          return Error{Errc::kOutOfRange, fmt::format("cannot track the part: {}", u->reason)};
        }
      }
      pump_eye();
      std::this_thread::sleep_for(1ms);
    }
    return Error{Errc::kTimeout, "the motion service did not plan the track within 1 s"};
  }

  /// Takes the belt camera's new frames: each part located goes into the queue (downstream
  /// first); a frame that could not be processed or showed nothing is a locating failure.
  void pump_eye() {
    for (Frame& f : run_.links().take_frames(spec_.camera)) {
      if (!f.error.empty()) {
        run_.count("locate_failed");
        (void)run_.step("frame not processed", {{"error", f.error}});
        continue;
      }
      if (f.parts.empty()) {
        run_.count("locate_failed");
        (void)run_.step("nothing located", {{"count", f.belt_count}});
        continue;
      }
      const Belt belt = current_belt();
      std::vector<Located> parts = std::move(f.parts);
      f.parts.clear();
      std::sort(parts.begin(), parts.end(), [&](const Located& a, const Located& b) {
        return along(belt, a) > along(belt, b);
      });
      for (Located& l : parts) {
        queue_.push_back({std::move(l), f});
      }
    }
  }

  /// The ready pose between picks: above the belt, where parts enter the window (the job's
  /// `ready_mm`, else halfway between the upstream limit and the point nearest the robot).
  std::optional<ExecResult> go_ready(const Belt& belt) {
    Eigen::Vector3d at = belt.nearest + belt.direction * (0.5 * spec_.upstream_mm);
    if (spec_.ready_mm) {
      at.x() = spec_.ready_mm->x();
      at.y() = spec_.ready_mm->y();
    }
    const RobotView now = run_.links().robot(run_.robot().id());
    const double yaw = now.known ? std::atan2(now.base_T_tool.linear()(1, 0),
                                              now.base_T_tool.linear()(0, 0))
                                 : 0.0;
    if (now.known && (now.base_T_tool.translation() -
                      Eigen::Vector3d(at.x(), at.y(), spec_.travel_z_mm)).norm() < 1.0) {
      return std::nullopt;  // there already
    }
    cell_motion_MotionRequest r{};
    const std::string id = fresh(run_, "ready", run_.progress()["seq"].get<int>());
    r.motion_id = bus::borrow(id);
    r.kind = cell_motion_MOTION_MOVE_POSE;
    r.target = geometry::pose_to_idl(
        task::grasp_pose(run_.robot(), at.x(), at.y(), spec_.travel_z_mm, yaw));
    r.speed_scale = spec_.speed_scale;
    auto o = run_.move(r, "to the ready pose");
    if (!o) {
      return ExecResult::failed(o.error().message);
    }
    if (auto i = stop_if(o->interrupted); i) {
      return i;
    }
    if (o->robot_fault) {
      if (run_.pause_for_robot(o->reason) != Interrupt::kNone) {
        return stop_if(interrupt_of(run_.control()));
      }
      return std::nullopt;
    }
    if (!o->ok()) {
      return ExecResult::failed(fmt::format("ready pose: {}", o->reason));
    }
    return std::nullopt;
  }

  std::optional<ExecResult> stop_if(Interrupt i) { return stop_if_result(interrupted_result(i)); }
  /// A stop keeps the elapsed time for the resumed job.
  std::optional<ExecResult> stop_if_result(std::optional<ExecResult> r) {
    if (r && r->kind == ExecResult::Kind::kStopped) {
      run_.progress()["elapsed_s"] = elapsed();
    }
    return r;
  }

  double elapsed() const {
    return elapsed_before_ + std::chrono::duration<double>(Clock::now() - resumed_at_).count();
  }
  std::uint32_t picked() const {
    auto it = run_.counters().find("picked");
    return it != run_.counters().end() ? it->second : 0;
  }
  bool finished() const {
    return (spec_.duration_s > 0 && elapsed() >= spec_.duration_s) ||
           (spec_.max_parts > 0 && picked() >= static_cast<std::uint32_t>(spec_.max_parts));
  }
  double fraction() const {
    if (spec_.max_parts > 0) {
      return std::min(1.0, static_cast<double>(picked()) / spec_.max_parts);
    }
    return spec_.duration_s > 0 ? std::min(1.0, elapsed() / spec_.duration_s) : 0.0;
  }

  Belt current_belt() {
    Belt b = nominal_;
    if (auto cal = run_.links().belt_calibration(spec_.belt);
        cal && cal->robot_id == run_.robot().id()) {
      b.mm_per_count = cal->mm_per_count;
      b.direction = cal->direction;
      b.source = "calibration " + cal->version;
    }
    return b;
  }

  /// Position of a part along the belt's travel, from the point nearest the robot [mm].
  static double along(const Belt& belt, const Located& l) {
    return (Eigen::Vector3d(l.x_mm, l.y_mm, belt.nearest.z()) - belt.nearest).dot(belt.direction);
  }

  double grasp_z(const std::string& class_name, int& symmetry) const {
    auto cls = run_.catalogue().find(class_name);
    symmetry = cls ? cls->yaw_symmetry : 1;
    if (spec_.pick_z_mm) {
      return *spec_.pick_z_mm;
    }
    return plane_z_ + (cls ? cls->part_T_grasp.translation().z() : 0.0);
  }

  void record(const Located& l, cell_task_PartOutcome outcome, const std::string& detail) {
    PartRecord rec;
    rec.index = static_cast<std::uint32_t>(run_.parts().size());
    rec.class_name = l.class_name;
    rec.picked_x_mm = l.x_mm;
    rec.picked_y_mm = l.y_mm;
    rec.picked_yaw_rad = l.yaw_rad;
    rec.outcome = outcome;
    rec.detail = detail;
    // A long stream: keep the last 200 parts in the status; the counters keep the totals.
    auto& parts = run_.parts();
    if (parts.size() >= 200) {
      parts.erase(parts.begin());
    }
    parts.push_back(rec);
  }

  /// Stage 1 and 2 for one located part. Parts that cannot be taken are counted by cause.
  std::optional<ExecResult> take(const Located& part, const Frame& frame, const Belt& belt) {
    json& p = run_.progress();
    if (!part.has_pose) {
      run_.count("locate_failed");
      record(part, cell_task_PART_LOCATE_FAILED, "no pose in the robot frame");
      return std::nullopt;
    }
    if (!run_.catalogue().find(part.class_name) && !spec_.pick_z_mm) {
      run_.count("locate_failed");
      record(part, cell_task_PART_LOCATE_FAILED,
             fmt::format("not recognised (class '{}'): no grasp height", part.class_name));
      return std::nullopt;
    }
    if (part.grip == cell_vision_GRIP_BLOCKED) {
      run_.count("grip_blocked");
      record(part, cell_task_PART_SKIPPED_GRIP_BLOCKED, part.grip_detail);
      return std::nullopt;
    }
    const auto reading = run_.links().belt(spec_.belt);
    if (!reading) {
      return ExecResult::failed(fmt::format("no encoder reading of belt '{}' on the bus",
                                            spec_.belt));
    }
    const Eigen::Vector3d v_belt = belt.direction * reading->speed_mm_per_s;
    auto shift_at = [&](std::int64_t count) {
      return belt.direction * (belt.mm_per_count * static_cast<double>(count - frame.belt_count));
    };
    int symmetry = 1;
    const double z = grasp_z(part.class_name, symmetry);
    // Among the part's symmetric yaws, the one whose roll joint is nearest its current value
    // while staying a quarter turn inside its limits: rolls must not creep toward a limit
    // pick after pick (a line that meets it would need a joint to jump).
    const RobotView now = run_.links().robot(run_.robot().id());
    const double yaw = grasp_yaw(part, z, symmetry, now);
    // Where to meet the part: a point downstream of it, reached before the part gets there
    // (the planned duration, from the motion service's preview, plus a margin). The robot
    // goes there with ALTER on; the correction, shift(t) - lead, stays 0 until the part
    // arrives, then follows the belt: continuous from 0, so the arm never jumps, at any belt
    // speed. lead is the belt travel since exposure at the meeting time.
    const int seq = p["seq"].get<int>() + 1;
    p["seq"] = seq;
    const std::string track_id = fresh(run_, "track", seq);
    cell_motion_MotionRequest r{};
    const std::string robot_id = run_.robot().id();
    r.motion_id = bus::borrow(track_id);
    r.robot_id = bus::borrow(robot_id);
    r.kind = cell_motion_MOTION_TRACK;
    r.speed_scale = spec_.speed_scale;
    r.alter_cumulative = false;
    r.alter_world_frame = true;
    const Eigen::Vector3d at_exposure(part.x_mm, part.y_mm, z);
    const auto reading_now = run_.links().belt(spec_.belt);
    const double travel_now =
        belt.mm_per_count *
        static_cast<double>((reading_now ? reading_now->count : frame.belt_count) -
                            frame.belt_count);
    const double speed = std::abs(reading_now ? reading_now->speed_mm_per_s : 0.0);
    // First guess: where the arm already is along the belt (it waits downstream of the camera).
    double lead_mm = travel_now;
    if (now.known) {
      lead_mm = std::max(lead_mm, (now.base_T_tool.translation() - at_exposure).dot(belt.direction));
    }
    double planned_s = 0.0;
    const auto aim = [&] {
      r.target = geometry::pose_to_idl(task::grasp_pose(
          run_.robot(), at_exposure.x() + belt.direction.x() * lead_mm,
          at_exposure.y() + belt.direction.y() * lead_mm, z, yaw));
    };
    for (int pass = 0; pass < 5; ++pass) {
      aim();
      const auto d = preview_duration(r);
      if (!d) {
        // A meeting point the arm cannot reach is outside the window; anything else failed.
        const bool reach = d.error().code == Errc::kOutOfRange;
        run_.count(reach ? "outside_window" : "motion_failed");
        record(part, reach ? cell_task_PART_SKIPPED_OUTSIDE_WINDOW : cell_task_PART_MISSED,
               d.error().message);
        return std::nullopt;
      }
      planned_s = *d;
      const double needed_mm =
          travel_now + speed * (planned_s + kStartLatencyS + kMeetMarginS);
      if (needed_mm <= lead_mm + 1.0) {
        break;  // the robot is there before the part
      }
      lead_mm = needed_mm;
    }
    aim();  // the target is where lead_mm says, whatever pass ended the loop
    // The downstream limit before the robot moves (the chapter's downstr_lim): the meeting
    // point and the grip's end (following the part through the dwell) inside the window.
    const double s_meet =
        (Eigen::Vector3d(part.x_mm, part.y_mm, belt.nearest.z()) + belt.direction * lead_mm -
         belt.nearest)
            .dot(belt.direction);
    {
      const double s_end = s_meet + speed * spec_.dwell_s;
      if (s_end > spec_.downstream_mm || s_meet < spec_.upstream_mm) {
        run_.count("outside_window");
        record(part, cell_task_PART_SKIPPED_OUTSIDE_WINDOW,
               fmt::format("the grasp would be {:.0f} to {:.0f} mm along the belt, outside the "
                           "window [{:.0f}, {:.0f}] mm",
                           s_meet, s_end, spec_.upstream_mm, spec_.downstream_mm));
        (void)run_.step("part skipped");
        return std::nullopt;
      }
    }
    const Eigen::Vector3d lead = belt.direction * lead_mm;
    moved_ = true;
    r.preview_only = false;
    auto sent = run_.links().send_motion(r);
    if (!sent) {
      return ExecResult::failed(sent.error().message);
    }
    run_.report(fmt::format("tracking part ({} picked)", picked()), fraction());
    // Stage 2: ALTER every cycle until the motion arrives, then through the grip.
    std::uint64_t cycle = 0;
    std::int64_t accepted_ns = 0;  // wall clock when the motion service took the track
    bool arrived = false;
    std::string trajectory_id;
    auto next = Clock::now();
    const auto give_up = Clock::now() + std::chrono::milliseconds(static_cast<std::int64_t>(
                                            run_.config().motion_timeout_s * 1000));
    bool part_met = false;  // the part has reached the meeting point: ALTER follows it
    bool escaped = false;   // the part went past the window before it was gripped
    // This part is not taken: it escaped the window, or `why`. Stop, count, go on.
    const auto let_go = [&](const char* why) {
      stop_robot();
      run_.count(escaped ? "outside_window" : "motion_failed");
      record(part, escaped ? cell_task_PART_SKIPPED_OUTSIDE_WINDOW : cell_task_PART_MISSED,
             escaped ? "the part left the window before the arm reached it" : why);
      return recover_after_stop();
    };
    const auto send_alter = [&] {
      const RobotView v = run_.links().robot(robot_id);
      if (!v.trajectory_id.empty()) {
        trajectory_id = v.trajectory_id;
      }
      if (!trajectory_id.empty()) {
        if (const auto latest = run_.links().belt(spec_.belt); latest) {
          Eigen::Vector3d c = shift_at(latest->count) - lead;
          // Never past the window's downstream limit: there the part escapes (the arm holds
          // at the limit and this part is counted outside the window).
          if (s_meet + c.dot(belt.direction) > spec_.downstream_mm) {
            c = belt.direction * std::max(0.0, spec_.downstream_mm - s_meet);
            escaped = true;
          }
          const bool met = c.dot(belt.direction) > 0.0;
          part_met = part_met || met;
          // The rate only while following: held at the limit (or waiting), the gateway must
          // not extrapolate the correction further. Near the limit, the extrapolation (at the
          // belt's rate, whatever the link delays) may run only until the limit, never past
          // it (netlab, 50 ms + 5 % loss: a chased part drove the arm 32 mm past the limit
          // and out of reach). The rate itself stays the belt's: a cut rate makes the arm lag
          // the part between corrections (5 mm at 2 m/s, a missed grasp).
          Eigen::Vector3d rate = Eigen::Vector3d::Zero();
          double horizon_s = 0.0;  // the gateway's own
          if (met && !escaped) {
            const double room = spec_.downstream_mm - (s_meet + c.dot(belt.direction));
            rate = v_belt;
            if (speed * trajectory::AlterState::kExtrapolationHorizonS > room) {
              // At least 1 us: 0 would mean the gateway's horizon.
              horizon_s = std::max(1e-6, room / speed);
            }
          }
          (void)run_.links().alter(robot_id, trajectory_id, ++cycle,
                                   met ? c : Eigen::Vector3d::Zero(), rate, latest->stamp_ns,
                                   horizon_s);
        }
      }
      pump_eye();
      next += std::chrono::duration_cast<Clock::duration>(
          std::chrono::duration<double>(spec_.alter_period_s));
      std::this_thread::sleep_until(next);
    };
    while (!arrived) {
      if (control_interrupted()) {
        stop_robot();
        return stop_if(interrupt_of(run_.control()));
      }
      if (Clock::now() > give_up || escaped) {
        return let_go("the tracking motion did not end in time");
      }
      if (auto u = run_.links().poll_motion(*sent); u) {
        if (accepted_ns == 0 && u->state != cell_motion_MOTION_REFUSED) {
          accepted_ns = wall_time_ns();
        }
        if (u->terminal) {
          if (u->state != cell_motion_MOTION_DONE) {
            run_.count("motion_failed");
            record(part, cell_task_PART_MISSED, u->reason);
            return recover_after_stop();
          }
          arrived = true;
        }
      }
      send_alter();
    }
    // At the meeting point: wait for the part (ALTER then follows it), close the gripper,
    // keep tracking through the dwell.
    const auto meet_deadline = Clock::now() + std::chrono::duration<double>(
                                                  1.0 + 2.0 * kMeetMarginS +
                                                  (speed > 1.0 ? 200.0 / speed : 0.0));
    while (!part_met && Clock::now() < meet_deadline) {
      if (control_interrupted()) {
        stop_robot();
        return stop_if(interrupt_of(run_.control()));
      }
      send_alter();
    }
    if (!part_met || escaped) {
      return let_go("the part did not reach the meeting point in time");
    }
    send_alter();  // one correction past the meeting point, so the arm moves with the part
    if (const auto latest = run_.links().belt(spec_.belt); latest) {
      const RobotView v = run_.links().robot(robot_id);
      const Eigen::Vector3d part_now = at_exposure + shift_at(latest->count);
      log::debug("job", "gripping", {{"job", run_.job_id()},
                                     {"tool_minus_part_mm",
                                      fmt::format("{:.2f},{:.2f}",
                                                  v.base_T_tool.translation().x() - part_now.x(),
                                                  v.base_T_tool.translation().y() - part_now.y())},
                                     {"met", part_met ? "yes" : "no"},
                                     {"tracking", v.tracking ? "yes" : "no"}});
    }
    // Corrections go on while the command and its answer travel (tens of ms to a few hundred
    // over a lossy link: the gateway's extrapolation alone would stop after its horizon).
    if (auto closed = run_.links().command(robot_id, cell_robot_CMD_GRIPPER_CLOSE, 2000ms,
                                           send_alter);
        !closed) {
      run_.count("motion_failed");
      record(part, cell_task_PART_MISSED, closed.error().message);
      return recover_after_stop();
    }
    if (escaped) {
      // The arm held at the window's limit while the command travelled: whatever the gripper
      // closed on, this is not a grip at the part's grasp point. Let it go.
      (void)run_.links().command(robot_id, cell_robot_CMD_GRIPPER_OPEN, 2000ms);
      return let_go("the part left the window while the gripper closed");
    }
    const auto grip_end = Clock::now() + std::chrono::duration<double>(spec_.dwell_s);
    while (Clock::now() < grip_end) {
      send_alter();
    }
    // Following the held part until ALTOFF lands (held at the window's limit at the most).
    (void)run_.links().command(robot_id, cell_robot_CMD_ALTER_OFF, 2000ms, send_alter);
    // The depart starts where ALTER left the arm: wait for it to rest there (a state taken
    // while it still followed the belt would be refused by the gateway).
    (void)run_.links().wait_robot(
        robot_id, [](const RobotView& v) { return !v.moving && !v.tracking; }, 500ms,
        run_.control());
    if (const RobotView held = run_.links().robot(robot_id);
        held.gripper != cell_robot_GRIPPER_CLOSED) {
      run_.count("motion_failed");
      record(part, cell_task_PART_MISSED, "the gripper did not close");
      return recover_after_stop();
    }
    // Held from here: journal the intent to place, then depart and place.
    const task::Slot& slot =
        spec_.place.slots[static_cast<std::size_t>(p["slot"].get<int>()) % spec_.place.slots.size()];
    const double place_z = spec_.place_z_mm.value_or(z);
    p["holding"] = {{"class", part.class_name},
                    {"x", part.x_mm},
                    {"y", part.y_mm},
                    {"yaw", part.yaw_rad},
                    {"pick_z", z},
                    {"place_z", place_z},
                    {"place_yaw", slot.yaw_rad + (yaw - part.yaw_rad)},
                    {"depart_id", fresh(run_, "depart", seq)},
                    {"place_id", fresh(run_, "place", seq)},
                    {"stage", "depart"}};
    // Exposure -> the tracking motion under way (the motion service planned it and handed it
    // to the gateway): the chapter's stage-1 latency (bench/task).
    const double exposure_to_track_ms =
        accepted_ns > 0 ? static_cast<double>(accepted_ns - frame.exposure_ns) * 1e-6 : -1.0;
    if (auto s = run_.step("gripped", {{"class", part.class_name},
                                       {"exposure_to_track_ms", exposure_to_track_ms},
                                       {"vision_ms", frame.processing_ms}});
        !s) {
      return ExecResult::failed(s.error().message);
    }
    return finish_holding();
  }

  /// Depart and place the part held in progress["holding"] (also after a restart).
  std::optional<ExecResult> finish_holding() {
    json& p = run_.progress();
    json& h = p["holding"];
    const std::string robot_id = run_.robot().id();
    for (;;) {
      const bool departing = h["stage"] == "depart";
      const std::string id = h[departing ? "depart_id" : "place_id"].get<std::string>();
      if (auto done = run_.links().motion_status(id, 0ms);
          done && done->state == cell_motion_MOTION_DONE) {
        // Done before a restart.
      } else {
        cell_motion_MotionRequest r{};
        r.motion_id = bus::borrow(id);
        r.speed_scale = spec_.speed_scale;
        if (departing) {
          r.kind = cell_motion_MOTION_DEPART;
          r.distance_mm = std::max(10.0, spec_.travel_z_mm - h["pick_z"].get<double>());
        } else {
          const task::Slot& slot = spec_.place.slots[static_cast<std::size_t>(
                                                         p["slot"].get<int>()) %
                                                     spec_.place.slots.size()];
          r.kind = cell_motion_MOTION_PLACE;
          r.target = geometry::pose_to_idl(task::grasp_pose(
              run_.robot(), slot.x_mm, slot.y_mm, h["place_z"].get<double>(),
              h["place_yaw"].get<double>()));
          r.distance_mm = std::max(10.0, spec_.travel_z_mm - h["place_z"].get<double>());
        }
        auto o = run_.move(r, departing ? "departing" : "placing");
        if (!o) {
          return ExecResult::failed(o.error().message);
        }
        if (o->interrupted == Interrupt::kStop || run_.control().stop.load()) {
          return ExecResult::stopped();
        }
        if (o->interrupted == Interrupt::kCancel || run_.control().cancel.load()) {
          return ExecResult::cancelled();
        }
        if (o->robot_fault) {
          if (run_.pause_for_robot(o->reason) != Interrupt::kNone) {
            return stop_if(interrupt_of(run_.control()));
          }
          h[departing ? "depart_id" : "place_id"] =
              fresh(run_, departing ? "depart" : "place", p["seq"].get<int>());
          continue;
        }
        if (!o->ok()) {
          Located l;
          l.class_name = h["class"].get<std::string>();
          record(l, cell_task_PART_MISSED, o->reason);
          run_.count("place_failed");
          p["holding"] = nullptr;
          if (auto s = run_.step("place failed", {{"why", o->reason}}); !s) {
            return ExecResult::failed(s.error().message);
          }
          return std::nullopt;
        }
      }
      if (departing) {
        h["stage"] = "place";
        if (auto s = run_.step("departed"); !s) {
          return ExecResult::failed(s.error().message);
        }
        continue;
      }
      Located l;
      l.class_name = h["class"].get<std::string>();
      l.x_mm = h["x"].get<double>();
      l.y_mm = h["y"].get<double>();
      l.yaw_rad = h["yaw"].get<double>();
      record(l, cell_task_PART_PLACED, "");
      const std::size_t slot_index =
          static_cast<std::size_t>(p["slot"].get<int>()) % spec_.place.slots.size();
      auto& rec = run_.parts().back();
      rec.placed_x_mm = spec_.place.slots[slot_index].x_mm;
      rec.placed_y_mm = spec_.place.slots[slot_index].y_mm;
      rec.placed_yaw_rad = spec_.place.slots[slot_index].yaw_rad;
      p["slot"] = p["slot"].get<int>() + 1;
      p["holding"] = nullptr;
      p["elapsed_s"] = elapsed();
      run_.count("picked");
      if (auto s = run_.step("placed"); !s) {
        return ExecResult::failed(s.error().message);
      }
      return std::nullopt;
    }
  }

  bool control_interrupted() const { return run_.control().interrupted(); }

  void stop_robot() {
    cell_motion_MotionRequest stop{};
    const std::string id = run_.job_id() + "/stop";
    const std::string robot_id = run_.robot().id();
    stop.motion_id = bus::borrow(id);
    stop.robot_id = bus::borrow(robot_id);
    stop.kind = cell_motion_MOTION_STOP;
    (void)run_.links().send_motion(stop);
  }

  void wait_terminal(std::uint64_t seq) {
    const auto until = Clock::now() + 5s;
    while (Clock::now() < until) {
      if (auto u = run_.links().poll_motion(seq); u && u->terminal) {
        return;
      }
      std::this_thread::sleep_for(5ms);
    }
  }

  /// After a stop (outside the window, a failed track): reset the robot, which holds where it
  /// stopped, and go on with the next part.
  std::optional<ExecResult> recover_after_stop() {
    const std::string robot_id = run_.robot().id();
    (void)run_.links().wait_robot(robot_id, [](const RobotView& v) { return !v.moving; }, 2000ms,
                                  run_.control());
    const RobotView v = run_.links().robot(robot_id);
    if (v.mode == cell_robot_MODE_STOPPED) {
      (void)run_.links().command(robot_id, cell_robot_CMD_RESET, 2000ms);
    } else if (v.mode == cell_robot_MODE_FAULT) {
      if (run_.pause_for_robot(v.fault_text) != Interrupt::kNone) {
        return stop_if(interrupt_of(run_.control()));
      }
    }
    (void)run_.links().command(robot_id, cell_robot_CMD_ALTER_OFF, 2000ms);
    if (auto s = run_.step("part skipped"); !s) {
      return ExecResult::failed(s.error().message);
    }
    return std::nullopt;
  }

  JobRun& run_;
  const task::ConveyorPickSpec& spec_;
  Belt nominal_;
  double plane_z_ = 0.0;
  double elapsed_before_ = 0.0;
  Clock::time_point resumed_at_;
  std::deque<Queued> queue_;
  bool moved_ = false;  ///< a part was tracked since the robot was last at its ready pose
  /// From the preview to the arm moving (the real request, planning, the gateway's start).
  static constexpr double kStartLatencyS = 0.02;
  /// The robot is at the meeting point this long before the part.
  static constexpr double kMeetMarginS = 0.03;
};

}  // namespace

ExecResult run_conveyor_job(JobRun& run) { return ConveyorJob(run).run(); }

}  // namespace cell::task_service
