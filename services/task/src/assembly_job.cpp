// The assembly job (issue 9, kind 3): a RAPT program (core/rapt, Yin 1984) run by a robot.
//
// The program is compiled when the job is checked and again when it runs. The executor walks
// its situations in order. A vision package is measured when the robot has reached it: one
// image of each camera it uses, one EdgeRequest per LOOK the package's route uses, each window
// predicted at FM * PN of the situation before (thesis §7.7), everything before it corrected.
// A MOVE/TURN is executed as the agent's actual motion (7.13) in one step, or in two (7.15,
// 7.17-7.18), as the job's method says; TIED/UNTIED with the agent close and open the gripper
// after the motion into their situation. Every completed situation is journaled with the
// readings taken so far, so a restarted service resumes at the next situation with the same
// corrections (it does not look again at what it has measured: the bodies it measured have
// not moved unless the robot moved them, and those moves are in the MF array).
//
// Frames: W is the program's world; base_T_world (the job) places it in the robot's base frame;
// a cell camera's calibration gives base_T_camera (its z the optical axis, x right, y down). A
// RAPT camera's frame has X along the lens axis (core/rapt camera.hpp); the executor replaces
// each program camera's declared pose by its cell camera's calibrated one, with the RAPT axes
// X_c = z, Y_c = x, Z_c = y of the cell camera, so that a RAPT image point (y, z) is F times
// the cell camera's normalised ideal coordinates (x/z, y/z).

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>
#include <set>

#include <fmt/format.h>

#include "cell/bus/view.hpp"
#include "cell/calibration/camera_calibration.hpp"
#include "cell/common/log.hpp"
#include "cell/geometry/idl_pose.hpp"
#include "cell/rapt/compiler.hpp"
#include "cell/rapt/runtime.hpp"
#include "cell/render/camera_model.hpp"
#include "cell/service/paths.hpp"
#include "job_run.hpp"

