// `cellctl robot ...`: commands to a robot's gateway (cell/robot/command, answered on
// cell/robot/command_reply) and its latest state (cell/robot/state_latest).
#include <algorithm>
#include <memory>
#include <optional>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/view.hpp"
#include "cell/motion/wire.hpp"
#include "commands.hpp"
#include "robot_args.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;

struct RobotArgs {
  std::string robot;
  bool halogen = false;
  bool fluorescent = false;
};

int command(Session& session, const RobotArgs& args, cell_robot_RobotCommandKind kind,
            const char* what) {
  bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply> requester(
      session.participant(), bus::topics::kRobotCommand, bus::topics::kRobotCommandReply,
      bus::make_client_id("cellctl"));
  const std::string operator_id = "cellctl";
  cell_robot_RobotCommand c{};
  c.robot_id = bus::borrow(args.robot);
  c.kind = kind;
  c.halogen_on = args.halogen;
  c.fluorescent_on = args.fluorescent;
  c.operator_id = bus::borrow(operator_id);
  auto reply = requester.call(c, session.timeout());
  if (!reply) {
    return session.fail(fmt::format("{} '{}': {} (is gateway.{} running on {}?)", what,
                                    args.robot, reply.error().message, args.robot,
                                    session.describe_bus()));
  }
  const bool ok = (*reply)->status.accepted;
  if (session.json()) {
    json out{{"robot", args.robot}, {"command", what}, {"accepted", ok}};
    if (!ok) {
      out["reason"] = std::string(bus::str((*reply)->status.reason));
    }
    session.out() << out.dump(2) << "\n";
  } else if (ok) {
    session.out() << what << " '" << args.robot << "': accepted\n";
  }
  if (!ok) {
    return session.fail(fmt::format("{} '{}' refused: {}", what, args.robot,
                                    bus::str((*reply)->status.reason)));
  }
  return kExitOk;
}

std::string_view mode_name(cell_robot_RobotMode m) {
  switch (m) {
    case cell_robot_MODE_UNCONFIGURED:
      return "unconfigured";
    case cell_robot_MODE_IDLE:
      return "idle";
    case cell_robot_MODE_HOMING:
      return "homing";
    case cell_robot_MODE_MOVING:
      return "moving";
    case cell_robot_MODE_MANUAL:
      return "manual";
    case cell_robot_MODE_TEACH:
      return "teach";
    case cell_robot_MODE_PLAYBACK:
      return "playback";
    case cell_robot_MODE_FAULT:
      return "fault";
    case cell_robot_MODE_STOPPED:
      return "stopped";
  }
  return "unknown";
}

std::string_view gripper_name(cell_robot_GripperState g) {
  switch (g) {
    case cell_robot_GRIPPER_OPEN:
      return "open";
    case cell_robot_GRIPPER_CLOSED:
      return "closed";
    case cell_robot_GRIPPER_OPENING:
      return "opening";
    case cell_robot_GRIPPER_CLOSING:
      return "closing";
    default:
      return "unknown";
  }
}

