// `cellctl kin fk|ik`: the robots' kinematics from config/robots/<id>.yaml, computed locally
// (no bus): joints in deg or mm as each joint's config says, poses in mm and URDF rpy degrees.
#include <memory>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "commands.hpp"
#include "robot_args.hpp"
#include "table.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;

struct KinArgs {
  std::string robot;
  std::string joints;
  std::string pose;
  std::string seed;
  bool all = false;
};

int fk(Session& session, const KinArgs& args) {
  auto model = load_robot_by_id(args.robot);
  if (!model) {
    return session.fail(model.error().message, kExitUsage);
  }
  auto values = parse_numbers(args.joints, "--joints");
  if (!values) {
    return session.fail(values.error().message, kExitUsage);
  }
  auto q = joints_from_display(*model, *values, "--joints");
  if (!q) {
    return session.fail(q.error().message, kExitUsage);
  }
  auto pose = model->forward(*q);
  if (!pose) {
    return session.fail(pose.error().message);
  }
  const Status limits = model->check_limits(*q);
  if (session.json()) {
    json out{{"robot", model->id()},
             {"joints", joints_json(*model, *q)},
             {"pose", pose_json(*pose)},
             {"rpy_convention", "R = Rz(yaw) * Ry(pitch) * Rx(roll)"},
             {"within_limits", limits.has_value()}};
    if (!limits) {
      out["limit_error"] = limits.error().message;
    }
    session.out() << out.dump(2) << "\n";
  } else {
    session.out() << "robot " << model->id() << "\n  joints " << joints_text(*model, *q)
                  << "\n  tool   " << pose_text(*pose) << "\n";
    if (!limits) {
      session.out() << "  note   " << limits.error().message << "\n";
    }
  }
  return kExitOk;
}

int ik(Session& session, const KinArgs& args) {
  auto model = load_robot_by_id(args.robot);
  if (!model) {
    return session.fail(model.error().message, kExitUsage);
  }
  auto pose = pose_from_text(args.pose, "--pose");
  if (!pose) {
    return session.fail(pose.error().message, kExitUsage);
  }
  kinematics::JointVector seed = kinematics::JointVector::Zero(model->dof());
  if (!args.seed.empty()) {
    auto values = parse_numbers(args.seed, "--seed");
    if (!values) {
      return session.fail(values.error().message, kExitUsage);
    }
    auto q = joints_from_display(*model, *values, "--seed");
    if (!q) {
      return session.fail(q.error().message, kExitUsage);
    }
    seed = *q;
  }
  if (!args.all) {
    auto q = model->inverse(*pose, seed);
    if (!q) {
      if (session.json()) {
        session.out() << json{{"robot", model->id()}, {"error", q.error().message}}.dump(2) << "\n";
      }
      return session.fail(q.error().message);
    }
    if (session.json()) {
      session.out() << json{{"robot", model->id()}, {"joints", joints_json(*model, *q)}}.dump(2)
                    << "\n";
    } else {
      session.out() << "robot " << model->id() << " (branch nearest to the seed)\n  joints "
                    << joints_text(*model, *q) << "\n";
    }
    return kExitOk;
  }
  auto all = model->inverse_all(*pose, seed);
  if (!all) {
    if (session.json()) {
      session.out() << json{{"robot", model->id()}, {"error", all.error().message}}.dump(2) << "\n";
    }
    return session.fail(all.error().message);
  }
  json branches = json::array();
  Table table({"BRANCH", "JOINTS", "LIMITS"});
  for (const auto& s : *all) {
    const std::string limits =
        s.within_limits()
            ? "ok"
            : fmt::format("{} outside",
                          model->joints()[static_cast<std::size_t>(s.violated_joint)].name);
    branches.push_back({{"branch", std::string(s.branch)},
                        {"joints", joints_json(*model, s.q)},
                        {"within_limits", s.within_limits()},
                        {"singular", s.singular}});
    table.add_row({std::string(s.branch), joints_text(*model, s.q), limits});
  }
  if (session.json()) {
    session.out() << json{{"robot", model->id()}, {"branches", branches}}.dump(2) << "\n";
  } else {
    session.out() << "robot " << model->id() << ": " << all->size() << " branch(es)\n";
    table.print(session.out());
  }
  return kExitOk;
}

}  // namespace

void add_kin_commands(CLI::App& app, Commands& commands) {
  auto args = std::make_shared<KinArgs>();
  CLI::App* kin = app.add_subcommand("kin", "forward and inverse kinematics of a robot (local)");
  kin->require_subcommand(1);
  CLI::App* fk_cmd = kin->add_subcommand("fk", "tool pose of joint values");
  fk_cmd->add_option("--robot", args->robot, "robot id (config/robots/<id>.yaml)")->required();
  fk_cmd->add_option("--joints", args->joints, "joint values, deg or mm per joint: a,b,c,...")
      ->required();
  CLI::App* ik_cmd = kin->add_subcommand("ik", "joint values reaching a tool pose");
  ik_cmd->add_option("--robot", args->robot, "robot id (config/robots/<id>.yaml)")->required();
  ik_cmd->add_option("--pose", args->pose, "x,y,z [mm], roll,pitch,yaw [deg] (URDF rpy)")
      ->required();
  ik_cmd->add_option("--seed", args->seed, "joints the nearest branch is chosen from (deg/mm)");
  ik_cmd->add_flag("--all", args->all, "every branch, with its name and limit check");
  commands.add(fk_cmd, [args](Session& s) { return fk(s, *args); });
  commands.add(ik_cmd, [args](Session& s) { return ik(s, *args); });
}

}  // namespace cell::cellctl
