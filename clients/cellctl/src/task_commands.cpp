// `cellctl task ...`: task files (core/teach; the EXCAL thesis's teach and playback, digest 001
// §5): record the robot's poses, gripper steps and waits into a human-readable YAML file, list
// and edit it, and play it back on the robot (MotionRequests to the motion service, gripper
// commands to the gateway) or off line (the motion planner's plan, nothing moves).
#include <pthread.h>
#include <unistd.h>

#include <atomic>
#include <csignal>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/view.hpp"
#include "cell/teach/bus_runner.hpp"
#include "cell/teach/playback.hpp"
#include "cell/teach/task_file.hpp"
#include "commands.hpp"
#include "robot_args.hpp"
#include "table.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;

struct TaskArgs {
  std::string file;
  std::string robot;
  std::string name;
  std::string move = "joint";
  std::string gripper;
  std::optional<double> wait_s;
  std::optional<double> speed;
  std::optional<std::size_t> at;  // 1-based: insert before this step
  bool interactive = false;
  bool preview = false;
  bool backward = false;
  std::optional<std::size_t> from;  // 1-based, inclusive
  std::optional<std::size_t> to;    // 1-based, inclusive
  double timeout_s = 600.0;
  std::size_t index = 0;   // 1-based step for delete/rename/move
  std::size_t target = 0;  // 1-based destination for move
};

/// The file's task and its robot model, or a usage error naming the file.
struct Loaded {
  teach::Task task;
  kinematics::RobotModel model;
};

Result<Loaded> load(const std::string& file) {
  std::optional<kinematics::RobotModel> model;
  auto lookup = [&](const std::string& id) -> Result<kinematics::RobotModel> {
    auto m = load_robot_by_id(id);
    if (m) {
      model = *m;
    }
    return m;
  };
  auto task = teach::load_task(file, lookup);
  if (!task) {
    return std::move(task).error();
  }
  return Loaded{std::move(*task), std::move(*model)};
}

json step_json(const kinematics::RobotModel& model, const teach::Step& step, std::size_t index) {
  json out{{"index", index + 1}, {"text", teach::describe(step)}};
  if (const auto* p = std::get_if<teach::PoseStep>(&step)) {
    out["kind"] = "pose";
    out["name"] = p->name;
    out["move"] = std::string(teach::to_string(p->move));
    out["joints"] = joints_json(model, p->joints);
    if (auto fk = model.forward(p->joints)) {
      out["tool"] = pose_json(*fk);
    }
    if (p->speed_scale > 0.0) {
      out["speed_scale"] = p->speed_scale;
    }
  } else if (const auto* g = std::get_if<teach::GripperStep>(&step)) {
    out["kind"] = "gripper";
    out["action"] = std::string(teach::to_string(g->action));
  } else {
    out["kind"] = "wait";
    out["wait_s"] = std::get<teach::WaitStep>(step).duration_s;
  }
  return out;
}

std::string bar(std::size_t done, std::size_t total) {
  constexpr int kWidth = 24;
  const int n = total == 0 ? kWidth : static_cast<int>(kWidth * done / total);
  return "[" + std::string(static_cast<std::size_t>(n), '#') +
         std::string(static_cast<std::size_t>(kWidth - n), '.') + "]";
}

