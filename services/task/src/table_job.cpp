// table_pick_place: the 1994 thesis's sequence (digest 000 §1.3, §5.3, §6) without its flaws:
// no key-press after recognition, an unreachable part is skipped and reported instead of
// exit(1), a missed grasp is found by looking again and retried, and every step is journaled
// so that a restarted service goes on from the last one without picking a part twice.
#include <cmath>
#include <numbers>
#include <random>

#include <fmt/format.h>

#include "cell/bus/view.hpp"
#include "cell/common/log.hpp"
#include "cell/geometry/idl_pose.hpp"
#include "job_run.hpp"

namespace cell::task_service {
namespace {

using json = nlohmann::json;
using namespace std::chrono_literals;

constexpr double kSameSpotMm = 3.0;  // a part seen again within this of a pick: the same part

struct Target {
  Located part;
  double grasp_z_mm = 0.0;
  int symmetry = 1;
};


/// Grasp height of a located part: the spec's, or the plane plus the class's grasp height.
std::optional<double> grasp_height(JobRun& run, const task::TablePickPlaceSpec& spec,
                                   const std::string& class_name, int& symmetry) {
  auto cls = run.catalogue().find(class_name);
  symmetry = cls ? cls->yaw_symmetry : 1;
  if (spec.pick_z_mm) {
    return spec.pick_z_mm;
  }
  if (!cls) {
    return std::nullopt;
  }
  for (const auto& c : run.config().cameras) {
    if (c.id == spec.camera) {
      return c.working_plane_z_mm + cls->part_T_grasp.translation().z();
    }
  }
  return std::nullopt;
}

cell_motion_MotionRequest joints_request(const std::string& id, const std::vector<double>& q,
                                         double speed) {
  cell_motion_MotionRequest r{};
  r.motion_id = bus::borrow(id);
  r.kind = cell_motion_MOTION_MOVE_JOINTS;
  bus::borrow(r.joints_rad_or_mm, q);
  r.speed_scale = speed;
  return r;
}

std::vector<double> to_std(const kinematics::JointVector& q) {
  return std::vector<double>(q.data(), q.data() + q.size());
}

/// Tool poses for the pick and the place that leave the part at the slot's yaw. The part is
/// taken by its clear grasp styles in their order (the chapter: the first clear style wins;
/// vision's clear-grip test, Located::grasps), or at its centre and own yaw when vision did
/// not test the grip, each at any of its symmetric turns; the place turns and shifts the tool
/// as the part must turn and shift onto the slot. The first combination both ends of which
/// the robot reaches (seeded from the current joints) wins.
struct Grip {
  Eigen::Isometry3d pick;
  Eigen::Isometry3d place;
};
std::optional<Grip> plan_grip(const kinematics::RobotModel& robot, const Located& part,
                              double pick_z, const task::Slot& slot, double place_z,
                              int symmetry, const kinematics::JointVector& seed,
                              std::string& why) {
  std::vector<Located::Grasp> styles = part.grasps;
  if (styles.empty()) {
    styles.push_back({-1, "centre", part.x_mm, part.y_mm, part.yaw_rad});
  }
  const int n = symmetry <= 0 ? 1 : symmetry;
  for (const Located::Grasp& style : styles) {
    for (int k = 0; k < n; ++k) {
      const double offset = 2 * std::numbers::pi * k / n;
      // The part turns by slot - part yaw onto the slot; the grasp point turns with it.
      const Eigen::Vector2d from_centre =
          Eigen::Rotation2Dd(slot.yaw_rad - part.yaw_rad) *
          Eigen::Vector2d(style.x_mm - part.x_mm, style.y_mm - part.y_mm);
      const double tool_minus_part = style.yaw_rad - part.yaw_rad + offset;
      Grip g{task::grasp_pose(robot, style.x_mm, style.y_mm, pick_z, style.yaw_rad + offset),
             task::grasp_pose(robot, slot.x_mm + from_centre.x(), slot.y_mm + from_centre.y(),
                              place_z, slot.yaw_rad + tool_minus_part)};
      auto q_pick = robot.inverse(g.pick, seed);
      if (!q_pick) {
        why = q_pick.error().message;
        continue;
      }
      auto q_place = robot.inverse(g.place, *q_pick);
      if (!q_place) {
        why = q_place.error().message;
        continue;
      }
      return g;
    }
  }
  return std::nullopt;
}

/// Index of the part record whose pick location is within kSameSpotMm of (x, y), or -1.
int record_at(const std::vector<PartRecord>& parts, double x, double y) {
  for (std::size_t i = 0; i < parts.size(); ++i) {
    if (std::hypot(parts[i].picked_x_mm - x, parts[i].picked_y_mm - y) < kSameSpotMm) {
      return static_cast<int>(i);
    }
  }
  return -1;
}

class TableJob {
 public:
  explicit TableJob(JobRun& run) : run_(run), spec_(*run.spec().table()) {}