namespace cell::task_service {
namespace {

using namespace std::chrono_literals;
using nlohmann::json;
using rapt::ImagePoint;
using rapt::Pose;

constexpr double kRadToDeg = 180.0 / std::numbers::pi;


/// The RAPT camera axes in the cell camera's frame: X_c (lens) = z, Y_c = x, Z_c = y.
Eigen::Isometry3d cellcam_T_raptcam() {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.linear().col(0) = Eigen::Vector3d::UnitZ();
  t.linear().col(1) = Eigen::Vector3d::UnitX();
  t.linear().col(2) = Eigen::Vector3d::UnitY();
  return t;
}

/// Compiles the job's program (its file relative to CELL_HOME, or its inline text).
Result<rapt::CompiledProgram> compile_program(const task::AssemblySpec& spec) {
  rapt::Diagnostics diags;
  if (!spec.program_path.empty()) {
    return rapt::compile_file(service::resolve_path(spec.program_path), diags);
  }
  return rapt::compile(spec.program_text, "source", diags);
}

/// The agent body's number (the spec's, or the program's only AGENT). 0 and `why` otherwise.
int agent_of(const task::AssemblySpec& spec, const rapt::Program& program, std::string& why) {
  if (spec.agent.empty()) {
    if (program.agents.size() == 1) {
      return program.agents.front();
    }
    why = fmt::format("the program has {} AGENT bodies: name the robot's with agent:",
                      program.agents.size());
    return 0;
  }
  const int b = program.find_body(spec.agent);
  if (b == 0) {
    why = fmt::format("agent '{}' is not a body of the program", spec.agent);
    return 0;
  }
  if (std::find(program.agents.begin(), program.agents.end(), b) == program.agents.end()) {
    why = fmt::format("agent '{}' is not declared AGENT in the program", spec.agent);
    return 0;
  }
  return b;
}

/// Everything check_assembly verifies, collected. `cp` is the compiled program on success.
std::vector<std::string> assembly_problems(const task::AssemblySpec& spec,
                                           const kinematics::RobotModel& robot,
                                           std::optional<rapt::CompiledProgram>& cp_out,
                                           int& agent) {
  std::vector<std::string> why;
  auto cp = compile_program(spec);
  if (!cp) {
    for (const auto& line : split_lines(cp.error().message)) {
      why.push_back("program: " + line);
    }
    return why;
  }
  const rapt::Program& program = cp->program;
  std::string reason;
  agent = agent_of(spec, program, reason);
  if (agent == 0) {
    why.push_back(reason);
    return why;
  }
  for (int s = 2; s <= program.situation_count(); ++s) {
    const auto& moved = program.moved[static_cast<std::size_t>(s - 1)];
    if (!moved.empty() && std::find(moved.begin(), moved.end(), agent) == moved.end()) {
      why.push_back(fmt::format(
          "{}:{}: the action into situation {} does not move the agent '{}' (the robot can only "
          "move what its gripper holds)",
          program.file, rapt::to_string(program.situation(s).action.loc), s,
          program.body(agent).name));
    }
  }
  std::set<std::string> named;
  for (const rapt::CompiledPackage& pkg : cp->packages) {
    for (const rapt::CompiledLook& look : pkg.looks) {
      const rapt::Camera& cam = program.cameras[static_cast<std::size_t>(look.decl.camera)];
      if (!named.insert(cam.name).second) {
        continue;
      }
      if (cam.general) {
        why.push_back(fmt::format("camera '{}': only immovable cameras (CAMERA/POSITION) are "
                                  "supported by the cell",
                                  cam.name));
      }
      if (!spec.cameras.contains(cam.name)) {
        why.push_back(fmt::format("camera '{}' of the program has no cell camera: add "
                                  "cameras: {{{}: <camera id>}}",
                                  cam.name, cam.name));
      }
    }
  }
  for (const auto& [name, id] : spec.cameras) {
    if (!named.contains(name)) {
      bool declared = false;
      for (const auto& c : program.cameras) {
        declared = declared || c.name == name;
      }
      if (!declared) {
        why.push_back(fmt::format("cameras: '{}' is not a camera of the program", name));
      }
    }
  }
  // The agent's nominal tool pose in every situation: inside the robot's limits.
  std::optional<kinematics::JointVector> seed;
  for (int s = 1; s <= program.situation_count(); ++s) {
    const Eigen::Isometry3d target =
        spec.base_T_world * cp->nominal_pose(agent, s) * spec.agent_T_tool;
    const Eigen::Vector3d t = target.translation();
    if (auto ok = robot.cartesian_limits().check(t); !ok) {
      why.push_back(fmt::format("situation {}: the tool at ({:.1f}, {:.1f}, {:.1f}) mm: {}", s,
                                t.x(), t.y(), t.z(), ok.error().message));
      continue;
    }
    auto q = robot.inverse(target, seed ? *seed : kinematics::JointVector::Zero(robot.dof()));
    if (!q) {
      why.push_back(fmt::format("situation {}: the tool at ({:.1f}, {:.1f}, {:.1f}) mm is out "
                                "of reach: {}",
                                s, t.x(), t.y(), t.z(), q.error().message));
      continue;
    }
    seed = *q;
  }
  cp_out = std::move(*cp);
  return why;
}

json to_json(const rapt::Reading& r) {
  return {{"situation", r.situation}, {"body", r.body},       {"edge", r.edge},
          {"camera", r.camera},       {"p1", {r.p1.x(), r.p1.y()}}, {"p2", {r.p2.x(), r.p2.y()}}};
}

rapt::Reading reading_from_json(const json& j) {
  rapt::Reading r;
  r.situation = j.at("situation").get<int>();
  r.body = j.at("body").get<std::string>();
  r.edge = j.at("edge").get<std::string>();
  r.camera = j.at("camera").get<std::string>();
  r.p1 = ImagePoint(j.at("p1")[0].get<double>(), j.at("p1")[1].get<double>());
  r.p2 = ImagePoint(j.at("p2")[0].get<double>(), j.at("p2")[1].get<double>());
  r.where = fmt::format("journal (situation {})", r.situation);
  return r;
}

/// A cell camera as the executor uses it: its lens and the RAPT camera it stands for.
struct CellCamera {
  std::string id;
  render::CameraModel lens;
  Eigen::Isometry3d world_T_camera = Eigen::Isometry3d::Identity();  ///< cell axes, in W
  std::string version;
};

class AssemblyJob {
 public:
  explicit AssemblyJob(JobRun& run)
      : run_(run),
        spec_(*run.spec().assembly()),
        edge_requests_(run.links().participant(), bus::topics::kEdgeRequest,
                       bus::topics::kEdgeResult, run.links().client_id() + ".edges"),
        calibration_topic_(run.links().participant(), bus::topics::kCameraCalibration),
        calibrations_(run.links().participant(), calibration_topic_,
                      bus::topics::kCameraCalibration) {}