/// The robot's newest joints from cell/robot/state_latest (transient-local), or an error
/// naming the robot and the bus.
Result<kinematics::JointVector> current_joints(Session& session,
                                               const kinematics::RobotModel& model) {
  bus::Topic<cell_robot_RobotState> topic(session.participant(), bus::topics::kRobotStateLatest);
  bus::Reader<cell_robot_RobotState> reader(session.participant(), topic,
                                            bus::topics::kRobotStateLatest);
  const auto deadline = std::chrono::steady_clock::now() + session.timeout();
  while (std::chrono::steady_clock::now() < deadline) {
    (void)reader.wait_for_data(std::chrono::milliseconds(100));
    std::optional<kinematics::JointVector> found;
    std::string problem;
    auto taken = reader.take_each([&](const cell_robot_RobotState& s, const dds_sample_info_t&) {
      if (bus::str(s.robot_id) != model.id()) {
        return;
      }
      const auto q = bus::span(s.position_rad_or_mm);
      if (static_cast<int>(q.size()) != model.dof()) {
        problem = fmt::format("robot '{}' reports {} joints, its config {}", model.id(), q.size(),
                              model.dof());
        return;
      }
      kinematics::JointVector v(model.dof());
      for (int j = 0; j < model.dof(); ++j) {
        v[j] = q[static_cast<std::size_t>(j)];
      }
      if (s.moving) {
        problem = fmt::format("robot '{}' is moving: record it at rest", model.id());
        found.reset();
        return;
      }
      problem.clear();
      found = v;
    });
    if (!taken) {
      return std::move(taken).error();
    }
    if (found) {
      return *found;
    }
    if (!problem.empty()) {
      return Error{Errc::kNotReady, problem};
    }
  }
  return Error{Errc::kTimeout, fmt::format("no state from robot '{}' on {} (is gateway.{} running?)",
                                           model.id(), session.describe_bus(), model.id())};
}

/// The task of `args.file`, or a new one for --robot when the file does not exist yet.
Result<Loaded> open_or_create(const TaskArgs& args) {
  if (std::filesystem::exists(args.file)) {
    auto loaded = load(args.file);
    if (!loaded) {
      return std::move(loaded).error();
    }
    if (!args.robot.empty() && args.robot != loaded->task.robot_id) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("{} is a task for robot '{}', not '{}'", args.file,
                               loaded->task.robot_id, args.robot)};
    }
    return loaded;
  }
  if (args.robot.empty()) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("{} does not exist: give --robot to start a new task", args.file)};
  }
  auto model = load_robot_by_id(args.robot);
  if (!model) {
    return std::move(model).error();
  }
  teach::Task task;
  task.name = std::filesystem::path(args.file).stem().string();
  task.robot_id = args.robot;
  return Loaded{std::move(task), std::move(*model)};
}

/// Records one step (pose, gripper or wait) at `at` (0-based). Returns what it recorded.
Result<std::string> record_step(Session& session, Loaded& t, const TaskArgs& args,
                                std::size_t at, const std::string& name) {
  if (!args.gripper.empty()) {
    if (args.gripper != "open" && args.gripper != "close") {
      return Error{Errc::kInvalidArgument,
                   fmt::format("--gripper must be open or close, got '{}'", args.gripper)};
    }
    const auto action =
        args.gripper == "open" ? teach::GripperAction::kOpen : teach::GripperAction::kClose;
    CELL_TRY(t.task.insert(at, teach::GripperStep{action}));
    return fmt::format("gripper {}", args.gripper);
  }
  if (args.wait_s) {
    if (!(*args.wait_s >= 0.0 && *args.wait_s <= 3600.0)) {
      return Error{Errc::kOutOfRange,
                   fmt::format("--wait-s must be in [0, 3600] s, got {}", *args.wait_s)};
    }
    CELL_TRY(t.task.insert(at, teach::WaitStep{*args.wait_s}));
    return fmt::format("wait {:.2f} s", *args.wait_s);
  }
  if (args.move != "joint" && args.move != "line") {
    return Error{Errc::kInvalidArgument,
                 fmt::format("--move must be joint or line, got '{}'", args.move)};
  }
  auto q = current_joints(session, t.model);
  if (!q) {
    return std::move(q).error();
  }
  auto pose = teach::record_pose(t.task, t.model, *q, name,
                                 args.move == "line" ? teach::MoveKind::kLine
                                                     : teach::MoveKind::kJoint);
  if (!pose) {
    return std::move(pose).error();
  }
  if (args.speed) {
    pose->speed_scale = *args.speed;
  }
  std::string text = fmt::format("pose '{}' at {}", pose->name, joints_text(t.model, pose->joints));
  CELL_TRY(t.task.insert(at, std::move(*pose)));
  return text;
}

int usage_or_failure(Session& session, const Error& e) {
  const bool usage = e.code == Errc::kInvalidArgument || e.code == Errc::kOutOfRange ||
                     e.code == Errc::kConfig;
  return session.fail(e.message, usage ? kExitUsage : kExitFailure);
}