  ExecResult run() {
    json& p = run_.progress();
    if (!p.contains("window")) {
      p["window"] = 0;
      json free = json::array();
      const std::size_t n = spec_.max_parts > 0
                                ? std::min<std::size_t>(spec_.max_parts, spec_.place.slots.size())
                                : spec_.place.slots.size();
      for (std::size_t i = 0; i < n; ++i) {
        free.push_back(i);
      }
      p["free_slots"] = free;
      p["seq"] = 0;
      p["phase"] = "windows";
      p["holding"] = nullptr;
      p["attempts"] = json::object();
    }
    if (auto r = run_.ready_robot(); r) {
      return *r;
    }
    if (auto r = resolve_holding(); r) {
      return *r;
    }
    while (p["phase"] == "windows") {
      const int w = p["window"].get<int>();
      if (w >= static_cast<int>(spec_.windows.size())) {
        p["phase"] = "home";
        break;
      }
      // Every slot taken: one more look at the window all the same, since a grasp that
      // closed on nothing leaves its part there and gives its slot back.
      if (p["free_slots"].empty()) {
        if (p.value("verified_full", false)) {
          p["phase"] = "home";
          break;
        }
        p["verified_full"] = true;
      } else {
        p["verified_full"] = false;
      }
      if (auto r = visit_window(w); r) {
        return *r;
      }
    }
    if (p["phase"] == "home") {
      if (spec_.return_home) {
        if (auto r = go_home(); r) {
          return *r;
        }
      }
      p["phase"] = "done";
      if (auto s = run_.step("done"); !s) {
        return ExecResult::failed(s.error().message);
      }
    }
    return ExecResult::done();
  }

 private:
  static std::optional<ExecResult> interrupted(Interrupt i) { return interrupted_result(i); }

  std::optional<ExecResult> journal(const std::string& name, const json& detail = json::object()) {
    run_.set_fraction(fraction());  // parts done of those located (the progress bar)
    if (auto s = run_.step(name, detail); !s) {
      return ExecResult::failed(s.error().message);
    }
    return std::nullopt;
  }

  /// The job's lights before a grab (the thesis switched its lamps on from the program).
  std::optional<ExecResult> switch_lights() {
    using Lights = task::TablePickPlaceSpec::Lights;
    if (spec_.lights == Lights::kKeep) {
      return std::nullopt;
    }
    const std::string robot_id = run_.robot().id();
    const std::vector<std::string> gateway{run_.motion_peers().front()};
    for (int attempt = 0;; ++attempt) {
      if (auto r = interrupted(run_.wait_for_peers(gateway)); r) {
        return r;
      }
      const auto gens = run_.links().peers().generations(gateway);
      cell_robot_RobotCommand c{};
      c.robot_id = bus::borrow(robot_id);
      c.kind = cell_robot_CMD_LIGHTS;
      c.halogen_on = spec_.lights == Lights::kHalogen || spec_.lights == Lights::kBoth;
      c.fluorescent_on = spec_.lights == Lights::kFluorescent || spec_.lights == Lights::kBoth;
      auto s = run_.links().command(c, 5000ms);
      if (s) {
        return std::nullopt;
      }
      // The gateway went away while it was asked: ask its successor (not a reason to fail).
      if (!run_.peers_changed(gateway, gens) || attempt >= 20) {
        return ExecResult::failed(fmt::format("lights: {}", s.error().message));
      }
    }
  }

  /// Sends a motion; robot faults pause the job and return kRetry via `retry`.
  std::optional<ExecResult> move(cell_motion_MotionRequest& r, const std::string& text,
                                 MotionOutcome& out, bool& retry) {
    retry = false;
    auto o = run_.move(r, text);
    if (!o) {
      return ExecResult::failed(o.error().message);
    }
    out = *o;
    if (auto i = interrupted(o->interrupted == Interrupt::kNone ? interrupt_of(run_.control())
                                                                : o->interrupted);
        i) {
      return i;
    }
    if (o->robot_fault) {
      if (auto i = interrupted(run_.pause_for_robot(o->reason)); i) {
        return i;
      }
      if (auto r2 = run_.ready_robot(); r2) {
        return r2;
      }
      retry = true;
    } else if (o->unseen) {
      // Motion or gateway lost or restarted while it ran: the robot is at rest now; a
      // restarted 7545 gateway may have come back unhomed (ready_robot homes it). The caller
      // verifies what the motion did before redoing it.
      if (auto r2 = run_.ready_robot(); r2) {
        return r2;
      }
      retry = true;
    }
    return std::nullopt;
  }