  ExecResult run() {
    std::optional<rapt::CompiledProgram> cp;
    const auto problems = assembly_problems(spec_, run_.robot(), cp, agent_);
    if (!problems.empty()) {
      std::string all;
      for (const auto& p : problems) {
        all += (all.empty() ? "" : "; ") + p;
      }
      return ExecResult::failed(all);
    }
    cp_ = std::move(*cp);
    const rapt::Program& program = cp_.program;
    json& p = run_.progress();
    if (!p.contains("situation")) {
      p["situation"] = 0;
      p["readings"] = json::array();
      p["seq"] = 0;
    }
    for (const auto& r : p["readings"]) {
      readings_.push_back(reading_from_json(r));
    }
    if (auto e = interrupted_result(run_.hold_if_paused()); e) {
      return *e;
    }
    if (auto r = run_.ready_robot(); r) {
      return *r;
    }
    if (auto e = cameras(); e) {
      return *e;
    }
    const int total = program.situation_count();
    int s = std::max(1, p["situation"].get<int>() + 1);
    while (s <= total) {
      if (auto e = interrupted_result(run_.hold_if_paused()); e) {
        return *e;
      }
      const rapt::Action& action = program.situation(s).action;
      run_.report(fmt::format("situation {} of {}", s, total),
                  static_cast<double>(s - 1) / static_cast<double>(total));
      std::optional<ExecResult> e;
      std::string done;
      if (s == 1) {
        e = start_pose();
        done = "start pose";
      } else if (action.kind == rapt::ActionKind::kVision) {
        e = verify(s, action.package);
        done = fmt::format("verified {}", program.body(action.body).name);
      } else {
        e = act(s);
        done = fmt::format("{} {}", action.kind == rapt::ActionKind::kTurn ? "turned" : "moved",
                           program.body(action.body).name);
      }
      if (e) {
        return *e;
      }
      // The first move after a grasp: where a camera saw the body, look that it left.
      if (s > 1 && action.kind != rapt::ActionKind::kVision) {
        int redo = 0;
        if (auto g = check_grasp(s - 1, redo); g) {
          return *g;
        }
        if (redo > 0) {
          s = redo;
          continue;
        }
      }
      if (auto g = grip(s); g) {
        return *g;
      }
      if (auto st = journal(s, fmt::format("situation {} of {}: {}", s, total, done)); st) {
        return *st;
      }
      ++s;
    }
    record_results();
    if (auto st = run_.step("assembled"); !st) {
      return ExecResult::failed("journal: " + st.error().message);
    }
    return ExecResult::done();
  }

 private:
  /// Journals situation s as done, with the readings so far.
  std::optional<ExecResult> journal(int s, const std::string& text) {
    json& p = run_.progress();
    p["situation"] = s;
    json readings = json::array();
    for (const auto& r : readings_) {
      readings.push_back(to_json(r));
    }
    p["readings"] = std::move(readings);
    run_.count("situations");
    if (auto st = run_.step(text, {{"situation", s}}); !st) {
      return ExecResult::failed("journal: " + st.error().message);
    }
    return std::nullopt;
  }

  /// After the first move following a TIED of the agent in situation `grasped`: when a vision
  /// package verified the tied body before, its first LOOK's edge is looked for again where it
  /// was. Still there: the grasp missed. The gripper opens and, within max_retries, `redo` is
  /// set to that package's situation (its readings dropped: the body is measured again and
  /// taken again); beyond, the job fails naming the body.
  std::optional<ExecResult> check_grasp(int grasped, int& redo) {
    redo = 0;
    const rapt::Program& program = cp_.program;
    for (const rapt::TieChange& t : program.situation(grasped).tie_changes) {
      if (!t.tied || (t.a != agent_ && t.b != agent_)) {
        continue;
      }
      const int body = t.a == agent_ ? t.b : t.a;
      const rapt::CompiledPackage* pkg = nullptr;
      for (const auto& candidate : cp_.packages) {
        if (candidate.body == body && candidate.fixable && candidate.situation < grasped) {
          pkg = &candidate;
        }
      }
      if (pkg == nullptr) {
        continue;  // no camera saw it: the gripper's state is all there is
      }
      auto still = still_there(*pkg, grasped);
      if (!still) {
        log::warn("assembly_grasp",
                  fmt::format("could not look whether {} left: {}", program.body(body).name,
                              still.error().message),
                  {{"job", run_.job_id()}});
        continue;
      }
      if (!*still) {
        run_.count("grasps_verified");
        continue;
      }
      run_.count("grasp_missed");
      const int misses = static_cast<int>(run_.counters().at("grasp_missed"));
      log::warn("assembly_grasp",
                fmt::format("situation {}: the gripper did not take {}: it is still where it "
                            "was (miss {} of at most {})",
                            grasped, program.body(body).name, misses, spec_.max_retries + 1),
                {{"job", run_.job_id()}});
      if (auto e = gripper(false); e) {
        return e;
      }
      if (misses > spec_.max_retries) {
        return ExecResult::failed(fmt::format(
            "the grasp of {} in situation {} missed {} times: it stays where it was",
            program.body(body).name, grasped, misses));
      }
      std::erase_if(readings_, [&](const rapt::Reading& r) { return r.situation >= pkg->situation; });
      redo = pkg->situation;
      return journal(pkg->situation - 1, fmt::format("grasp of {} missed: measuring it again",
                                                     program.body(body).name));
    }
    return std::nullopt;
  }

