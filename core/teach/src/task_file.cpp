#include "cell/teach/task_file.hpp"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <set>
#include <sstream>

#include <fmt/format.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/service/paths.hpp"

namespace cell::teach {
namespace {

// A tool pose written in a file may differ from the joints' FK by rounding only (six
// decimals are written): anything larger means the file was edited inconsistently.
constexpr double kToolTolMm = 0.1;
constexpr double kToolTolDeg = 0.01;

/// "j1_deg" / "z_mm": a joint's key in the file.
std::string joint_key(const kinematics::JointSpec& joint) {
  return joint.name + "_" + std::string(joint.display_unit());
}

std::string step_label(std::size_t index, const Step& step) {
  return fmt::format("step {} ({})", index + 1, describe(step));
}

Status range_error(const char* what, std::size_t index, std::size_t size) {
  return Error{Errc::kOutOfRange,
               fmt::format("{} {} is out of range: the task has {} step{} (valid 1..{})", what,
                           index + 1, size, size == 1 ? "" : "s", size)};
}

}  // namespace

std::string_view to_string(MoveKind kind) noexcept {
  return kind == MoveKind::kLine ? "line" : "joint";
}

std::string_view to_string(GripperAction action) noexcept {
  return action == GripperAction::kClose ? "close" : "open";
}

std::string describe(const Step& step) {
  if (const auto* p = std::get_if<PoseStep>(&step)) {
    return fmt::format("pose '{}' ({})", p->name, to_string(p->move));
  }
  if (const auto* g = std::get_if<GripperStep>(&step)) {
    return fmt::format("gripper {}", to_string(g->action));
  }
  return fmt::format("wait {:.2f} s", std::get<WaitStep>(step).duration_s);
}

Status Task::insert(std::size_t at, Step step) {
  if (at > steps.size()) {
    return Error{Errc::kOutOfRange,
                 fmt::format("cannot insert at {}: the task has {} step{} (valid 1..{})", at + 1,
                             steps.size(), steps.size() == 1 ? "" : "s", steps.size() + 1)};
  }
  if (const auto* p = std::get_if<PoseStep>(&step)) {
    if (p->name.empty()) {
      return Error{Errc::kInvalidArgument, "a pose step needs a name"};
    }
    if (find(p->name)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("a pose called '{}' exists already (step {})", p->name,
                               *find(p->name) + 1)};
    }
  }
  steps.insert(steps.begin() + static_cast<std::ptrdiff_t>(at), std::move(step));
  return ok_status();
}

Status Task::append(Step step) { return insert(steps.size(), std::move(step)); }

Status Task::remove(std::size_t at) {
  if (at >= steps.size()) {
    return range_error("step", at, steps.size());
  }
  steps.erase(steps.begin() + static_cast<std::ptrdiff_t>(at));
  return ok_status();
}

Status Task::move(std::size_t from, std::size_t to) {
  if (from >= steps.size()) {
    return range_error("step", from, steps.size());
  }
  if (to >= steps.size()) {
    return range_error("destination", to, steps.size());
  }
  Step step = std::move(steps[from]);
  steps.erase(steps.begin() + static_cast<std::ptrdiff_t>(from));
  steps.insert(steps.begin() + static_cast<std::ptrdiff_t>(to), std::move(step));
  return ok_status();
}

Status Task::rename(std::size_t at, const std::string& new_name) {
  if (at >= steps.size()) {
    return range_error("step", at, steps.size());
  }
  auto* pose = std::get_if<PoseStep>(&steps[at]);
  if (pose == nullptr) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("step {} is a {}, not a pose: only poses have names", at + 1,
                             describe(steps[at]))};
  }
  if (new_name.empty()) {
    return Error{Errc::kInvalidArgument, "a pose step needs a name"};
  }
  if (auto other = find(new_name); other && *other != at) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("a pose called '{}' exists already (step {})", new_name, *other + 1)};
  }
  pose->name = new_name;
  return ok_status();
}

std::optional<std::size_t> Task::find(const std::string& pose_name) const {
  for (std::size_t i = 0; i < steps.size(); ++i) {
    if (const auto* p = std::get_if<PoseStep>(&steps[i]); p != nullptr && p->name == pose_name) {
      return i;
    }
  }
  return std::nullopt;
}