  std::string next_id(const char* what) {
    json& p = run_.progress();
    const int seq = p["seq"].get<int>() + 1;
    p["seq"] = seq;
    return run_.motion_id(fresh_tag(what, seq));
  }

  std::optional<ExecResult> visit_window(int w) {
    json& p = run_.progress();
    const std::vector<double> q = to_std(spec_.windows[static_cast<std::size_t>(w)]);
    for (;;) {
      if (auto r = interrupted(run_.hold_if_paused()); r) {
        return r;
      }
      const std::string id = next_id("w");
      auto request = joints_request(id, q, spec_.speed_scale);
      MotionOutcome o;
      bool retry = false;
      if (auto r = move(request, fmt::format("to image window {}", w + 1), o, retry); r) {
        return r;
      }
      if (retry) {
        continue;
      }
      if (!o.ok()) {
        return ExecResult::failed(fmt::format("image window {}: {}", w + 1, o.reason));
      }
      break;
    }
    if (auto r = switch_lights(); r) {
      return r;
    }
    if (auto r = interrupted(run_.sleep(spec_.settle_s)); r) {
      return r;
    }
    run_.report(fmt::format("locating at window {}", w + 1), fraction());
    const auto timeout =
        std::chrono::milliseconds(static_cast<std::int64_t>(run_.config().locate_timeout_s * 1000));
    Result<Frame> frame = Error{Errc::kProtocol, "not located"};
    // Three real failures skip the window; a try during which the camera or the vision
    // service was lost or restarted does not count (its request may simply be gone): the job
    // waits for them (paused) and asks again.
    const std::vector<std::string> needed = run_.locate_peers(spec_.camera);
    for (int failures = 0, attempt = 0; failures < 3 && attempt < 40; ++attempt) {
      if (auto r = interrupted(run_.wait_for_peers(needed)); r) {
        return r;
      }
      const auto gens = run_.links().peers().generations(needed);
      frame = run_.links().locate(spec_.camera, cell_vision_TRIGGER_NOW, timeout, run_.control());
      if (auto r = interrupted(interrupt_of(run_.control())); r) {
        return r;
      }
      if (frame && frame->error.empty()) {
        break;
      }
      if (run_.peers_changed(needed, gens)) {
        log::warn("job", "locating again: the camera or the vision service was lost or restarted",
                  {{"job", run_.job_id()},
                   {"window", std::to_string(w + 1)},
                   {"error", frame ? frame->error : frame.error().message}});
        continue;
      }
      ++failures;
    }
    if (!frame || !frame->error.empty()) {
      run_.count("locate_failed");
      log::warn("job", "window could not be located; going on with the next",
                {{"job", run_.job_id()},
                 {"window", std::to_string(w + 1)},
                 {"error", frame ? frame->error : frame.error().message}});
      p["window"] = w + 1;
      return journal("window skipped",
                     {{"window", w}, {"error", frame ? frame->error : frame.error().message}});
    }
    // What to pick: parts of the wanted classes with a pose; blocked grips are reported.
    std::vector<Target> targets;
    auto& parts = run_.parts();
    for (const Located& l : frame->parts) {
      if (!spec_.classes.empty() &&
          std::find(spec_.classes.begin(), spec_.classes.end(), l.class_name) ==
              spec_.classes.end()) {
        continue;
      }
      const int known = record_at(parts, l.x_mm, l.y_mm);
      if (known >= 0) {
        PartRecord& rec = parts[static_cast<std::size_t>(known)];
        if (rec.outcome == cell_task_PART_PLACED) {
          // Still here after its pick: the grasp missed. Give its slot back.
          rec.outcome = cell_task_PART_PENDING;
          rec.detail = "missed grasp: the part was still on the table after the pick";
          p["free_slots"].insert(p["free_slots"].begin(), slot_of(rec));
          run_.count("missed_grasps");
        }
        if (rec.outcome != cell_task_PART_PENDING) {
          continue;  // skipped or given up before
        }
        const int tries = p["attempts"].value(std::to_string(known), 0);
        if (tries > spec_.max_retries) {
          rec.outcome = cell_task_PART_MISSED;
          rec.detail = fmt::format("missed {} times", tries);
          continue;
        }
      }
      if (!l.has_pose) {
        run_.count("locate_failed");
        continue;
      }
      Target t;
      t.part = l;
      auto z = grasp_height(run_, spec_, l.class_name, t.symmetry);
      if (!z) {
        add_record(l, cell_task_PART_LOCATE_FAILED,
                   fmt::format("class '{}' has no grasp height", l.class_name));
        continue;
      }
      t.grasp_z_mm = *z;
      if (l.grip == cell_vision_GRIP_BLOCKED) {
        if (known < 0) {
          add_record(l, cell_task_PART_SKIPPED_GRIP_BLOCKED, l.grip_detail);
          run_.count("grip_blocked");
        }
        continue;
      }
      targets.push_back(t);
    }
    if (targets.empty()) {
      p["window"] = w + 1;
      return journal("window done", {{"window", w}, {"found", frame->parts.size()}});
    }
    if (auto r = journal("located", {{"window", w}, {"targets", targets.size()}}); r) {
      return r;
    }
    for (const Target& t : targets) {
      if (p["free_slots"].empty()) {
        break;
      }
      if (auto r = pick_and_place(t); r) {
        return r;
      }
    }
    // Look again: a part still there was missed and is retried; none left ends the window.
    return std::nullopt;
  }

