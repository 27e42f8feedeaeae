#include "commands.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"

namespace cell::monitor {
namespace {

using nlohmann::json;

Result<bool> bool_field(const json& body, const char* key) {
  if (!body.contains(key) || body[key].is_null()) {
    return false;
  }
  if (!body[key].is_boolean()) {
    return Error{Errc::kInvalidArgument, fmt::format("field '{}' must be true or false", key)};
  }
  return body[key].get<bool>();
}

Result<std::array<double, 3>> triple(const json& body, const char* key) {
  if (!body.contains(key) || !body[key].is_array() || body[key].size() != 3) {
    return Error{Errc::kInvalidArgument, fmt::format("field '{}' must be a list of 3 numbers", key)};
  }
  std::array<double, 3> out{};
  for (std::size_t i = 0; i < 3; ++i) {
    if (!body[key][i].is_number() || !std::isfinite(body[key][i].get<double>())) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("field '{}[{}]' must be a finite number", key, i)};
    }
    out[i] = body[key][i].get<double>();
  }
  return out;
}

kinematics::JointVector current_joints(const RobotSample& latest) {
  kinematics::JointVector q(static_cast<Eigen::Index>(latest.q.size()));
  for (std::size_t i = 0; i < latest.q.size(); ++i) {
    q[static_cast<Eigen::Index>(i)] = latest.q[i];
  }
  return q;
}

Result<MotionCommand> parse_jog(const json& jog, const kinematics::RobotModel& model,
                                const RobotSample* latest, MotionCommand cmd) {
  if (!jog.is_object()) {
    return Error{Errc::kInvalidArgument, "field 'jog' must be an object"};
  }
  if (latest == nullptr || static_cast<int>(latest->q.size()) != model.dof()) {
    return Error{Errc::kNotReady,
                 fmt::format("no state from robot '{}' yet: cannot jog from an unknown pose",
                             model.id())};
  }
  auto space = string_field(jog, "space");
  if (!space) {
    return Error{space.error().code, "jog: " + space.error().message};
  }
  auto delta = number_field(jog, "delta", std::nan(""), -1000.0, 1000.0, "");
  if (!delta || std::isnan(*delta)) {
    return Error{Errc::kInvalidArgument,
                 delta ? "jog: missing field 'delta'" : "jog: " + delta.error().message};
  }
  if (*space == "joint") {
    int index = -1;
    if (jog.contains("joint") && jog["joint"].is_number_integer()) {
      index = jog["joint"].get<int>();
    } else if (jog.contains("joint") && jog["joint"].is_string()) {
      const auto name = jog["joint"].get<std::string>();
      for (int k = 0; k < model.dof(); ++k) {
        if (model.joints()[static_cast<std::size_t>(k)].name == name) {
          index = k;
        }
      }
    }
    if (index < 0 || index >= model.dof()) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("jog: field 'joint' must name one of robot '{}'s {} joints",
                               model.id(), model.dof())};
    }
    const auto& spec = model.joints()[static_cast<std::size_t>(index)];
    kinematics::JointVector q = current_joints(*latest);
    q[index] += spec.from_display(*delta);
    CELL_TRY(model.check_limits(q));
    cmd.kind = cell_motion_MOTION_MOVE_JOINTS;
    cmd.joints = q;
    cmd.what = fmt::format("jog {} {:+g} {}", spec.name, *delta, spec.display_unit());
    return cmd;
  }
  if (*space != "base" && *space != "tool") {
    return Error{Errc::kInvalidArgument,
                 fmt::format("jog: field 'space' must be joint, base or tool, got '{}'", *space)};
  }
  if (!latest->pose_valid) {
    return Error{Errc::kNotReady, fmt::format("robot '{}' reports no tool pose", model.id())};
  }
  auto axis = string_field(jog, "axis");
  if (!axis) {
    return Error{axis.error().code, "jog: " + axis.error().message};
  }
  static const std::array<const char*, 6> kAxes = {"x", "y", "z", "rx", "ry", "rz"};
  int a = -1;
  for (int i = 0; i < 6; ++i) {
    if (*axis == kAxes[static_cast<std::size_t>(i)]) {
      a = i;
    }
  }
  if (a < 0) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("jog: field 'axis' must be x, y, z, rx, ry or rz, got '{}'", *axis)};
  }
  Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
  if (a < 3) {
    step.translation()[a] = *delta;  // mm
  } else {
    step.linear() = Eigen::AngleAxisd(geometry::deg_to_rad(*delta),
                                      Eigen::Vector3d::Unit(a - 3))
                        .toRotationMatrix();  // deg
  }
  const Eigen::Isometry3d& base_T_tool = latest->base_T_tool;
  if (*space == "tool") {
    cmd.target = base_T_tool * step;
  } else {
    // Base-frame axes, rotations about the tool point (the thesis's relative world moves).
    cmd.target = base_T_tool;
    cmd.target.translation() += step.translation();
    cmd.target.linear() = step.linear() * base_T_tool.linear();
  }
  cmd.kind = cell_motion_MOTION_MOVE_LINEAR;
  cmd.what = fmt::format("jog {} {} {:+g} {}", *space, *axis, *delta, a < 3 ? "mm" : "deg");
  return cmd;
}

}  // namespace

