#include "teach_session.hpp"

#include <algorithm>
#include <filesystem>

#include <fmt/format.h>

#include "cell/common/log.hpp"
#include "commands.hpp"

namespace cell::monitor {
namespace {

using nlohmann::json;

json joints_json(const kinematics::JointVector& q) {
  json out = json::array();
  for (Eigen::Index i = 0; i < q.size(); ++i) {
    out.push_back(number(q[i]));
  }
  return out;
}

json step_json(const teach::Step& step) {
  json out{{"text", teach::describe(step)}};
  if (const auto* p = std::get_if<teach::PoseStep>(&step)) {
    out["kind"] = "pose";
    out["name"] = p->name;
    out["move"] = std::string(teach::to_string(p->move));
    out["speed_scale"] = p->speed_scale;
    out["joints"] = joints_json(p->joints);
  } else if (const auto* g = std::get_if<teach::GripperStep>(&step)) {
    out["kind"] = "gripper";
    out["action"] = std::string(teach::to_string(g->action));
  } else {
    out["kind"] = "wait";
    out["wait_s"] = std::get<teach::WaitStep>(step).duration_s;
  }
  return out;
}

json action_json(const teach::Action& a) {
  json out{{"step", a.step_index}, {"text", a.describe()}};
  switch (a.kind) {
    case teach::Action::Kind::kMove:
      out["kind"] = "move";
      out["joints"] = joints_json(a.joints);
      break;
    case teach::Action::Kind::kGripper:
      out["kind"] = "gripper";
      out["action"] = std::string(teach::to_string(a.gripper));
      break;
    case teach::Action::Kind::kWait:
      out["kind"] = "wait";
      out["wait_s"] = a.wait_s;
      break;
    case teach::Action::Kind::kNone:
      out["kind"] = "none";
      break;
  }
  return out;
}

}  // namespace

TeachSession::TeachSession(const bus::Participant& participant,
                           std::map<std::string, kinematics::RobotModel> models,
                           std::string tasks_dir, JointsFn joints, ChangeFn on_change)
    : participant_(participant),
      models_(std::move(models)),
      tasks_dir_(std::move(tasks_dir)),
      joints_(std::move(joints)),
      on_change_(std::move(on_change)) {}

TeachSession::~TeachSession() {
  stop();
  if (worker_.joinable()) {
    worker_.join();
  }
}

void TeachSession::changed() {
  if (on_change_) {
    on_change_();
  }
}

std::optional<std::string> TeachSession::file_path(const std::string& file) const {
  if (!safe_name(file) || file.size() < 6 || file.substr(file.size() - 5) != ".yaml") {
    return std::nullopt;
  }
  return tasks_dir_ + "/" + file;
}

Status TeachSession::editable() const {
  if (running_) {
    return Error{Errc::kNotReady, "a playback is running on the robot: stop it first"};
  }
  if (!task_) {
    return Error{Errc::kNotReady, "no task open: create or open one first"};
  }
  return ok_status();
}

json TeachSession::state() {
  std::lock_guard lock(mutex_);
  json files = json::array();
  std::error_code ec;
  std::vector<std::string> names;
  for (const auto& e : std::filesystem::directory_iterator(tasks_dir_, ec)) {
    if (e.path().extension() == ".yaml" && safe_name(e.path().filename().string())) {
      names.push_back(e.path().filename().string());
    }
  }
  std::sort(names.begin(), names.end());
  for (auto& n : names) {
    files.push_back(n);
  }
  json out{{"file", file_},         {"dirty", dirty_},       {"cursor", cursor_.position()},
           {"running", running_.load()}, {"message", message_}, {"files", files},
           {"task", nullptr}};
  if (task_) {
    json steps = json::array();
    for (const auto& s : task_->steps) {
      steps.push_back(step_json(s));
    }
    out["task"] = {{"name", task_->name},
                   {"robot", task_->robot_id},
                   {"speed_scale", task_->speed_scale},
                   {"steps", steps}};
  }
  return out;
}

Status TeachSession::create(const std::string& robot, const std::string& name) {
  {
    std::lock_guard lock(mutex_);
    if (running_) {
      return Error{Errc::kNotReady, "a playback is running on the robot: stop it first"};
    }
    auto it = models_.find(robot);
    if (it == models_.end()) {
      return Error{Errc::kInvalidArgument, fmt::format("unknown robot '{}'", robot.substr(0, 64))};
    }
    if (!safe_name(name)) {
      return Error{Errc::kInvalidArgument,
                   "a task name is 1-64 characters of A-Z a-z 0-9 _ . -"};
    }
    teach::Task task;
    task.name = name;
    task.robot_id = robot;
    task_ = std::move(task);
    model_ = it->second;
    file_ = name + ".yaml";
    dirty_ = true;
    cursor_ = teach::Cursor();
    message_ = fmt::format("new task '{}' for {}", name, robot);
  }
  changed();
  return ok_status();
}

Status TeachSession::open(const std::string& file) {
  {
    std::lock_guard lock(mutex_);
    if (running_) {
      return Error{Errc::kNotReady, "a playback is running on the robot: stop it first"};
    }
    auto path = file_path(file);
    if (!path) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("'{}' is not a task file name (<name>.yaml, A-Z a-z 0-9 _ . -)",
                               file.substr(0, 64))};
    }
    if (models_.empty()) {
      return Error{Errc::kNotReady, "the monitor has no robots configured"};
    }
    kinematics::RobotModel model = models_.begin()->second;
    auto lookup = [this](const std::string& id) -> Result<kinematics::RobotModel> {
      auto it = models_.find(id);
      if (it == models_.end()) {
        return Error{Errc::kInvalidArgument,
                     fmt::format("robot '{}' is not one of the monitor's robots", id)};
      }
      return it->second;
    };
    auto task = teach::load_task(*path, lookup, &model);
    if (!task) {
      return std::move(task).error();
    }
    task_ = std::move(*task);
    model_ = model;
    file_ = file;
    dirty_ = false;
    cursor_ = teach::Cursor();
    message_ = fmt::format("opened {}", file);
  }
  changed();
  return ok_status();
}