  std::uint32_t slot_of(const PartRecord& rec) const {
    for (std::size_t i = 0; i < spec_.place.slots.size(); ++i) {
      const auto& s = spec_.place.slots[i];
      if (std::hypot(s.x_mm - rec.placed_x_mm, s.y_mm - rec.placed_y_mm) < 1e-6) {
        return static_cast<std::uint32_t>(i);
      }
    }
    return 0;
  }

  int add_record(const Located& l, cell_task_PartOutcome outcome, const std::string& detail) {
    PartRecord rec;
    rec.index = static_cast<std::uint32_t>(run_.parts().size());
    rec.class_name = l.class_name;
    rec.picked_x_mm = l.x_mm;
    rec.picked_y_mm = l.y_mm;
    rec.picked_yaw_rad = l.yaw_rad;
    rec.outcome = outcome;
    rec.detail = detail;
    run_.parts().push_back(rec);
    return static_cast<int>(rec.index);
  }

  std::optional<ExecResult> pick_and_place(const Target& t) {
    json& p = run_.progress();
    auto& parts = run_.parts();
    int index = record_at(parts, t.part.x_mm, t.part.y_mm);
    if (index < 0) {
      index = add_record(t.part, cell_task_PART_PENDING, "");
    }
    const std::uint32_t slot_index = p["free_slots"].front().get<std::uint32_t>();
    const task::Slot& slot = spec_.place.slots[slot_index];
    const double place_z = spec_.place_z_mm.value_or(t.grasp_z_mm);
    std::string why;
    const RobotView v = run_.links().robot(run_.robot().id());
    const auto grip = plan_grip(run_.robot(), t.part, t.grasp_z_mm, slot, place_z, t.symmetry,
                                v.known ? v.q : kinematics::JointVector::Zero(run_.robot().dof()),
                                why);
    PartRecord& rec = parts[static_cast<std::size_t>(index)];
    if (!grip) {
      rec.outcome = cell_task_PART_SKIPPED_UNREACHABLE;
      rec.detail = why;
      run_.count("unreachable");
      return journal("part unreachable", {{"part", index}, {"why", why}});
    }
    p["attempts"][std::to_string(index)] = p["attempts"].value(std::to_string(index), 0) + 1;
    // Intent first: the ids of both motions, so that a restart knows what was sent.
    p["holding"] = {{"stage", "pick"},
                    {"part", index},
                    {"slot", slot_index},
                    {"pick_id", next_id("pick")},
                    {"place_id", next_id("place")},
                    {"pick", pose_json(grip->pick)},
                    {"place", pose_json(grip->place)},
                    {"pick_distance", spec_.travel_z_mm - t.grasp_z_mm},
                    {"place_distance", spec_.travel_z_mm - place_z}};
    if (auto r = journal("picking", {{"part", index}, {"class", rec.class_name}}); r) {
      return r;
    }
    return continue_holding();
  }