int record(Session& session, const TaskArgs& args) {
  if (args.speed && !(*args.speed > 0.0 && *args.speed <= 1.0)) {
    return session.fail(fmt::format("--speed must be in (0, 1], got {}", *args.speed), kExitUsage);
  }
  const int kinds = int{!args.gripper.empty()} + int{args.wait_s.has_value()} +
                    int{args.interactive};
  if (kinds > 1) {
    return session.fail("give one of --gripper, --wait-s, --interactive (or none: a pose)",
                        kExitUsage);
  }
  auto t = open_or_create(args);
  if (!t) {
    return usage_or_failure(session, t.error());
  }
  std::size_t at = t->task.steps.size();
  if (args.at) {
    if (*args.at < 1 || *args.at > t->task.steps.size() + 1) {
      return session.fail(fmt::format("--at {} is out of range: {} has {} steps (valid 1..{})",
                                      *args.at, args.file, t->task.steps.size(),
                                      t->task.steps.size() + 1),
                          kExitUsage);
    }
    at = *args.at - 1;
  }
  if (!args.interactive) {
    auto what = record_step(session, *t, args, at, args.name);
    if (!what) {
      return usage_or_failure(session, what.error());
    }
    if (auto s = teach::save_task(args.file, t->task, t->model); !s) {
      return session.fail(s.error().message);
    }
    if (session.json()) {
      session.out() << json{{"file", args.file},
                            {"recorded", step_json(t->model, t->task.steps[at], at)},
                            {"steps", t->task.steps.size()}}
                           .dump(2)
                    << "\n";
    } else {
      session.out() << fmt::format("{}: step {} of {}: {}\n", args.file, at + 1,
                                   t->task.steps.size(), *what);
    }
    return kExitOk;
  }
  // The thesis's teach mode: one keystroke (here one line) per pose, saved after each.
  session.err() << fmt::format(
      "teaching {} for {}: Enter (or 'p NAME') records the pose, 'o'/'c' opens/closes the "
      "gripper, 'w S' waits S s, 'd' deletes the last step, 'q' ends.\n",
      args.file, t->task.robot_id);
  std::string line;
  std::size_t recorded = 0;
  while (std::getline(std::cin, line)) {
    TaskArgs step = args;
    step.interactive = false;
    std::string name;
    if (line == "q") {
      break;
    }
    if (line == "d") {
      if (t->task.steps.empty() || at == 0) {
        session.err() << "nothing to delete\n";
        continue;
      }
      (void)t->task.remove(at - 1);
      --at;
    } else {
      if (line == "o" || line == "c") {
        step.gripper = line == "o" ? "open" : "close";
      } else if (line.rfind("w ", 0) == 0) {
        char* end = nullptr;
        step.wait_s = std::strtod(line.c_str() + 2, &end);
        if (end == line.c_str() + 2) {
          session.err() << "w needs seconds, e.g. 'w 0.5'\n";
          continue;
        }
      } else if (line.rfind("p ", 0) == 0) {
        name = line.substr(2);
      } else if (!line.empty()) {
        session.err() << fmt::format("unknown input '{}': Enter, p NAME, o, c, w S, d or q\n",
                                     line);
        continue;
      }
      auto what = record_step(session, *t, step, at, name);
      if (!what) {
        session.err() << "not recorded: " << what.error().message << "\n";
        continue;
      }
      session.err() << fmt::format("step {}: {}\n", at + 1, *what);
      ++at;
      ++recorded;
    }
    if (auto s = teach::save_task(args.file, t->task, t->model); !s) {
      return session.fail(s.error().message);
    }
  }
  if (session.json()) {
    session.out() << json{{"file", args.file}, {"recorded", recorded},
                          {"steps", t->task.steps.size()}}
                         .dump(2)
                  << "\n";
  } else {
    session.out() << fmt::format("{}: {} steps recorded, {} in the task\n", args.file, recorded,
                                 t->task.steps.size());
  }
  return kExitOk;
}