Status TeachSession::save(const std::string& file) {
  {
    std::lock_guard lock(mutex_);
    if (!task_) {
      return Error{Errc::kNotReady, "no task open"};
    }
    const std::string name = file.empty() ? file_ : file;
    auto path = file_path(name);
    if (!path) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("'{}' is not a task file name (<name>.yaml, A-Z a-z 0-9 _ . -)",
                               name.substr(0, 64))};
    }
    std::error_code ec;
    std::filesystem::create_directories(tasks_dir_, ec);
    CELL_TRY(teach::save_task(*path, *task_, *model_));
    file_ = name;
    dirty_ = false;
    message_ = fmt::format("saved {}", name);
    log::info("teach.save", "task saved", {{"file", *path}});
  }
  changed();
  return ok_status();
}

Status TeachSession::record(const std::string& name, teach::MoveKind move) {
  {
    std::lock_guard lock(mutex_);
    CELL_TRY(editable());
    auto q = joints_(task_->robot_id);
    if (!q) {
      return Error{Errc::kNotReady,
                   fmt::format("no state from robot '{}': cannot record its pose",
                               task_->robot_id)};
    }
    auto pose = teach::record_pose(*task_, *model_, *q, name, move);
    if (!pose) {
      return std::move(pose).error();
    }
    const std::string recorded = pose->name;
    CELL_TRY(task_->insert(cursor_.position(), std::move(*pose)));
    cursor_.advance();
    dirty_ = true;
    message_ = fmt::format("recorded '{}'", recorded);
  }
  changed();
  return ok_status();
}

Status TeachSession::add_gripper(teach::GripperAction action) {
  {
    std::lock_guard lock(mutex_);
    CELL_TRY(editable());
    CELL_TRY(task_->insert(cursor_.position(), teach::GripperStep{action}));
    cursor_.advance();
    dirty_ = true;
    message_ = fmt::format("gripper {} inserted", teach::to_string(action));
  }
  changed();
  return ok_status();
}

Status TeachSession::add_wait(double seconds) {
  if (!(std::isfinite(seconds) && seconds >= 0.0 && seconds <= 3600.0)) {
    return Error{Errc::kOutOfRange, fmt::format("a wait must be in [0, 3600] s, got {}", seconds)};
  }
  {
    std::lock_guard lock(mutex_);
    CELL_TRY(editable());
    CELL_TRY(task_->insert(cursor_.position(), teach::WaitStep{seconds}));
    cursor_.advance();
    dirty_ = true;
    message_ = fmt::format("wait {:.2f} s inserted", seconds);
  }
  changed();
  return ok_status();
}

Status TeachSession::remove(std::size_t index) {
  {
    std::lock_guard lock(mutex_);
    CELL_TRY(editable());
    CELL_TRY(task_->remove(index));
    if (cursor_.position() > index) {
      cursor_.retreat();
    }
    cursor_.clamp(*task_);
    dirty_ = true;
    message_ = fmt::format("step {} deleted", index + 1);
  }
  changed();
  return ok_status();
}

Status TeachSession::move(std::size_t from, std::size_t to) {
  {
    std::lock_guard lock(mutex_);
    CELL_TRY(editable());
    CELL_TRY(task_->move(from, to));
    dirty_ = true;
    message_ = fmt::format("step {} moved to {}", from + 1, to + 1);
  }
  changed();
  return ok_status();
}

Status TeachSession::rename(std::size_t index, const std::string& name) {
  {
    std::lock_guard lock(mutex_);
    CELL_TRY(editable());
    CELL_TRY(task_->rename(index, name));
    dirty_ = true;
  }
  changed();
  return ok_status();
}

Status TeachSession::seek(std::size_t position) {
  {
    std::lock_guard lock(mutex_);
    CELL_TRY(editable());
    CELL_TRY(cursor_.seek(*task_, position));
  }
  changed();
  return ok_status();
}