  static json pose_json(const Eigen::Isometry3d& pose) {
    const Eigen::Quaterniond q(pose.linear());
    return json{pose.translation().x(), pose.translation().y(), pose.translation().z(),
                q.w(),                  q.x(),                  q.y(),
                q.z()};
  }
  static Eigen::Isometry3d pose_of(const json& j) {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
    pose.translation() = Eigen::Vector3d(j[0].get<double>(), j[1].get<double>(), j[2].get<double>());
    pose.linear() = Eigen::Quaterniond(j[3].get<double>(), j[4].get<double>(), j[5].get<double>(),
                                       j[6].get<double>())
                        .normalized()
                        .toRotationMatrix();
    return pose;
  }

  /// Runs (or, after a restart, finishes) the pick and place held in progress["holding"].
  std::optional<ExecResult> continue_holding() {
    json& p = run_.progress();
    json& h = p["holding"];
    const int index = h["part"].get<int>();
    for (;;) {
      if (auto r = interrupted(run_.hold_if_paused()); r) {
        return r;
      }
      const bool picking = h["stage"] == "pick";
      const std::string id = h[picking ? "pick_id" : "place_id"].get<std::string>();
      cell_motion_MotionRequest r{};
      r.motion_id = bus::borrow(id);
      r.kind = picking ? cell_motion_MOTION_PICK : cell_motion_MOTION_PLACE;
      r.target = geometry::pose_to_idl(pose_of(h[picking ? "pick" : "place"]));
      r.distance_mm = h[picking ? "pick_distance" : "place_distance"].get<double>();
      r.speed_scale = spec_.speed_scale;
      MotionOutcome o;
      bool retry = false;
      const std::string text = fmt::format("{} part {} ({})", picking ? "picking" : "placing",
                                           index + 1, run_.parts()[index].class_name);
      if (auto e = move(r, text, o, retry); e) {
        return e;
      }
      PartRecord& rec = run_.parts()[static_cast<std::size_t>(index)];
      if (retry) {
        // The robot faulted mid-way and was reset. Picking: look again before anything (the
        // part may have moved or be in the gripper). Placing: the part is (or was) held.
        // The same when the motion's outcome was not seen (motion or gateway lost): the
        // gripper tells what the robot did. Pick with the gripper closed: it holds the part
        // (a grasp that closed on nothing is found when the window is looked at again).
        // Place with the gripper open: the part was let go at its slot.
        const RobotView v = run_.links().robot(run_.robot().id());
        const char* why = o.robot_fault ? "a robot fault" : "a lost service";
        if (picking) {
          if (v.gripper == cell_robot_GRIPPER_CLOSED) {
            h["stage"] = "place";
            h["place_id"] = next_id("place");
          } else {
            p["holding"] = nullptr;
            uncount_attempt(index);
            return journal(fmt::format("pick interrupted by {}", why), {{"part", index}});
          }
        } else if (v.gripper == cell_robot_GRIPPER_OPEN) {
          return record_placed(index, fmt::format("placed (seen from the gripper after {})", why));
        } else {
          h["place_id"] = next_id("place");
        }
        if (auto j = journal(fmt::format("resuming after {}", why), {{"part", index}}); j) {
          return j;
        }
        continue;
      }
      if (!o.ok()) {
        // Refused (unreachable after all, a limit) or failed otherwise: report and go on.
        rec.outcome = picking ? cell_task_PART_SKIPPED_UNREACHABLE : cell_task_PART_MISSED;
        rec.detail = o.reason;
        if (!picking) {
          run_.count("place_failed");
        }
        p["holding"] = nullptr;
        return journal(picking ? "pick refused" : "place failed", {{"part", index},
                                                                    {"why", o.reason}});
      }
      if (picking) {
        h["stage"] = "place";
        if (auto j = journal("picked", {{"part", index}}); j) {
          return j;
        }
        continue;
      }
      return record_placed(index, "placed");
    }
  }

  /// The part of progress["holding"] is in its slot: record it, take the slot, journal.
  std::optional<ExecResult> record_placed(int index, const std::string& step) {
    json& p = run_.progress();
    json& h = p["holding"];
    PartRecord& rec = run_.parts()[static_cast<std::size_t>(index)];
    const std::uint32_t slot_index = h["slot"].get<std::uint32_t>();
    const task::Slot& slot = spec_.place.slots[slot_index];
    rec.outcome = cell_task_PART_PLACED;
    rec.detail.clear();
    rec.placed_x_mm = slot.x_mm;
    rec.placed_y_mm = slot.y_mm;
    rec.placed_yaw_rad = slot.yaw_rad;
    auto& free = p["free_slots"];
    for (auto it = free.begin(); it != free.end(); ++it) {
      if (it->get<std::uint32_t>() == slot_index) {
        free.erase(it);
        break;
      }
    }
    p["holding"] = nullptr;
    run_.count("placed");
    return journal(step, {{"part", index}, {"slot", slot_index}});
  }

