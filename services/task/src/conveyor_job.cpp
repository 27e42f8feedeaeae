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
        (void)run_.links().wait_frames(5ms);  // a frame wakes it at once
        if (auto r = stop_if(interrupt_of(run_.control())); r) {
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

  /// Where the tool takes a part: its grasp point (base frame, mm) and the tool's yaw there.
  struct Grasp {
    double x_mm = 0.0;
    double y_mm = 0.0;
    double yaw_rad = 0.0;
  };

  /// Of the part's clear grasps (all of them turned by its symmetry), the one whose roll joint
  /// is nearest its current value while staying a quarter turn inside its limits, judged
  /// where the arm meets the part: level with the arm along the belt (the roll that puts the
  /// tool at a yaw depends on where the arm is). A part whose grip vision did not test is
  /// taken at its centre and its own yaw (and turns).
  Grasp choose_grasp(const Located& part, double z, int symmetry, const RobotView& now,
                     const Belt& belt) const {
    std::vector<Grasp> styles;
    for (const auto& g : part.grasps) {
      styles.push_back({g.x_mm, g.y_mm, g.yaw_rad});
    }
    if (styles.empty()) {
      styles.push_back({part.x_mm, part.y_mm, part.yaw_rad});
    }
    if (!now.known) {
      return styles.front();
    }
    const auto& robot = run_.robot();
    const Eigen::Index roll = robot.dof() - 1;
    const auto& spec = robot.joints()[static_cast<std::size_t>(roll)];
    const double margin = std::numbers::pi / 2;
    const int n = symmetry <= 0 ? 1 : symmetry;  // a disc: its own yaw will do
    const double step = 2 * std::numbers::pi / n;
    const Eigen::Vector3d to_arm =
        belt.direction * (along(belt, Eigen::Vector3d(now.base_T_tool.translation())) -
                          along(belt, part));
    Grasp best = styles.front();
    double best_cost = std::numeric_limits<double>::infinity();
    for (const Grasp& style : styles) {
      for (int k = -n; k <= n; ++k) {
        Grasp g = style;
        g.yaw_rad += step * k;
        auto q = robot.inverse(task::grasp_pose(robot, g.x_mm + to_arm.x(), g.y_mm + to_arm.y(),
                                                z, g.yaw_rad),
                               now.q);
        if (!q) {
          continue;
        }
        const double r = (*q)[roll];
        const bool inside = r >= spec.lower + margin && r <= spec.upper - margin;
        const double cost = std::abs(r - now.q[roll]) + (inside ? 0.0 : 100.0);
        if (cost < best_cost) {
          best_cost = cost;
          best = g;
        }
      }
    }
    return best;
  }

  /// The farthest point along the belt, up to the window's downstream limit, where the arm
  /// still holds grasp `g` (a part followed along the belt at its lateral place) [mm along
  /// the belt], found in 5 mm steps back from the limit.
  double reach_end(const Grasp& g, double z, const Belt& belt, const RobotView& now) const {
    const auto& robot = run_.robot();
    const Eigen::Vector3d p0(g.x_mm, g.y_mm, z);
    const double s0 = along(belt, p0);
    for (double s = spec_.downstream_mm; s > spec_.upstream_mm; s -= 5.0) {
      const Eigen::Vector3d p = p0 + belt.direction * (s - s0);
      if (robot.cartesian_limits().check(p) &&
          robot.inverse(task::grasp_pose(robot, p.x(), p.y(), z, g.yaw_rad), now.q)) {
        return s;
      }
    }
    return spec_.upstream_mm;
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
    return along(belt, Eigen::Vector3d(l.x_mm, l.y_mm, 0.0));
  }
  static double along(const Belt& belt, const Eigen::Vector3d& p) {
    return (Eigen::Vector3d(p.x(), p.y(), belt.nearest.z()) - belt.nearest).dot(belt.direction);
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
    // The grasp: of the part's clear grasp styles (vision's clear-grip test; the part's own
    // yaw when it was not tested) and their symmetric turns, the one whose roll joint is
    // nearest its current value while staying a quarter turn inside its limits. On a fast
    // belt the roll is what takes the arm longest (a DIP across its body or on its ends: at
    // most 45 deg), and rolls must not creep toward a limit pick after pick.
    const RobotView now = run_.links().robot(run_.robot().id());
    const Grasp grasp = choose_grasp(part, z, symmetry, now, belt);
    // Where to meet the part: the motion service plans it in one round trip (the earliest
    // point of the part's path the arm reaches kMeetMarginS before the part, inside the belt
    // window with room for the grip: the chapter's downstream limit, checked before the arm
    // moves) and sends the track there. The robot goes there with ALTER on; the correction
    // stays 0 until the part comes within the meeting ramp of it, then takes up the belt's pace
    // along the ramp (f(d) of the part's travel d = shift(t) - lead past the meeting point:
    // trajectory::MeetingRamp), and follows the belt from d = D on: continuous in position and
    // speed, so the arm never jumps, at any belt speed it can follow. lead is the belt travel
    // since exposure at the meeting point.
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
    r.track_joint_interpolated = spec_.track_joint_interpolated;
    const Eigen::Vector3d at_exposure(grasp.x_mm, grasp.y_mm, z);
    r.target = geometry::pose_to_idl(
        task::grasp_pose(run_.robot(), at_exposure.x(), at_exposure.y(), z, grasp.yaw_rad));
    const double speed = std::abs(reading->speed_mm_per_s);
    r.target_velocity_mm_per_s = {v_belt.x(), v_belt.y(), v_belt.z()};
    r.target_stamp_ns = frame.exposure_ns;
    r.meet_margin_s = kMeetMarginS;
    r.meet_follow_s = spec_.dwell_s;
    const double s_exposure = along(belt, at_exposure);
    r.meet_from_mm = spec_.upstream_mm - s_exposure;
    // The grip's end (following the part through the dwell) inside the window too: the
    // window's downstream end, or sooner where the arm's reach ends (on the belt's far side
    // the reach ends before a window drawn along the centre line: following the part there
    // would fault the robot).
    const double downstream = std::min(spec_.downstream_mm, reach_end(grasp, z, belt, now));
    r.meet_to_mm = downstream - speed * spec_.dwell_s - s_exposure;
    // Where the part is now (its frame may have waited in the queue while the arm was busy).
    const double travel_now =
        belt.mm_per_count * static_cast<double>(reading->count - frame.belt_count);
    if (speed <= 0.0 || r.meet_to_mm <= travel_now || r.meet_to_mm < r.meet_from_mm) {
      run_.count("outside_window");
      record(part, cell_task_PART_SKIPPED_OUTSIDE_WINDOW,
             speed <= 0.0 ? std::string("the belt is not moving")
                          : fmt::format("{:.0f} mm along the belt now: no room left in the "
                                        "window [{:.0f}, {:.0f}] mm for the grip",
                                        s_exposure + travel_now, spec_.upstream_mm, downstream));
      (void)run_.step("part skipped");
      return std::nullopt;
    }
    moved_ = true;
    auto sent = run_.links().send_motion(r);
    if (!sent) {
      return ExecResult::failed(sent.error().message);
    }
    // The answer: accepted with the meeting point, or refused (no point of the window can be
    // met in time: outside the window; anything else failed).
    std::optional<Links::MotionUpdate> first;
    const auto answer_by = Clock::now() + 2000ms;
    while (!first && Clock::now() < answer_by) {
      first = run_.links().poll_motion(*sent);
      if (!first) {
        pump_eye();
        std::this_thread::sleep_for(200us);
      }
    }
    if (!first) {
      run_.count("motion_failed");
      record(part, cell_task_PART_MISSED, "the motion service did not answer the track in 2 s");
      return recover_after_stop();
    }
    if (first->state == cell_motion_MOTION_REFUSED) {
      moved_ = false;  // refused: the arm did not move
      const bool window = first->error_code == "out_of_range";
      run_.count(window ? "outside_window" : "motion_failed");
      record(part, window ? cell_task_PART_SKIPPED_OUTSIDE_WINDOW : cell_task_PART_MISSED,
             first->reason);
      (void)run_.step("part skipped");
      return std::nullopt;
    }
    if (first->meet_stamp_ns == 0 || (first->terminal && first->state != cell_motion_MOTION_DONE)) {
      run_.count("motion_failed");
      record(part, cell_task_PART_MISSED,
             first->terminal ? first->reason
                             : "the motion service gave no meeting point for the track");
      return recover_after_stop();
    }
    const std::int64_t accepted_ns = wall_time_ns();  // the motion service took the track
    const double lead_mm = (first->meet_target.translation() - at_exposure).dot(belt.direction);
    const double s_meet = s_exposure + lead_mm;
    const Eigen::Vector3d lead = belt.direction * lead_mm;
    // The arm waits at the meeting point and takes up the part's pace along the meeting ramp
    // the motion service planned within its joints' limits (no velocity step: held to its
    // limits, the arm would lag the part and the gripper close beside it).
    const trajectory::MeetingRamp ramp{first->meet_ramp_mm};
    run_.report(fmt::format("tracking part ({} picked)", picked()), fraction());
    // Stage 2: ALTER every cycle until the motion arrives, then through the grip.
    std::uint64_t cycle = 0;
    bool arrived = first->terminal;  // DONE already (a status batch can hold several)
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
          // d: the part's travel past the meeting point; the arm's along the ramp.
          const double d = (shift_at(latest->count) - lead).dot(belt.direction);
          Eigen::Vector3d c = belt.direction * ramp.displacement(d);
          const double pace = ramp.rate(d);  // the arm's speed as a fraction of the belt's
          // Never past the window's downstream limit: there the part escapes (the arm holds
          // at the limit and this part is counted outside the window).
          if (s_meet + c.dot(belt.direction) > downstream) {
            c = belt.direction * std::max(0.0, downstream - s_meet);
            escaped = true;
          }
          const bool met = c.dot(belt.direction) > 0.0;
          part_met = part_met || ramp.on_target(d);
          // The rate only while following: held at the limit (or waiting), the gateway must
          // not extrapolate the correction further. Near the limit, the extrapolation (at the
          // belt's rate, whatever the link delays) may run only until the limit, never past
          // it (netlab, 50 ms + 5 % loss: a chased part drove the arm 32 mm past the limit
          // and out of reach). The rate itself stays the belt's: a cut rate makes the arm lag
          // the part between corrections (5 mm at 2 m/s, a missed grasp).
          Eigen::Vector3d rate = Eigen::Vector3d::Zero();
          double horizon_s = 0.0;  // the gateway's own
          if (met && !escaped) {
            const double room = downstream - (s_meet + c.dot(belt.direction));
            rate = v_belt * pace;
            if (speed * pace * trajectory::AlterState::kExtrapolationHorizonS > room) {
              // At least 1 us: 0 would mean the gateway's horizon.
              horizon_s = std::max(1e-6, room / (speed * pace));
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
    const auto meet_deadline =
        Clock::now() +
        std::chrono::duration<double>(1.0 + 2.0 * kMeetMarginS +
                                      (speed > 1.0 ? (200.0 + 2.0 * ramp.length_mm) / speed : 0.0));
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
    // The gripper closes once the gateway reports the tool on the part: its state, stamped,
    // against where the part was at that instant. Over a slow link the gateway extrapolates the
    // ramp's corrections linearly while the ramp accelerates, and catches up at the arm's limits
    // when the later ones arrive (netlab, 50 ms: grasps 1.3-1.7 mm off, some beside the part).
    // Not reported within kOnPartWaitS: the gripper closes as before, and the grip is checked.
    {
      const auto on_part_by =
          Clock::now() + std::chrono::duration_cast<Clock::duration>(
                             std::chrono::duration<double>(kOnPartWaitS + ramp.length_mm / speed));
      while (Clock::now() < on_part_by && !escaped) {
        const RobotView v = run_.links().robot(robot_id);
        const auto latest = run_.links().belt(spec_.belt);
        if (latest && v.stamp_ns > 0) {
          const Eigen::Vector3d part_then =
              at_exposure + shift_at(latest->count) +
              v_belt * (static_cast<double>(v.stamp_ns - latest->stamp_ns) * 1e-9);
          const Eigen::Vector3d off = v.base_T_tool.translation() - part_then;
          if (std::hypot(off.x(), off.y()) <= kOnPartToleranceMm) {
            break;
          }
        }
        send_alter();
      }
    }
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
                    {"place_yaw", slot.yaw_rad + (grasp.yaw_rad - part.yaw_rad)},
                    {"depart_id", fresh(run_, "depart", seq)},
                    {"place_id", fresh(run_, "place", seq)},
                    {"stage", "depart"}};
    // Exposure -> the tracking motion under way (the motion service planned it and handed it
    // to the gateway): the chapter's stage-1 latency (bench/task).
    const double exposure_to_track_ms = static_cast<double>(accepted_ns - frame.exposure_ns) * 1e-6;
    if (auto s = run_.step("gripped",
                           {{"class", part.class_name},
                            {"exposure_to_track_ms", exposure_to_track_ms},
                            {"exposure_to_frame_ms",
                             static_cast<double>(frame.received_ns - frame.exposure_ns) * 1e-6},
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
  /// The robot is at the meeting point this long before the part.
  static constexpr double kMeetMarginS = 0.03;
  /// Before the gripper closes: how long to wait, past the ramp's own time, for the gateway to
  /// report the tool within kOnPartToleranceMm of the part.
  static constexpr double kOnPartWaitS = 0.15;
  static constexpr double kOnPartToleranceMm = 0.5;
};

}  // namespace

ExecResult run_conveyor_job(JobRun& run) { return ConveyorJob(run).run(); }

}  // namespace cell::task_service