int state(Session& session, const RobotArgs& args) {
  auto model = load_robot_by_id(args.robot);
  if (!model) {
    return session.fail(model.error().message, kExitUsage);
  }
  bus::Topic<cell_robot_RobotState> topic(session.participant(), bus::topics::kRobotStateLatest);
  bus::Reader<cell_robot_RobotState> reader(session.participant(), topic,
                                            bus::topics::kRobotStateLatest);
  // The robot's state, and its simulator's truth when one runs ("<robot>.sim", on the state
  // stream: the simulated board counts the late periods its grace absorbed, which the gateway
  // cannot see).
  bus::Topic<cell_robot_RobotState> stream_topic(session.participant(), bus::topics::kRobotState);
  bus::Reader<cell_robot_RobotState> stream(session.participant(), stream_topic,
                                            bus::topics::kRobotState);
  const std::string sim_id = args.robot + ".sim";
  std::optional<bus::Owned<cell_robot_RobotState>> found;
  std::optional<bus::Owned<cell_robot_RobotState>> sim;
  auto deadline = std::chrono::steady_clock::now() + session.timeout();
  while (std::chrono::steady_clock::now() < deadline && !(found && sim)) {
    reader.wait_for_data(std::chrono::milliseconds(100));
    auto batch = reader.take_copies(64);
    if (!batch) {
      return session.fail(batch.error().message);
    }
    for (auto& s : *batch) {
      const std::string_view id = bus::str(s->robot_id);
      if (id == args.robot) {
        if (!found) {  // the simulator's truth may follow: wait a little for it
          deadline = std::min(deadline, std::chrono::steady_clock::now() +
                                            std::chrono::milliseconds(200));
        }
        found = std::move(s);
      }
    }
    auto streamed = stream.take_copies(64);
    if (!streamed) {
      return session.fail(streamed.error().message);
    }
    for (auto& s : *streamed) {
      if (bus::str(s->robot_id) == sim_id) {
        sim = std::move(s);
      }
    }
  }
  if (found) {
    auto& s = *found;
    {
      const auto q_in = bus::span(s->position_rad_or_mm);
      if (static_cast<int>(q_in.size()) != model->dof()) {
        return session.fail(fmt::format("robot '{}' reports {} joints, its config {}", args.robot,
                                        q_in.size(), model->dof()));
      }
      kinematics::JointVector q(model->dof());
      for (int j = 0; j < model->dof(); ++j) {
        q[j] = q_in[static_cast<std::size_t>(j)];
      }
      auto pose = motion::from_idl(s->base_T_tool);
      if (session.json()) {
        session.out() << json{{"robot", args.robot},
                              {"mode", std::string(mode_name(s->mode))},
                              {"homed", s->homed},
                              {"moving", s->moving},
                              {"gripper", std::string(gripper_name(s->gripper))},
                              {"joints", joints_json(*model, q)},
                              {"tool", pose ? pose_json(*pose) : json()},
                              {"fault", std::string(bus::str(s->fault_text))},
                              {"trajectory_id", std::string(bus::str(s->trajectory_id))},
                              {"cycle_count", s->cycle_count},
                              {"cycle_period_s", s->cycle_period_s},
                              {"cycle_overruns", s->cycle_overruns},
                              {"cycle_jitter_max_us", s->cycle_jitter_max_us},
                              {"board", sim ? json{{"periods", (*sim)->cycle_count},
                                                   {"late_periods", (*sim)->cycle_overruns}}
                                            : json()}}
                             .dump(2)
                      << "\n";
      } else {
        session.out() << fmt::format("robot {}: {}{}{}, gripper {}\n  joints {}\n  tool   {}\n",
                                     args.robot, mode_name(s->mode),
                                     s->homed ? ", homed" : ", not homed",
                                     s->moving ? ", moving" : "", gripper_name(s->gripper),
                                     joints_text(*model, q), pose ? pose_text(*pose) : "?");
        session.out() << fmt::format(
            "  servo  {} cycles of {:.1f} ms, {} late, worst wake-up {:.0f} us late\n",
            s->cycle_count, s->cycle_period_s * 1e3, s->cycle_overruns, s->cycle_jitter_max_us);
        if (sim) {
          // A late period the board would have faulted on, served by the simulator's grace.
          session.out() << fmt::format(
              "  board  (simulated) {} periods, {} late (past the board's deadline: served "
              "within the simulator's grace or flagged)\n",
              (*sim)->cycle_count, (*sim)->cycle_overruns);
        }
        if (s->fault_text != nullptr && *s->fault_text != '\0') {
          session.out() << "  fault  " << s->fault_text << "\n";
        }
      }
      return kExitOk;
    }
  }
  return session.fail(fmt::format("no state from robot '{}' on {} (is its gateway running?)",
                                  args.robot, session.describe_bus()));
}

}  // namespace

void add_robot_commands(CLI::App& app, Commands& commands) {
  auto args = std::make_shared<RobotArgs>();
  CLI::App* group = app.add_subcommand("robot", "a robot's gateway: commands and state");
  group->require_subcommand(1);
  struct Cmd {
    const char* name;
    const char* help;
    cell_robot_RobotCommandKind kind;
  };
  static constexpr Cmd kCommands[] = {
      {"home", "find home (homing sequence)", cell_robot_CMD_HOME},
      {"open", "open the gripper", cell_robot_CMD_GRIPPER_OPEN},
      {"close", "close the gripper", cell_robot_CMD_GRIPPER_CLOSE},
      {"stop", "halt within one servo cycle", cell_robot_CMD_STOP},
      {"reset", "clear a fault or a stop", cell_robot_CMD_RESET},
      {"lights", "switch the lights (--halogen, --fluorescent)", cell_robot_CMD_LIGHTS},
  };
  for (const Cmd& c : kCommands) {
    CLI::App* sub = group->add_subcommand(c.name, c.help);
    sub->add_option("--robot", args->robot, "robot id")->required();
    if (c.kind == cell_robot_CMD_LIGHTS) {
      sub->add_flag("--halogen", args->halogen, "halogen lamp on");
      sub->add_flag("--fluorescent", args->fluorescent, "fluorescent lights on");
    }
    const auto kind = c.kind;
    const char* name = c.name;
    commands.add(sub, [args, kind, name](Session& s) { return command(s, *args, kind, name); });
  }
  CLI::App* st = group->add_subcommand("state", "the robot's latest state");
  st->add_option("--robot", args->robot, "robot id")->required();
  commands.add(st, [args](Session& s) { return state(s, *args); });
}

}  // namespace cell::cellctl