std::size_t Task::pose_count() const {
  return static_cast<std::size_t>(std::count_if(steps.begin(), steps.end(), [](const Step& s) {
    return std::holds_alternative<PoseStep>(s);
  }));
}

std::string Task::next_pose_name() const {
  for (std::size_t n = pose_count() + 1;; ++n) {
    std::string candidate = fmt::format("p{}", n);
    if (!find(candidate)) {
      return candidate;
    }
  }
}

Status Task::validate(const kinematics::RobotModel& model) const {
  if (!(speed_scale > 0.0 && speed_scale <= 1.0)) {
    return Error{Errc::kOutOfRange,
                 fmt::format("speed_scale must be in (0, 1], got {}", speed_scale)};
  }
  if (robot_id != model.id()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("the task is for robot '{}', the model is '{}'", robot_id,
                             model.id())};
  }
  std::set<std::string> names;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const Step& step = steps[i];
    if (const auto* p = std::get_if<PoseStep>(&step)) {
      if (p->name.empty()) {
        return Error{Errc::kInvalidArgument, fmt::format("step {}: a pose needs a name", i + 1)};
      }
      if (!names.insert(p->name).second) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("{}: the name '{}' is used twice", step_label(i, step), p->name)};
      }
      if (!(p->speed_scale >= 0.0 && p->speed_scale <= 1.0)) {
        return Error{Errc::kOutOfRange, fmt::format("{}: speed_scale must be in [0, 1], got {}",
                                                    step_label(i, step), p->speed_scale)};
      }
      if (auto s = model.check_limits(p->joints); !s) {
        return Error{s.error().code,
                     fmt::format("{}: {}", step_label(i, step), s.error().message)};
      }
    } else if (const auto* w = std::get_if<WaitStep>(&step)) {
      if (!(std::isfinite(w->duration_s) && w->duration_s >= 0.0)) {
        return Error{Errc::kOutOfRange, fmt::format("step {}: wait_s must be >= 0, got {}", i + 1,
                                                    w->duration_s)};
      }
    }
  }
  return ok_status();
}

Result<kinematics::RobotModel> load_robot_by_id(const std::string& robot_id) {
  if (robot_id.empty() || robot_id.find_first_of("/\\.") != std::string::npos) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("'{}' is not a robot id (e.g. ibm7545, excalibur)", robot_id)};
  }
  return kinematics::load_robot(service::resolve_path("config/robots/" + robot_id + ".yaml"));
}