  /// Whether the first used LOOK of `pkg` still finds its edge (within the package's
  /// tolerance) where the program put the body before the grasp.
  Result<bool> still_there(const rapt::CompiledPackage& pkg, int grasped) {
    auto rr = evaluate(grasped);
    if (!rr) {
      return rr.error();
    }
    for (const rapt::CompiledLook& look : pkg.looks) {
      if (!look.used) {
        continue;
      }
      const LookGeometry g = geometry_of(look);
      const CellCamera& cell = g.cell;
      const rapt::CameraModel& model = g.model;
      const Eigen::Vector3d& e1 = g.e1;
      const Eigen::Vector3d& e2 = g.e2;
      const Pose at = rr->actual_pose(pkg.body, grasped);
      auto i1 = model.project(at * e1);
      auto i2 = model.project(at * e2);
      if (!i1 || !i2) {
        return (!i1 ? i1 : i2).error();
      }
      // A fresh image, the package's own window: an edge found there is the body's, still in
      // its place (a body taken away leaves the table's plain surface).
      std::map<std::string, std::uint64_t> images;
      auto m = measure(grasped, cell, model, at * e1, at * e2, *i1, *i2, pkg, images);
      if (!m) {
        if (m.error().code == Errc::kOutOfRange) {
          return false;  // no edge there: it left
        }
        return m.error();
      }
      return true;
    }
    return false;
  }

  /// The calibrated model of every cell camera the program uses; each program camera's pose
  /// replaced by its camera's (after checking they agree within the job's tolerance).
  std::optional<ExecResult> cameras() {
    rapt::Program& program = cp_.program;
    for (auto& cam : program.cameras) {
      const auto it = spec_.cameras.find(cam.name);
      if (it == spec_.cameras.end()) {
        continue;
      }
      auto c = calibration_of(it->second);
      if (!c) {
        return ExecResult::failed(fmt::format("camera '{}' ({}): {}", cam.name, it->second,
                                              c.error().message));
      }
      const Eigen::Isometry3d world_T_rapt = c->world_T_camera * cellcam_T_raptcam();
      const double off_mm =
          (world_T_rapt.translation() - cam.world_T_camera.translation()).norm();
      const double off_deg =
          std::acos(std::clamp(world_T_rapt.linear().col(0).dot(cam.world_T_camera.linear().col(0)),
                               -1.0, 1.0)) *
          kRadToDeg;
      if (off_mm > spec_.camera_tolerance_mm || off_deg > spec_.camera_tolerance_deg) {
        return ExecResult::failed(fmt::format(
            "camera '{}' is declared {:.1f} mm and {:.1f} deg (lens axis) from camera '{}' as "
            "calibrated ({}): beyond the job's camera_tolerance ({} mm, {} deg)",
            cam.name, off_mm, off_deg, it->second, c->version, spec_.camera_tolerance_mm,
            spec_.camera_tolerance_deg));
      }
      log::info("assembly_camera",
                fmt::format("program camera {} is {} ({}), {:.1f} mm / {:.2f} deg from its "
                            "declared pose",
                            cam.name, it->second, c->version, off_mm, off_deg),
                {{"job", run_.job_id()}});
      cam.world_T_camera = world_T_rapt;
      cells_[cam.name] = std::move(*c);
    }
    return std::nullopt;
  }

  /// The newest CameraCalibration of `camera_id` (transient-local: waits for it to arrive).
  Result<CellCamera> calibration_of(const std::string& camera_id) {
    const auto deadline = Clock::now() + 5s;
    std::optional<calibration::CameraCalibration> found;
    for (;;) {
      auto batch = calibrations_.take_copies(16);
      if (batch) {
        for (const auto& sample : *batch) {
          auto c = calibration::from_idl(sample.get());
          if (c && c->camera_id == camera_id) {
            found = std::move(*c);
          }
        }
      }
      if (found || Clock::now() >= deadline || run_.control().interrupted()) {
        break;
      }
      (void)calibrations_.wait_for_data(100ms);
    }
    if (!found) {
      return Error{Errc::kNotReady,
                   "no calibration published on cell/calibration/camera within 5 s (calibrate "
                   "it: cellctl calibrate)"};
    }
    if (found->mounting != calibration::Mounting::kFixed) {
      return Error{Errc::kInvalidArgument, "is not a fixed camera"};
    }
    if (found->robot_id != run_.robot().id()) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("is calibrated to the base of '{}', not of '{}'", found->robot_id,
                               run_.robot().id())};
    }
    auto lens = found->camera_model();
    if (!lens) {
      return lens.error();
    }
    CellCamera c;
    c.id = camera_id;
    c.lens = *lens;
    c.world_T_camera = spec_.base_T_world.inverse() * found->extrinsics;
    c.version = found->version.empty() ? found->source : found->version;
    return c;
  }