bool safe_name(const std::string& text) noexcept {
  if (text.empty() || text.size() > 64 || text == "." || text == "..") {
    return false;
  }
  for (const char c : text) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '-' || c == '.';
    if (!ok) {
      return false;
    }
  }
  return true;
}

Result<double> number_field(const json& body,
                            const char* key,
                            double fallback,
                            double lo,
                            double hi,
                            std::string_view unit) {
  if (!body.contains(key) || body[key].is_null()) {
    return fallback;
  }
  if (!body[key].is_number()) {
    return Error{Errc::kInvalidArgument, fmt::format("field '{}' must be a number", key)};
  }
  const double v = body[key].get<double>();
  if (!std::isfinite(v) || v < lo || v > hi) {
    return Error{Errc::kOutOfRange, fmt::format("field '{}' must be in [{}, {}]{}{}, got {}", key, lo,
                                                hi, unit.empty() ? "" : " ", unit, v)};
  }
  return v;
}

Result<std::string> string_field(const json& body, const char* key) {
  if (!body.is_object() || !body.contains(key)) {
    return Error{Errc::kInvalidArgument, fmt::format("missing field '{}'", key)};
  }
  if (!body[key].is_string()) {
    return Error{Errc::kInvalidArgument, fmt::format("field '{}' must be a string", key)};
  }
  return body[key].get<std::string>();
}

Result<MotionCommand> parse_motion(const json& body, const kinematics::RobotModel& model,
                                   const RobotSample* latest) {
  if (!body.is_object()) {
    return Error{Errc::kInvalidArgument, "the request body must be a JSON object"};
  }
  MotionCommand cmd;
  cmd.robot_id = model.id();
  auto speed = number_field(body, "speed", 0.5, 0.01, 1.0, "");
  if (!speed) {
    return std::move(speed).error();
  }
  cmd.speed_scale = *speed;
  auto preview = bool_field(body, "preview");
  if (!preview) {
    return std::move(preview).error();
  }
  cmd.preview = *preview;
  const int kinds = int{body.contains("joints")} + int{body.contains("jog")} +
                    int{body.contains("pose")} + int{body.contains("stop")};
  if (kinds != 1) {
    return Error{Errc::kInvalidArgument,
                 "the request needs exactly one of 'joints', 'jog', 'pose', 'stop'"};
  }
  if (body.contains("stop")) {
    cmd.kind = cell_motion_MOTION_STOP;
    cmd.preview = false;
    cmd.what = "stop";
    return cmd;
  }
  if (body.contains("jog")) {
    return parse_jog(body["jog"], model, latest, std::move(cmd));
  }
  if (body.contains("joints")) {
    const json& j = body["joints"];
    if (!j.is_array() || static_cast<int>(j.size()) != model.dof()) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("field 'joints' must be a list of {} numbers (robot '{}')",
                               model.dof(), model.id())};
    }
    kinematics::JointVector q(model.dof());
    for (int k = 0; k < model.dof(); ++k) {
      const json& v = j[static_cast<std::size_t>(k)];
      if (!v.is_number() || !std::isfinite(v.get<double>())) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("field 'joints[{}]' must be a finite number", k)};
      }
      q[k] = model.joints()[static_cast<std::size_t>(k)].from_display(v.get<double>());
    }
    CELL_TRY(model.check_limits(q));
    cmd.kind = cell_motion_MOTION_MOVE_JOINTS;
    cmd.joints = q;
    cmd.what = "joints";
    return cmd;
  }
  const json& pose = body["pose"];
  if (!pose.is_object()) {
    return Error{Errc::kInvalidArgument, "field 'pose' must be an object"};
  }
  auto xyz = triple(pose, "xyz_mm");
  if (!xyz) {
    return Error{xyz.error().code, "pose: " + xyz.error().message};
  }
  auto rpy = triple(pose, "rpy_deg");
  if (!rpy) {
    return Error{rpy.error().code, "pose: " + rpy.error().message};
  }
  auto line = bool_field(pose, "line");
  if (!line) {
    return Error{line.error().code, "pose: " + line.error().message};
  }
  cmd.target = geometry::make_pose(
      Eigen::Vector3d((*xyz)[0], (*xyz)[1], (*xyz)[2]),
      {geometry::deg_to_rad((*rpy)[0]), geometry::deg_to_rad((*rpy)[1]),
       geometry::deg_to_rad((*rpy)[2])});
  cmd.kind = *line ? cell_motion_MOTION_MOVE_LINEAR : cell_motion_MOTION_MOVE_POSE;
  cmd.what = *line ? "line to pose" : "pose";
  return cmd;
}