Result<json> TeachSession::simulate_locked(teach::PlaybackOptions options) {
  // The simulated arm starts where the cell would be at the run's start: at the last pose
  // before it (forward) or at or before its end (backward); else where the robot is now.
  const std::size_t upto = options.direction == teach::Direction::kForward
                               ? options.from
                               : options.to.value_or(task_->steps.size());
  std::optional<kinematics::JointVector> start;
  for (std::size_t i = upto; i > 0; --i) {
    if (const auto* p = std::get_if<teach::PoseStep>(&task_->steps[i - 1])) {
      start = p->joints;
      break;
    }
  }
  if (!start) {
    start = joints_(task_->robot_id);
  }
  if (!start) {
    return Error{Errc::kNotReady, fmt::format("no state from robot '{}': nothing to start from",
                                              task_->robot_id)};
  }
  auto run = teach::simulate(*task_, *model_, *start, options);
  if (!run) {
    return std::move(run).error();
  }
  json steps = json::array();
  double total = 0.0;
  for (const auto& s : *run) {
    json samples = json::array();
    for (const auto& q : s.samples) {
      samples.push_back(joints_json(q));
    }
    steps.push_back({{"action", action_json(s.action)},
                     {"start_s", s.start_s},
                     {"duration_s", s.duration_s},
                     {"samples", samples},
                     {"gripper", s.gripper ? json(std::string(teach::to_string(*s.gripper)))
                                           : json(nullptr)}});
    total = s.start_s + s.duration_s;
  }
  return json{{"preview", true},
              {"robot", task_->robot_id},
              {"sample_period_s", 0.05},
              {"duration_s", total},
              {"steps", steps}};
}

Result<json> TeachSession::start_locked(teach::PlaybackOptions options) {
  if (worker_.joinable()) {
    worker_.join();  // the previous run has finished (running_ is false)
  }
  if (!runner_ || runner_->cancelled() || runner_robot_ != task_->robot_id) {
    runner_.reset();
    runner_robot_ = task_->robot_id;
    teach::BusRunnerOptions ro;
    ro.client_name = "monitor-teach";
    ro.operator_id = "monitor";
    runner_ = std::make_unique<teach::BusRunner>(participant_, task_->robot_id, ro);
  }
  running_ = true;
  message_ = "running on the robot";
  worker_ = std::thread([this, task = *task_, model = *model_, options,
                         runner = runner_.get()] {
    const bool forward = options.direction == teach::Direction::kForward;
    auto report = teach::play(task, model, *runner, options,
                              [&](const teach::Action& a, std::size_t, std::size_t) {
                                {
                                  std::lock_guard lock(mutex_);
                                  message_ = a.describe();
                                }
                                changed();
                              });
    {
      std::lock_guard lock(mutex_);
      const std::size_t to = options.to.value_or(task.steps.size());
      if (report) {
        const std::size_t done = report->steps_done;
        (void)cursor_.seek(*task_, forward ? options.from + done : to - done);
        message_ = report->brief();
      } else {
        message_ = report.error().message;
      }
      log::info("teach.run", message_, {{"task", task.name}});
    }
    running_ = false;
    changed();
  });
  return json{{"preview", false}, {"started", true}};
}

Result<json> TeachSession::step(teach::Direction direction, bool preview) {
  Result<json> out = json();
  {
    std::lock_guard lock(mutex_);
    CELL_TRY(editable());
    const std::size_t pos = cursor_.position();
    teach::PlaybackOptions options;
    options.direction = direction;
    if (direction == teach::Direction::kForward) {
      if (pos >= task_->steps.size()) {
        return Error{Errc::kOutOfRange, "at the end of the task"};
      }
      options.from = pos;
      options.to = pos + 1;
    } else {
      if (pos == 0) {
        return Error{Errc::kOutOfRange, "at the start of the task"};
      }
      options.from = pos - 1;
      options.to = pos;
    }
    if (preview) {
      out = simulate_locked(options);
      if (out) {
        if (direction == teach::Direction::kForward) {
          cursor_.advance();
        } else {
          cursor_.retreat();
        }
      }
    } else {
      out = start_locked(options);
    }
  }
  changed();
  return out;
}

Result<json> TeachSession::run(bool preview) {
  Result<json> out = json();
  {
    std::lock_guard lock(mutex_);
    CELL_TRY(editable());
    teach::PlaybackOptions options;
    options.from = cursor_.position() >= task_->steps.size() ? 0 : cursor_.position();
    if (preview) {
      out = simulate_locked(options);
      if (out) {
        (void)cursor_.seek(*task_, task_->steps.size());
      }
    } else {
      out = start_locked(options);
    }
  }
  changed();
  return out;
}

void TeachSession::stop() {
  std::lock_guard lock(mutex_);
  if (runner_ && running_) {
    runner_->cancel();
  }
}

}  // namespace cell::monitor