  std::string next_id(const char* what) {
    json& p = run_.progress();
    const int seq = p["seq"].get<int>() + 1;
    p["seq"] = seq;
    return run_.motion_id(fresh_tag(what, seq));
  }

  /// A motion of the tool to `target` (base frame): `linear` a straight line, else joint
  /// interpolated. Robot faults pause the job and the motion is sent again after the reset.
  std::optional<ExecResult> move_tool(const Eigen::Isometry3d& target, bool linear,
                                      const std::string& text) {
    for (;;) {
      cell_motion_MotionRequest r{};
      const std::string id = next_id(linear ? "line" : "pose");
      r.motion_id = bus::borrow(id);
      r.kind = linear ? cell_motion_MOTION_MOVE_LINEAR : cell_motion_MOTION_MOVE_POSE;
      r.target = geometry::pose_to_idl(target);
      r.speed_scale = spec_.speed_scale;
      auto o = run_.move(r, text);
      if (!o) {
        return ExecResult::failed(o.error().message);
      }
      if (auto i = interrupted_result(o->interrupted == Interrupt::kNone
                                          ? interrupt_of(run_.control())
                                          : o->interrupted);
          i) {
        return i;
      }
      if (o->robot_fault) {
        if (auto i = interrupted_result(run_.pause_for_robot(o->reason)); i) {
          return i;
        }
        if (auto r2 = run_.ready_robot(); r2) {
          return r2;
        }
        continue;  // an absolute target: sending it again is the recovery
      }
      if (o->unseen) {
        if (auto r2 = run_.ready_robot(); r2) {
          return r2;
        }
        continue;
      }
      if (!o->ok()) {
        return ExecResult::failed(fmt::format("{}: {}", text, o->reason));
      }
      return std::nullopt;
    }
  }

  Eigen::Isometry3d tool_of(const Pose& world_T_agent) const {
    return spec_.base_T_world * world_T_agent * spec_.agent_T_tool;
  }

  /// Runs the program through situation `s` with the readings so far.
  Result<rapt::RunResult> evaluate(int s) {
    rapt::RunOptions options;
    options.through_situation = s;
    return rapt::run(cp_, readings_, options);
  }

  std::optional<ExecResult> start_pose() {
    const Pose& pn = cp_.nominal_pose(agent_, 1);
    if (auto e = move_tool(tool_of(pn), false, "to the program's start pose"); e) {
      return e;
    }
    return std::nullopt;
  }

  /// The move into situation s: the agent's path by the job's method.
  std::optional<ExecResult> act(int s) {
    auto rr = evaluate(s);
    if (!rr) {
      return ExecResult::failed(fmt::format("situation {}: {}", s, rr.error().message));
    }
    const rapt::ActionOutcome* action = nullptr;
    for (const auto& a : rr->actions) {
      if (a.situation == s) {
        action = &a;
      }
    }
    const Pose before = rr->actual_pose(agent_, s - 1);
    const Pose after = rr->actual_pose(agent_, s);
    std::vector<Pose> path;
    if (action != nullptr && spec_.method == task::AssemblySpec::Method::kTwoStepWorld) {
      path.push_back(action->correction * before);  // TC first (7.15), then TN
    } else if (action != nullptr &&
               spec_.method == task::AssemblySpec::Method::kTwoStepDestination) {
      path.push_back(action->step1 * before);  // Ta1 to PN' (7.17), then Ta2
    }
    path.push_back(after);
    const std::string name = cp_.program.body(cp_.program.situation(s).action.body).name;
    for (std::size_t k = 0; k < path.size(); ++k) {
      const std::string text =
          fmt::format("situation {}: moving {}{}", s, name,
                      path.size() > 1 ? fmt::format(" (step {} of {})", k + 1, path.size()) : "");
      if (auto e = move_tool(tool_of(path[k]), true, text); e) {
        return e;
      }
    }
    return std::nullopt;
  }