Result<Task> parse_task(const config::Document& doc, const RobotLookup& lookup,
                        kinematics::RobotModel* model_out) {
  Task task;
  config::MapReader root(doc, doc.root, "");
  root.required("task", task.name);
  root.required("robot", task.robot_id);
  root.optional("description", task.description);
  root.optional("speed_scale", task.speed_scale);
  if (!(task.speed_scale > 0.0 && task.speed_scale <= 1.0)) {
    root.fail("speed_scale", fmt::format("must be in (0, 1], got {}", task.speed_scale));
  }
  std::optional<kinematics::RobotModel> model;
  if (!task.robot_id.empty()) {
    auto loaded = lookup(task.robot_id);
    if (loaded) {
      model = std::move(*loaded);
    } else {
      root.fail("robot", fmt::format("cannot load robot '{}': {}", task.robot_id,
                                     loaded.error().message));
    }
  }
  const auto steps = root.sequence("steps", false);
  std::set<std::string> names;
  for (std::size_t i = 0; i < steps.size(); ++i) {
    const std::string where = fmt::format("steps[{}]", i);
    if (!steps[i].IsMap()) {
      root.fail("steps", fmt::format("{} ({}): expected a map with pose, gripper or wait_s",
                                     where, config::location(doc.path, steps[i])));
      continue;
    }
    config::MapReader s = root.element(steps[i], where);
    const int kinds = int{s.node()["pose"].IsDefined()} + int{s.node()["gripper"].IsDefined()} +
                      int{s.node()["wait_s"].IsDefined()};
    if (kinds != 1) {
      s.fail("", "a step has exactly one of pose, gripper, wait_s");
      root.absorb(s);
      continue;
    }
    if (s.has("gripper")) {
      std::string action;
      s.required("gripper", action);
      GripperStep g;
      if (action == "open") {
        g.action = GripperAction::kOpen;
      } else if (action == "close") {
        g.action = GripperAction::kClose;
      } else {
        s.fail("gripper", fmt::format("must be open or close, got '{}'", action));
      }
      task.steps.emplace_back(g);
    } else if (s.has("wait_s")) {
      WaitStep w;
      s.required("wait_s", w.duration_s);
      if (!(std::isfinite(w.duration_s) && w.duration_s >= 0.0)) {
        s.fail("wait_s", fmt::format("must be >= 0, got {}", w.duration_s));
      }
      task.steps.emplace_back(w);
    } else {
      PoseStep p;
      s.required("pose", p.name);
      if (!p.name.empty() && !names.insert(p.name).second) {
        s.fail("pose", fmt::format("the name '{}' is used twice", p.name));
      }
      std::string move = "joint";
      s.optional("move", move);
      if (move == "line") {
        p.move = MoveKind::kLine;
      } else if (move != "joint") {
        s.fail("move", fmt::format("must be joint or line, got '{}'", move));
      }
      s.optional("speed_scale", p.speed_scale);
      if (!(p.speed_scale >= 0.0 && p.speed_scale <= 1.0)) {
        s.fail("speed_scale", fmt::format("must be in [0, 1], got {}", p.speed_scale));
      }
      config::MapReader j = s.child("joints");
      if (model) {
        p.joints.resize(model->dof());
        for (int k = 0; k < model->dof(); ++k) {
          const auto& spec = model->joints()[static_cast<std::size_t>(k)];
          double value = std::nan("");
          j.required(joint_key(spec), value);
          p.joints[k] = spec.from_display(value);
        }
        if (p.joints.allFinite()) {
          if (auto lim = model->check_limits(p.joints); !lim) {
            j.fail("", lim.error().message);
          }
        }
      } else {
        // Without a model the joint keys cannot be checked: accept them silently here (the
        // robot error is already reported).
        for (const auto& kv : j.node()) {
          (void)j.has(kv.first.as<std::string>());
        }
      }
      s.absorb(j);
      if (s.has("tool")) {
        config::MapReader t = s.child("tool");
        std::array<double, 3> xyz{};
        std::array<double, 3> rpy_deg{};
        t.required("xyz_mm", xyz);
        t.required("rpy_deg", rpy_deg);
        if (model && p.joints.size() == model->dof() && p.joints.allFinite()) {
          if (auto fk = model->forward(p.joints)) {
            const Eigen::Vector3d written(xyz[0], xyz[1], xyz[2]);
            const Eigen::Matrix3d r = geometry::rotation_from_rpy(
                {geometry::deg_to_rad(rpy_deg[0]), geometry::deg_to_rad(rpy_deg[1]),
                 geometry::deg_to_rad(rpy_deg[2])});
            const double dp = (fk->translation() - written).norm();
            const double dr =
                geometry::rad_to_deg(geometry::rotation_distance(fk->linear(), r));
            if (dp > kToolTolMm || dr > kToolTolDeg) {
              t.fail("", fmt::format("the tool pose disagrees with the joints' forward "
                                     "kinematics by {:.3f} mm / {:.3f} deg (FK gives xyz_mm "
                                     "[{:.3f}, {:.3f}, {:.3f}]): edit the joints, not the tool",
                                     dp, dr, fk->translation().x(), fk->translation().y(),
                                     fk->translation().z()));
            }
          }
        }
        s.absorb(t);
      }
      task.steps.emplace_back(std::move(p));
    }
    root.absorb(s);
  }
  CELL_TRY(root.finish());
  if (model_out != nullptr && model) {
    *model_out = *model;
  }
  return task;
}

Result<Task> load_task(const std::string& path, const RobotLookup& lookup,
                       kinematics::RobotModel* model_out) {
  auto doc = config::load_file(path);
  if (!doc) {
    return std::move(doc).error();
  }
  return parse_task(*doc, lookup, model_out);
}