int show(Session& session, const TaskArgs& args) {
  auto t = load(args.file);
  if (!t) {
    return usage_or_failure(session, t.error());
  }
  if (session.json()) {
    json steps = json::array();
    for (std::size_t i = 0; i < t->task.steps.size(); ++i) {
      steps.push_back(step_json(t->model, t->task.steps[i], i));
    }
    session.out() << json{{"file", args.file},
                          {"task", t->task.name},
                          {"robot", t->task.robot_id},
                          {"speed_scale", t->task.speed_scale},
                          {"steps", steps}}
                         .dump(2)
                  << "\n";
    return kExitOk;
  }
  session.out() << fmt::format("task '{}' for {} ({} steps, speed {:.0f} % of the limits)\n",
                               t->task.name, t->task.robot_id, t->task.steps.size(),
                               100 * t->task.speed_scale);
  Table table({"#", "step", "joints", "tool"});
  for (std::size_t i = 0; i < t->task.steps.size(); ++i) {
    const auto& step = t->task.steps[i];
    std::string joints;
    std::string tool;
    if (const auto* p = std::get_if<teach::PoseStep>(&step)) {
      joints = joints_text(t->model, p->joints);
      if (auto fk = t->model.forward(p->joints)) {
        tool = pose_text(*fk);
      }
    }
    table.add_row({std::to_string(i + 1), teach::describe(step), joints, tool});
  }
  table.print(session.out());
  return kExitOk;
}

/// delete / move / rename: load, edit, save, say what happened.
template <typename Edit>
int edit(Session& session, const TaskArgs& args, Edit&& fn, const std::string& what) {
  auto t = load(args.file);
  if (!t) {
    return usage_or_failure(session, t.error());
  }
  if (args.index == 0) {
    return session.fail("steps are numbered from 1", kExitUsage);
  }
  if (auto s = fn(t->task); !s) {
    return usage_or_failure(session, s.error());
  }
  if (auto s = teach::save_task(args.file, t->task, t->model); !s) {
    return session.fail(s.error().message);
  }
  if (session.json()) {
    session.out() << json{{"file", args.file}, {"done", what}, {"steps", t->task.steps.size()}}
                         .dump(2)
                  << "\n";
  } else {
    session.out() << fmt::format("{}: {}; {} steps\n", args.file, what, t->task.steps.size());
  }
  return kExitOk;
}

/// Blocks SIGINT/SIGTERM in this thread (and the DDS threads it creates after) and cancels
/// `runner` from a watcher thread when one arrives: Ctrl-C stops the arm, it does not abandon
/// it mid-move. Restores the signal mask when destroyed.
class StopOnSignal {
 public:
  explicit StopOnSignal(std::atomic<teach::BusRunner*>& runner) : runner_(runner) {
    sigemptyset(&set_);
    sigaddset(&set_, SIGINT);
    sigaddset(&set_, SIGTERM);
    pthread_sigmask(SIG_BLOCK, &set_, &saved_);
    watcher_ = std::thread([this] {
      const timespec tick{0, 200'000'000};
      while (!done_) {
        if (sigtimedwait(&set_, nullptr, &tick) > 0) {
          signalled_ = true;
          if (auto* r = runner_.load()) {
            r->cancel();
          }
        }
      }
    });
  }
  ~StopOnSignal() {
    done_ = true;
    watcher_.join();
    pthread_sigmask(SIG_SETMASK, &saved_, nullptr);
  }
  StopOnSignal(const StopOnSignal&) = delete;
  StopOnSignal& operator=(const StopOnSignal&) = delete;
  bool signalled() const noexcept { return signalled_; }

 private:
  std::atomic<teach::BusRunner*>& runner_;
  sigset_t set_{};
  sigset_t saved_{};
  std::atomic<bool> done_{false};
  std::atomic<bool> signalled_{false};
  std::thread watcher_;
};