  /// TIED / UNTIED of the agent declared in situation s: close or open the gripper.
  std::optional<ExecResult> grip(int s) {
    for (const rapt::TieChange& t : cp_.program.situation(s).tie_changes) {
      if (t.a != agent_ && t.b != agent_) {
        continue;
      }
      const int other = t.a == agent_ ? t.b : t.a;
      run_.report(fmt::format("situation {}: {} {}", s, t.tied ? "gripping" : "letting go of",
                              cp_.program.body(other).name),
                  run_.fraction());
      if (auto e = gripper(t.tied); e) {
        return ExecResult::failed(fmt::format("situation {}: {}", s, e->reason));
      }
    }
    return std::nullopt;
  }

  /// Closes or opens the gripper and waits until the gateway reports it so.
  std::optional<ExecResult> gripper(bool close) {
    const std::string& robot = run_.robot().id();
    const auto want = close ? cell_robot_GRIPPER_CLOSED : cell_robot_GRIPPER_OPEN;
    if (auto st = run_.links().command(
            robot, close ? cell_robot_CMD_GRIPPER_CLOSE : cell_robot_CMD_GRIPPER_OPEN, 5000ms);
        !st) {
      return ExecResult::failed("gripper: " + st.error().message);
    }
    if (!run_.links().wait_robot(robot, [&](const RobotView& v) { return v.gripper == want; },
                                 5000ms, run_.control())) {
      if (auto i = interrupted_result(interrupt_of(run_.control())); i) {
        return i;
      }
      return ExecResult::failed(
          fmt::format("the gripper did not {} within 5 s", close ? "close" : "open"));
    }
    return std::nullopt;
  }

  /// A LOOK's camera (program and cell) and the end points of its edge in the body frame.
  struct LookGeometry {
    const rapt::Camera& cam;
    const CellCamera& cell;
    rapt::CameraModel model;
    const rapt::Feature& edge;
    Eigen::Vector3d e1;
    Eigen::Vector3d e2;
  };
  LookGeometry geometry_of(const rapt::CompiledLook& look) const {
    const rapt::Program& program = cp_.program;
    const rapt::Camera& cam = program.cameras[static_cast<std::size_t>(look.decl.camera)];
    const rapt::Feature& edge = program.feature(look.decl.edge);
    const auto [e1, e2] = edge.edge_end_points();
    return {cam, cells_.at(cam.name), rapt::CameraModel{cam.world_T_camera, cam.focus}, edge,
            e1, e2};
  }

  /// RAPT image point -> pixel of a cell camera; nullopt outside the lens's valid field.
  std::optional<Eigen::Vector2d> to_pixel(const CellCamera& c, double focus,
                                          const ImagePoint& p) const {
    const Eigen::Vector2d ideal = p / focus;
    if (!(ideal.norm() < c.lens.max_ideal_radius())) {
      return std::nullopt;
    }
    return c.lens.project_normalised(ideal);
  }