Result<std::string> to_yaml(const Task& task, const kinematics::RobotModel& model) {
  CELL_TRY(task.validate(model));
  std::ostringstream out;
  out << "# cell task file (core/teach/README.md): recorded poses and gripper steps for "
      << task.robot_id << ".\n"
      << "# Joints in deg / mm (key suffix); tool = FK of the joints, base frame, written for "
         "people.\n";
  // Names are quoted with YAML's double-quote escapes so any text survives a round trip.
  auto quoted = [](const std::string& s) {
    std::string q = "\"";
    for (const char c : s) {
      if (c == '"' || c == '\\') {
        q += '\\';
        q += c;
      } else if (c == '\n') {
        q += "\\n";
      } else if (static_cast<unsigned char>(c) < 0x20) {
        q += fmt::format("\\x{:02x}", static_cast<unsigned char>(c));
      } else {
        q += c;
      }
    }
    return q + "\"";
  };
  out << "task: " << quoted(task.name) << "\n";
  out << "robot: " << task.robot_id << "\n";
  if (!task.description.empty()) {
    out << "description: " << quoted(task.description) << "\n";
  }
  out << fmt::format("speed_scale: {}\n", task.speed_scale);
  if (task.steps.empty()) {
    out << "steps: []\n";
    return out.str();
  }
  out << "steps:\n";
  for (const Step& step : task.steps) {
    if (const auto* p = std::get_if<PoseStep>(&step)) {
      out << "  - pose: " << quoted(p->name) << "\n";
      if (p->move != MoveKind::kJoint) {
        out << "    move: " << to_string(p->move) << "\n";
      }
      if (p->speed_scale > 0.0) {
        out << fmt::format("    speed_scale: {}\n", p->speed_scale);
      }
      out << "    joints: {";
      for (int k = 0; k < model.dof(); ++k) {
        const auto& spec = model.joints()[static_cast<std::size_t>(k)];
        out << (k == 0 ? "" : ", ") << joint_key(spec) << ": "
            << fmt::format("{:.6f}", spec.to_display(p->joints[k]));
      }
      out << "}\n";
      if (auto fk = model.forward(p->joints)) {
        const auto rpy = geometry::rpy_from_rotation(fk->linear());
        const Eigen::Vector3d t = fk->translation();
        out << fmt::format(
            "    tool: {{xyz_mm: [{:.6f}, {:.6f}, {:.6f}], rpy_deg: [{:.6f}, {:.6f}, {:.6f}]}}\n",
            t.x(), t.y(), t.z(), geometry::rad_to_deg(rpy.roll),
            geometry::rad_to_deg(rpy.pitch), geometry::rad_to_deg(rpy.yaw));
      }
    } else if (const auto* g = std::get_if<GripperStep>(&step)) {
      out << "  - gripper: " << to_string(g->action) << "\n";
    } else {
      out << fmt::format("  - wait_s: {}\n", std::get<WaitStep>(step).duration_s);
    }
  }
  return out.str();
}

Status save_task(const std::string& path, const Task& task, const kinematics::RobotModel& model) {
  auto text = to_yaml(task, model);
  if (!text) {
    return std::move(text).error();
  }
  const std::string tmp = path + ".tmp";
  std::FILE* f = std::fopen(tmp.c_str(), "w");
  if (f == nullptr) {
    return Error{Errc::kIo, fmt::format("{}: cannot write: {}", tmp, std::strerror(errno))};
  }
  const bool written = std::fwrite(text->data(), 1, text->size(), f) == text->size();
  const bool flushed = std::fflush(f) == 0 && fsync(fileno(f)) == 0;
  const int saved_errno = errno;
  std::fclose(f);
  if (!written || !flushed) {
    std::remove(tmp.c_str());
    return Error{Errc::kIo, fmt::format("{}: cannot write: {}", tmp, std::strerror(saved_errno))};
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    std::remove(tmp.c_str());
    return Error{Errc::kIo, fmt::format("{}: cannot replace: {}", path, std::strerror(e))};
  }
  return ok_status();
}

Result<PoseStep> record_pose(const Task& task, const kinematics::RobotModel& model,
                             const kinematics::JointVector& q, const std::string& name,
                             MoveKind move) {
  CELL_TRY(model.check_limits(q));
  PoseStep p;
  p.name = name.empty() ? task.next_pose_name() : name;
  if (task.find(p.name)) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("a pose called '{}' exists already (step {})", p.name,
                             *task.find(p.name) + 1)};
  }
  p.joints = q;
  p.move = move;
  return p;
}

}  // namespace cell::teach