int play(Session& session, const TaskArgs& args) {
  auto t = load(args.file);
  if (!t) {
    return usage_or_failure(session, t.error());
  }
  const std::size_t n = t->task.steps.size();
  teach::PlaybackOptions options;
  options.direction = args.backward ? teach::Direction::kBackward : teach::Direction::kForward;
  const std::size_t from = args.from.value_or(1);
  const std::size_t to = args.to.value_or(n);
  if (from < 1 || to > n || from > to) {
    return session.fail(fmt::format("--from {} --to {} is not a range of {}'s {} steps (1..{})",
                                    from, to, args.file, n, n),
                        kExitUsage);
  }
  options.from = from - 1;
  options.to = to;
  if (args.speed) {
    if (!(*args.speed > 0.0 && *args.speed <= 1.0)) {
      return session.fail(fmt::format("--speed must be in (0, 1], got {}", *args.speed),
                          kExitUsage);
    }
    options.speed_override = *args.speed;
  }
  if (args.preview) {
    // Off line (the thesis's simulation): planned with the motion planner from the task's
    // first pose; no bus, nothing moves.
    std::optional<kinematics::JointVector> start;
    for (const auto& s : t->task.steps) {
      if (const auto* p = std::get_if<teach::PoseStep>(&s)) {
        start = p->joints;
        break;
      }
    }
    if (!start) {
      return session.fail(fmt::format("{} has no pose to start a preview from", args.file),
                          kExitUsage);
    }
    auto run = teach::simulate(t->task, t->model, *start, options);
    if (!run) {
      return usage_or_failure(session, run.error());
    }
    double total = 0.0;
    json steps = json::array();
    for (const auto& s : *run) {
      total = s.start_s + s.duration_s;
      if (session.json()) {
        steps.push_back({{"step", s.action.step_index + 1},
                         {"text", s.action.describe()},
                         {"start_s", s.start_s},
                         {"duration_s", s.duration_s},
                         {"joints", joints_json(t->model, s.samples.back())}});
      } else {
        session.out() << fmt::format("{:8.2f} s  {:6.2f} s  {}  -> {}\n", s.start_s, s.duration_s,
                                     s.action.describe(),
                                     joints_text(t->model, s.samples.back()));
      }
    }
    if (session.json()) {
      session.out() << json{{"file", args.file}, {"preview", true}, {"duration_s", total},
                            {"steps", steps}}
                           .dump(2)
                    << "\n";
    } else {
      session.out() << fmt::format("preview: {} steps in {:.2f} s (nothing moved)\n", run->size(),
                                   total);
    }
    return kExitOk;
  }
  std::atomic<teach::BusRunner*> current{nullptr};
  StopOnSignal stop(current);  // before the participant: DDS threads inherit the mask
  teach::BusRunnerOptions ro;
  ro.client_name = "cellctl-task";
  ro.operator_id = "cellctl";
  ro.match_timeout = session.timeout();
  teach::BusRunner runner(session.participant(), t->task.robot_id, ro);
  current = &runner;
  const bool tty = isatty(STDERR_FILENO) == 1;
  const auto started = std::chrono::steady_clock::now();
  auto report = teach::play(
      t->task, t->model, runner, options,
      [&](const teach::Action& a, std::size_t done, std::size_t total) {
        if (session.json()) {
          return;
        }
        const double elapsed =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
        session.err() << fmt::format("{}{} {}/{} {:6.1f} s  {}{}", tty ? "\r\033[K" : "",
                                     bar(done, total), done, total, elapsed, a.describe(),
                                     tty ? "" : "\n")
                      << std::flush;
      });
  current = nullptr;
  if (tty && !session.json()) {
    session.err() << "\n";
  }
  if (!report) {
    return usage_or_failure(session, report.error());
  }
  if (session.json()) {
    json out{{"file", args.file},
             {"robot", t->task.robot_id},
             {"ok", report->ok()},
             {"steps_done", report->steps_done},
             {"steps_total", report->steps_total},
             {"duration_s", report->duration_s},
             {"message", report->message}};
    if (report->failed_step) {
      out["failed_step"] = *report->failed_step + 1;
    }
    if (report->final_joints) {
      out["final_joints"] = joints_json(t->model, *report->final_joints);
    }
    session.out() << out.dump(2) << "\n";
  } else {
    session.out() << fmt::format("{}: {}\n", args.file, report->brief());
  }
  if (stop.signalled()) {
    return session.fail("interrupted: the robot was stopped");
  }
  return report->ok() ? kExitOk : session.fail(report->brief());
}

}  // namespace