  /// The vision package of situation s: one image per camera, one edge per used LOOK.
  std::optional<ExecResult> verify(int s, int package) {
    const rapt::CompiledPackage& pkg = cp_.packages.at(static_cast<std::size_t>(package));
    const rapt::Program& program = cp_.program;
    const std::string body = program.body(pkg.body).name;
    if (!pkg.fixable) {
      log::warn("assembly_package",
                fmt::format("situation {}: the package cannot fix {} ({}): not measured", s,
                            body, pkg.cannot_fix),
                {{"job", run_.job_id()}});
      return std::nullopt;
    }
    auto rr = evaluate(s - 1);
    if (!rr) {
      return ExecResult::failed(fmt::format("situation {}: {}", s, rr.error().message));
    }
    const Pose body_before = rr->actual_pose(pkg.body, s - 1);
    std::map<std::string, std::uint64_t> images;  // cell camera id -> image sequence
    std::vector<rapt::Reading> taken;
    for (const rapt::CompiledLook& look : pkg.looks) {
      if (!look.used) {
        continue;
      }
      const LookGeometry g = geometry_of(look);
      const rapt::Camera& cam = g.cam;
      const CellCamera& cell = g.cell;
      const rapt::CameraModel& model = g.model;
      const rapt::Feature& edge = g.edge;
      const Eigen::Vector3d& e1 = g.e1;
      const Eigen::Vector3d& e2 = g.e2;
      const Eigen::Vector3d q1 = body_before * e1;
      const Eigen::Vector3d q2 = body_before * e2;
      auto i1 = model.project(q1);
      auto i2 = model.project(q2);
      if (!i1 || !i2) {
        return ExecResult::failed(fmt::format("situation {}: LOOK {} of {}: {}", s, edge.name,
                                              body, (!i1 ? i1 : i2).error().message));
      }
      rapt::Reading reading;
      reading.situation = s;
      reading.body = body;
      reading.edge = edge.name;
      reading.camera = cam.name;
      if (spec_.verify) {
        auto measured = measure(s, cell, model, q1, q2, *i1, *i2, pkg, images);
        if (!measured) {
          return ExecResult::failed(fmt::format(
              "situation {}: LOOK {} of {} with {} ({}, calibration {}): {}", s, edge.name, body,
              cam.name, cell.id, cell.version, measured.error().message));
        }
        reading.p1 = measured->first;
        reading.p2 = measured->second;
        run_.count("looks");
      } else {
        reading.p1 = *i1;  // not measured: the edge where the program expects it
        reading.p2 = *i2;
      }
      reading.where = fmt::format("{} image {}", cell.id, images[cell.id]);
      taken.push_back(reading);
    }
    readings_.insert(readings_.end(), taken.begin(), taken.end());
    auto check = evaluate(s);
    if (!check) {
      readings_.resize(readings_.size() - taken.size());
      return ExecResult::failed(fmt::format("situation {}: {}", s, check.error().message));
    }
    const Pose fm = check->fm_of(pkg.body, s);
    log::info("assembly_verified",
              fmt::format("situation {}: {} is {:.2f} mm and {:.2f} deg from its nominal "
                          "position{}",
                          s, body, (check->actual_pose(pkg.body, s).translation() -
                                    cp_.nominal_pose(pkg.body, s).translation())
                                       .norm(),
                          Eigen::AngleAxisd(fm.linear()).angle() * kRadToDeg,
                          spec_.verify ? "" : " (not measured: verify is off)"),
              {{"job", run_.job_id()}});
    return std::nullopt;
  }

  /// One LOOK: the image (taken once per camera and package), the EdgeRequest, and the
  /// measured end points as RAPT image points.
  Result<std::pair<ImagePoint, ImagePoint>> measure(int s, const CellCamera& cell,
                                                     const rapt::CameraModel& model,
                                                     const Eigen::Vector3d& q1,
                                                     const Eigen::Vector3d& q2,
                                                     const ImagePoint& i1, const ImagePoint& i2,
                                                     const rapt::CompiledPackage& pkg,
                                                     std::map<std::string, std::uint64_t>& images) {
    if (!images.contains(cell.id)) {
      if (run_.wait_for_peers(run_.locate_peers(cell.id)) != Interrupt::kNone) {
        return Error{Errc::kNotReady, "interrupted"};
      }
      run_.report(fmt::format("situation {}: image from {}", s, cell.id), run_.fraction());
      auto frame = run_.links().locate(cell.id, cell_vision_TRIGGER_NOW,
                                       std::chrono::milliseconds(static_cast<int>(
                                           run_.config().locate_timeout_s * 1000)),
                                       run_.control());
      if (!frame) {
        return frame.error();
      }
      images[cell.id] = frame->image_sequence;
    }
    // The window: across the predicted edge, as wide as the package's tolerance projected
    // into the image (thesis §5.7.1); the vision service cuts the same tolerance off each end
    // so that the corners next to the edge stay out.
    auto window = rapt::suggest_window(model, q1, q2, pkg.combined_tolerance_mm);
    if (!window) {
      return window.error();
    }
    auto pa = to_pixel(cell, model.focus, i1);
    auto pb = to_pixel(cell, model.focus, i2);
    if (!pa || !pb) {
      return Error{Errc::kInvalidArgument, "the predicted edge is outside the camera's field"};
    }
    const double px_per_unit = cell.lens.fx_px() / model.focus;
    cell_vision_EdgeRequest request{};
    request.camera_id = bus::borrow(cell.id);
    request.predicted_start_px = {pa->x(), pa->y()};
    request.predicted_end_px = {pb->x(), pb->y()};
    request.search_halfwidth_px = std::max(4.0, window->half_width * px_per_unit);
    request.image_sequence = images[cell.id];
    auto seq = edge_requests_.send(request, 3000ms);
    if (!seq) {
      return Error{Errc::kProtocol, "vision service: " + seq.error().message};
    }
    auto reply = edge_requests_.wait_reply(
        *seq, Clock::now() + std::chrono::milliseconds(
                                 static_cast<int>(run_.config().locate_timeout_s * 1000)));
    if (!reply) {
      return Error{Errc::kProtocol, "no EdgeResult: " + reply.error().message};
    }
    const cell_vision_EdgeResult& r = reply->get();
    if (!r.status.accepted) {
      // out_of_range: no edge in the window (the finder's verdict); anything else: a failure.
      const bool none = std::string_view(bus::str(r.status.error_code)) == "out_of_range";
      return Error{none ? Errc::kOutOfRange : Errc::kProtocol,
                   std::string(bus::str(r.status.reason))};
    }
    std::array<ImagePoint, 2> out;
    const std::array<cell_vision_PixelPoint, 2> px{r.start_px, r.end_px};
    for (std::size_t k = 0; k < 2; ++k) {
      auto ray = cell.lens.unproject({px[k].u_px, px[k].v_px});
      if (!ray) {
        return ray.error();
      }
      out[k] = ImagePoint(ray->x(), ray->y()) * model.focus;  // y = F x/z, z = F y/z
    }
    // Keep the predicted direction (the edge's origin first).
    if ((out[1] - out[0]).dot(i2 - i1) < 0) {
      std::swap(out[0], out[1]);
    }
    log::info("assembly_look",
              fmt::format("situation {}: edge ({:.2f}, {:.2f})-({:.2f}, {:.2f}) px predicted "
                          "({:.2f}, {:.2f})-({:.2f}, {:.2f}) px: {} points, {:.3f} px rms, in a "
                          "{:.1f} px half-width",
                          s, r.start_px.u_px, r.start_px.v_px, r.end_px.u_px, r.end_px.v_px,
                          pa->x(), pa->y(), pb->x(), pb->y(), r.point_count, r.residual_px,
                          request.search_halfwidth_px),
              {{"job", run_.job_id()}, {"camera", cell.id}});
    return std::pair{out[0], out[1]};
  }