  /// A pick that was interrupted (fault, lost service, restart) is not a missed grasp: it does
  /// not use up one of the part's retries.
  void uncount_attempt(int index) {
    json& attempts = run_.progress()["attempts"];
    const std::string key = std::to_string(index);
    const int tries = attempts.value(key, 0);
    if (tries > 0) {
      attempts[key] = tries - 1;
    }
  }

  /// After a restart: what became of the pick or place the journal says was under way.
  std::optional<ExecResult> resolve_holding() {
    json& p = run_.progress();
    if (p["holding"].is_null()) {
      return std::nullopt;
    }
    json& h = p["holding"];
    const bool picking = h["stage"] == "pick";
    const std::string id = h[picking ? "pick_id" : "place_id"].get<std::string>();
    const auto status = run_.links().motion_status(id, 2000ms);
    log::info("job", "resuming an interrupted pick/place",
              {{"job", run_.job_id()},
               {"stage", h["stage"].get<std::string>()},
               {"motion", id},
               {"status", status ? std::to_string(static_cast<int>(status->state)) : "none"}});
    if (status && status->state == cell_motion_MOTION_DONE) {
      if (picking) {
        h["stage"] = "place";  // picked before the restart: place it
        return continue_holding();
      }
      // Placed before the restart: record it as placed.
      return record_placed(h["part"].get<int>(), "placed (before the restart)");
    }
    const RobotView v = run_.links().robot(run_.robot().id());
    if (!picking) {
      // No status (a motion service restarted too): the gripper tells. Closed: the part is
      // still held, place it; open: it was let go at its slot (ready_robot waited for rest).
      if (v.gripper == cell_robot_GRIPPER_CLOSED) {
        h["place_id"] = next_id("place");
        return continue_holding();
      }
      if (v.gripper == cell_robot_GRIPPER_OPEN) {
        return record_placed(h["part"].get<int>(), "placed (seen from the gripper after a restart)");
      }
    } else if (!status && v.gripper == cell_robot_GRIPPER_CLOSED) {
      // No status, gripper closed: the pick ran to its end before the motion service's
      // history was lost; place what it holds.
      h["stage"] = "place";
      h["place_id"] = next_id("place");
      return continue_holding();
    }
    // The pick never ran (or failed): forget it; the window is looked at again.
    uncount_attempt(h["part"].get<int>());
    p["holding"] = nullptr;
    return journal("interrupted pick dropped; looking again", {{"motion", id}});
  }

  std::optional<ExecResult> go_home() {
    const RobotView v = run_.links().robot(run_.robot().id());
    std::vector<std::vector<double>> legs;
    if (v.known && run_.robot().kind() == kinematics::RobotKind::kScara) {
      // The thesis: Z to 0 first, then every joint to 0.
      std::vector<double> up = to_std(v.q);
      up[2] = 0.0;
      legs.push_back(up);
    }
    legs.push_back(std::vector<double>(static_cast<std::size_t>(run_.robot().dof()), 0.0));
    for (const auto& q : legs) {
      for (;;) {
        const std::string id = next_id("home");
        auto r = joints_request(id, q, spec_.speed_scale);
        MotionOutcome o;
        bool retry = false;
        if (auto e = move(r, "returning home", o, retry); e) {
          return e;
        }
        if (retry) {
          continue;
        }
        if (!o.ok()) {
          return ExecResult::failed(fmt::format("return home: {}", o.reason));
        }
        break;
      }
    }
    return std::nullopt;
  }

  double fraction() const {
    const auto& parts = run_.parts();
    if (parts.empty()) {
      return 0.0;
    }
    std::size_t done = 0;
    for (const auto& rec : parts) {
      done += rec.outcome != cell_task_PART_PENDING ? 1 : 0;
    }
    return static_cast<double>(done) / static_cast<double>(parts.size());
  }

  JobRun& run_;
  const task::TablePickPlaceSpec& spec_;
};

}  // namespace

ExecResult run_table_job(JobRun& run) { return TableJob(run).run(); }

}  // namespace cell::task_service