void add_task_commands(CLI::App& app, Commands& commands) {
  auto args = std::make_shared<TaskArgs>();
  CLI::App* group = app.add_subcommand(
      "task", "task files: record poses and gripper steps, edit, play back (core/teach)");
  group->require_subcommand(1);

  CLI::App* rec = group->add_subcommand(
      "record", "append the robot's current pose (or a gripper step, a wait) to FILE");
  rec->add_option("file", args->file, "task file (YAML); created when missing")->required();
  rec->add_option("--robot", args->robot, "robot id (needed to start a new file)");
  rec->add_option("--name", args->name, "pose name (default p<n>)");
  rec->add_option("--move", args->move, "how the pose is reached: joint (default) or line");
  rec->add_option("--speed", args->speed, "this pose's speed, fraction (0, 1] of the limits");
  rec->add_option("--gripper", args->gripper, "record a gripper step instead: open or close");
  rec->add_option("--wait-s", args->wait_s, "record a wait of this many seconds instead");
  rec->add_option("--at", args->at, "insert before step N (1-based) instead of appending");
  rec->add_flag("--interactive", args->interactive,
                "teach from stdin: Enter records a pose, o/c gripper, w S wait, d undo, q quit");
  commands.add(rec, [args](Session& s) { return record(s, *args); });

  CLI::App* pl = group->add_subcommand(
      "play", "play FILE on the robot (or --preview: plan it off line, nothing moves)");
  pl->add_option("file", args->file, "task file (YAML)")->required()->check(CLI::ExistingFile);
  pl->add_flag("--preview", args->preview, "off line: plan every step, print times and joints");
  pl->add_flag("--backward", args->backward, "undo the steps, last to first");
  pl->add_option("--from", args->from, "first step (1-based, default 1)");
  pl->add_option("--to", args->to, "last step (1-based, default the last)");
  pl->add_option("--speed", args->speed, "override every pose's speed, fraction (0, 1]");
  commands.add(pl, [args](Session& s) { return play(s, *args); });

  CLI::App* sh = group->add_subcommand("show", "list FILE's steps with joints [deg, mm] and tool poses");
  sh->add_option("file", args->file, "task file (YAML)")->required()->check(CLI::ExistingFile);
  commands.add(sh, [args](Session& s) { return show(s, *args); });

  CLI::App* del = group->add_subcommand("delete", "delete step N of FILE");
  del->add_option("file", args->file, "task file (YAML)")->required()->check(CLI::ExistingFile);
  del->add_option("step", args->index, "step number (1-based)")->required();
  commands.add(del, [args](Session& s) {
    return edit(s, *args, [&](teach::Task& t) { return t.remove(args->index - 1); },
                fmt::format("step {} deleted", args->index));
  });

  CLI::App* mv = group->add_subcommand("move", "move step N of FILE to position M");
  mv->add_option("file", args->file, "task file (YAML)")->required()->check(CLI::ExistingFile);
  mv->add_option("step", args->index, "step number (1-based)")->required();
  mv->add_option("to", args->target, "new position (1-based)")->required();
  commands.add(mv, [args](Session& s) {
    if (args->target == 0) {
      return s.fail("steps are numbered from 1", kExitUsage);
    }
    return edit(s, *args, [&](teach::Task& t) { return t.move(args->index - 1, args->target - 1); },
                fmt::format("step {} moved to {}", args->index, args->target));
  });

  CLI::App* rn = group->add_subcommand("rename", "rename pose step N of FILE");
  rn->add_option("file", args->file, "task file (YAML)")->required()->check(CLI::ExistingFile);
  rn->add_option("step", args->index, "step number (1-based)")->required();
  rn->add_option("name", args->name, "new name")->required();
  commands.add(rn, [args](Session& s) {
    return edit(s, *args, [&](teach::Task& t) { return t.rename(args->index - 1, args->name); },
                fmt::format("step {} renamed '{}'", args->index, args->name));
  });
}

}  // namespace cell::cellctl