  /// One record per body the program moves (not the agent): where it was verified (or
  /// nominally was) and where the last situation puts it, in the robot's base frame.
  void record_results() {
    const rapt::Program& program = cp_.program;
    auto rr = evaluate(program.situation_count());
    if (!rr) {
      return;
    }
    run_.parts().clear();
    std::uint32_t index = 0;
    for (int b = 2; b <= program.body_count(); ++b) {
      if (b == agent_) {
        continue;
      }
      bool moves = false;
      for (int s = 2; s <= program.situation_count(); ++s) {
        moves = moves || program.is_moved(b, s);
      }
      if (!moves) {
        continue;
      }
      int verified_in = 1;
      for (const auto& pkg : cp_.packages) {
        if (pkg.body == b && pkg.fixable) {
          verified_in = pkg.situation;
          break;
        }
      }
      const Eigen::Isometry3d picked = spec_.base_T_world * rr->actual_pose(b, verified_in);
      const Eigen::Isometry3d last =
          spec_.base_T_world * rr->actual_pose(b, program.situation_count());
      PartRecord rec;
      rec.index = index++;
      rec.class_name = program.body(b).name;
      const auto yaw = [](const Eigen::Isometry3d& t) {
        return std::atan2(t.linear()(1, 0), t.linear()(0, 0));
      };
      rec.picked_x_mm = picked.translation().x();
      rec.picked_y_mm = picked.translation().y();
      rec.picked_yaw_rad = yaw(picked);
      rec.placed_x_mm = last.translation().x();
      rec.placed_y_mm = last.translation().y();
      rec.placed_yaw_rad = yaw(last);
      rec.outcome = cell_task_PART_PLACED;
      rec.detail = spec_.verify ? fmt::format("verified in situation {}", verified_in)
                                : "not verified (verify: false)";
      run_.parts().push_back(rec);
    }
  }

  JobRun& run_;
  const task::AssemblySpec& spec_;
  rapt::CompiledProgram cp_;
  int agent_ = 0;
  std::vector<rapt::Reading> readings_;
  std::map<std::string, CellCamera> cells_;
  bus::Requester<cell_vision_EdgeRequest, cell_vision_EdgeResult> edge_requests_;
  bus::Topic<cell_calibration_CameraCalibration> calibration_topic_;
  bus::Reader<cell_calibration_CameraCalibration> calibrations_;
};

}  // namespace

Status check_assembly(const task::AssemblySpec& spec, const kinematics::RobotModel& robot) {
  std::optional<rapt::CompiledProgram> cp;
  int agent = 0;
  const auto why = assembly_problems(spec, robot, cp, agent);
  if (why.empty()) {
    return ok_status();
  }
  std::string text;
  for (const auto& w : why) {
    text += (text.empty() ? "" : "\n") + w;
  }
  return Error{Errc::kInvalidArgument, text};
}

ExecResult run_assembly_job(JobRun& run) { return AssemblyJob(run).run(); }

}  // namespace cell::task_service