Result<RobotCommandSpec> parse_robot_command(const json& body,
                                             const std::vector<std::string>& robots) {
  auto robot = string_field(body, "robot");
  if (!robot) {
    return std::move(robot).error();
  }
  if (std::find(robots.begin(), robots.end(), *robot) == robots.end()) {
    return Error{Errc::kInvalidArgument, fmt::format("unknown robot '{}'", robot->substr(0, 64))};
  }
  auto name = string_field(body, "command");
  if (!name) {
    return std::move(name).error();
  }
  RobotCommandSpec spec;
  spec.robot_id = *robot;
  spec.name = *name;
  if (*name == "home") {
    spec.kind = cell_robot_CMD_HOME;
  } else if (*name == "open") {
    spec.kind = cell_robot_CMD_GRIPPER_OPEN;
  } else if (*name == "close") {
    spec.kind = cell_robot_CMD_GRIPPER_CLOSE;
  } else if (*name == "stop") {
    spec.kind = cell_robot_CMD_STOP;
  } else if (*name == "reset") {
    spec.kind = cell_robot_CMD_RESET;
  } else {
    return Error{Errc::kInvalidArgument,
                 fmt::format("field 'command' must be home, open, close, stop or reset, got '{}'",
                             name->substr(0, 64))};
  }
  return spec;
}

Result<cell_task_JobKind> job_kind_from_name(const std::string& name) {
  if (name == "table_pick_place") {
    return cell_task_JOB_TABLE_PICK_PLACE;
  }
  if (name == "conveyor_pick") {
    return cell_task_JOB_CONVEYOR_PICK;
  }
  if (name == "assembly") {
    return cell_task_JOB_ASSEMBLY;
  }
  if (name == "task_file") {
    return cell_task_JOB_TASK_FILE;
  }
  return Error{Errc::kInvalidArgument, fmt::format("unknown job kind '{}'", name)};
}

Result<JobSpec> parse_job_submit(const json& body, const std::vector<JobTemplate>& templates,
                                 std::int64_t now_ms) {
  auto name = string_field(body, "template");
  if (!name) {
    return std::move(name).error();
  }
  JobSpec spec;
  for (const auto& t : templates) {
    if (t.name == *name) {
      spec.job_template = &t;
    }
  }
  if (spec.job_template == nullptr) {
    std::string known;
    for (const auto& t : templates) {
      known += (known.empty() ? "" : ", ") + t.name;
    }
    return Error{Errc::kInvalidArgument,
                 fmt::format("unknown job template '{}' (known: {})", name->substr(0, 64),
                             known.empty() ? "none configured" : known)};
  }
  auto kind = job_kind_from_name(spec.job_template->kind);
  if (!kind) {
    return std::move(kind).error();
  }
  spec.kind = *kind;
  if (body.contains("job_id") && !body["job_id"].is_null()) {
    auto id = string_field(body, "job_id");
    if (!id) {
      return std::move(id).error();
    }
    if (!safe_name(*id)) {
      return Error{Errc::kInvalidArgument,
                   "field 'job_id' must be 1-64 characters of A-Z a-z 0-9 _ . -"};
    }
    spec.job_id = *id;
  } else {
    spec.job_id = fmt::format("{}-{}", spec.job_template->name, now_ms);
  }
  return spec;
}

Result<JobCommandSpec> parse_job_command(const json& body) {
  auto id = string_field(body, "job_id");
  if (!id) {
    return std::move(id).error();
  }
  if (!safe_name(*id)) {
    return Error{Errc::kInvalidArgument,
                 "field 'job_id' must be 1-64 characters of A-Z a-z 0-9 _ . -"};
  }
  auto name = string_field(body, "command");
  if (!name) {
    return std::move(name).error();
  }
  JobCommandSpec spec;
  spec.job_id = *id;
  spec.name = *name;
  if (*name == "pause") {
    spec.kind = cell_task_JOB_PAUSE;
  } else if (*name == "resume") {
    spec.kind = cell_task_JOB_RESUME;
  } else if (*name == "cancel") {
    spec.kind = cell_task_JOB_CANCEL;
  } else if (*name == "confirm") {
    spec.kind = cell_task_JOB_CONFIRM;
  } else {
    return Error{Errc::kInvalidArgument,
                 fmt::format("field 'command' must be pause, resume, cancel or confirm, got '{}'",
                             name->substr(0, 64))};
  }
  return spec;
}

Result<Eigen::Isometry3d> grasp_tool_pose(const kinematics::RobotModel& model,
                                          const Eigen::Isometry3d& world_T_base,
                                          const Eigen::Isometry3d& world_T_grasp) {
  CELL_TRY(geometry::check_rigid(world_T_grasp, "grasp pose"));
  Eigen::Isometry3d base_T_tool = world_T_base.inverse(Eigen::Isometry) * world_T_grasp;
  const bool z_up = base_T_tool.linear()(2, 2) > 0.0;
  const bool want_up = model.scara() != nullptr;
  if (z_up != want_up) {
    // Turn the tool half a turn about its x axis: same point, z reversed.
    base_T_tool.linear() = base_T_tool.linear() * Eigen::Vector3d(1.0, -1.0, -1.0).asDiagonal();
  }
  return base_T_tool;
}

}  // namespace cell::monitor
