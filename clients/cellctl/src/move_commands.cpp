// `cellctl move ...`: sends a MotionRequest (cell/motion/request) and follows its MotionStatus
// (cell/motion/status) until it is done, failed, refused or previewed.
#include <memory>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "cell/bus/request_reply.hpp"
#include "cell/bus/view.hpp"
#include "cell/common/time.hpp"
#include "cell/motion/wire.hpp"
#include "commands.hpp"
#include "robot_args.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;

struct MoveArgs {
  std::string robot;
  std::string joints;
  std::string pose;
  std::string branch;
  double distance_mm = 0.0;
  double speed = 1.0;
  bool preview = false;
  double wait_s = 120.0;
  bool cumulative = false;
  bool tool_frame = false;
};

std::string_view state_name(cell_motion_MotionState s) {
  switch (s) {
    case cell_motion_MOTION_ACCEPTED:
      return "accepted";
    case cell_motion_MOTION_REFUSED:
      return "refused";
    case cell_motion_MOTION_RUNNING:
      return "running";
    case cell_motion_MOTION_DONE:
      return "done";
    case cell_motion_MOTION_FAILED:
      return "failed";
    case cell_motion_MOTION_PREVIEW:
      return "preview";
  }
  return "unknown";
}

bool terminal(cell_motion_MotionState s) {
  return s == cell_motion_MOTION_REFUSED || s == cell_motion_MOTION_DONE ||
         s == cell_motion_MOTION_FAILED || s == cell_motion_MOTION_PREVIEW;
}

int move(Session& session, const MoveArgs& args, cell_motion_MotionKind kind) {
  // Validate locally what can be: a typo must not need a round trip to be reported.
  auto model = load_robot_by_id(args.robot);
  if (!model) {
    return session.fail(model.error().message, kExitUsage);
  }
  if (!(args.speed > 0 && args.speed <= 1)) {
    return session.fail(fmt::format("--speed must be in (0, 1], got {}", args.speed), kExitUsage);
  }
  cell_motion_MotionRequest request{};
  std::vector<double> joints;
  if (kind == cell_motion_MOTION_MOVE_JOINTS) {
    auto values = parse_numbers(args.joints, "--joints");
    if (!values) {
      return session.fail(values.error().message, kExitUsage);
    }
    auto q = joints_from_display(*model, *values, "--joints");
    if (!q) {
      return session.fail(q.error().message, kExitUsage);
    }
    joints.assign(q->data(), q->data() + q->size());
    bus::borrow(request.joints_rad_or_mm, joints);
  }
  const bool needs_pose = kind != cell_motion_MOTION_MOVE_JOINTS &&
                          kind != cell_motion_MOTION_DEPART && kind != cell_motion_MOTION_STOP &&
                          kind != cell_motion_MOTION_ALTER_OFF;
  if (needs_pose) {
    auto pose = pose_from_text(args.pose, "--pose");
    if (!pose) {
      return session.fail(pose.error().message, kExitUsage);
    }
    request.target = motion::to_idl(*pose);
  }
  const std::string motion_id = fmt::format("cellctl-{}", wall_time_ns());
  request.motion_id = bus::borrow(motion_id);
  request.robot_id = bus::borrow(args.robot);
  request.kind = kind;
  request.distance_mm = args.distance_mm;
  request.speed_scale = args.speed;
  request.branch = bus::borrow(args.branch);
  request.preview_only = args.preview;
  request.alter_cumulative = args.cumulative;
  request.alter_world_frame = !args.tool_frame;

  bus::Requester<cell_motion_MotionRequest, cell_motion_MotionStatus> requester(
      session.participant(), bus::topics::kMotionRequest, bus::topics::kMotionStatus,
      bus::make_client_id("cellctl"));
  auto seq = requester.send(request, session.timeout());
  if (!seq) {
    return session.fail(fmt::format("{} (is the motion service running on {}?)",
                                    seq.error().message, session.describe_bus()));
  }
  const auto deadline = std::chrono::steady_clock::now() +
                        std::chrono::milliseconds(static_cast<long>(args.wait_s * 1000));
  int last_quarter = -1;
  for (;;) {
    auto status = requester.wait_reply(*seq, deadline);
    if (!status) {
      return session.fail(fmt::format("motion '{}': {}", motion_id, status.error().message));
    }
    const cell_motion_MotionStatus& s = status->get();
    const int quarter = static_cast<int>(s.progress * 4);
    const bool news = s.state != cell_motion_MOTION_RUNNING || quarter != last_quarter;
    last_quarter = quarter;
    if (!session.json() && news) {
      session.err() << fmt::format("motion {}: {} {:.0f}%{}", motion_id, state_name(s.state),
                                   s.progress * 100,
                                   bus::str(s.reason).empty()
                                       ? std::string()
                                       : ": " + std::string(bus::str(s.reason)))
                    << "\n";
    }
    if (!terminal(s.state)) {
      continue;
    }
    const auto final_q = bus::span(s.final_joints_rad_or_mm);
    kinematics::JointVector q(static_cast<Eigen::Index>(final_q.size()));
    for (std::size_t j = 0; j < final_q.size(); ++j) {
      q[static_cast<Eigen::Index>(j)] = final_q[j];
    }
    const bool ok = s.state == cell_motion_MOTION_DONE || s.state == cell_motion_MOTION_PREVIEW;
    if (session.json()) {
      json out{{"motion_id", motion_id},
               {"robot", args.robot},
               {"state", std::string(state_name(s.state))},
               {"duration_s", s.duration_s}};
      if (!ok) {
        out["error_code"] = std::string(bus::str(s.error_code));
        out["reason"] = std::string(bus::str(s.reason));
      }
      if (static_cast<int>(final_q.size()) == model->dof()) {
        out["final_joints"] = joints_json(*model, q);
      }
      json path = json::array();
      for (const auto& p : bus::span(s.path)) {
        if (auto pose = motion::from_idl(p)) {
          path.push_back(pose_json(*pose));
        }
      }
      if (!path.empty()) {
        out["path"] = path;
      }
      session.out() << out.dump(2) << "\n";
    } else if (ok) {
      session.out() << fmt::format("{} in {:.3f} s", state_name(s.state), s.duration_s);
      if (static_cast<int>(final_q.size()) == model->dof()) {
        session.out() << "; final joints " << joints_text(*model, q);
      }
      session.out() << "\n";
    }
    return ok ? kExitOk : kExitFailure;
  }
}

struct Kind {
  const char* name;
  const char* help;
  cell_motion_MotionKind kind;
};

}  // namespace

void add_move_commands(CLI::App& app, Commands& commands) {
  auto args = std::make_shared<MoveArgs>();
  CLI::App* group = app.add_subcommand("move", "plan and run a motion through the motion service");
  group->require_subcommand(1);
  static constexpr Kind kKinds[] = {
      {"joints", "joint-interpolated move to --joints", cell_motion_MOTION_MOVE_JOINTS},
      {"pose", "joint-interpolated move to --pose (IK, --branch or nearest)",
       cell_motion_MOTION_MOVE_POSE},
      {"line", "straight line of the tool to --pose", cell_motion_MOTION_MOVE_LINEAR},
      {"approach", "to --distance above --pose", cell_motion_MOTION_APPROACH},
      {"depart", "straight --distance up from where the tool is", cell_motion_MOTION_DEPART},
      {"pick", "approach, descend to --pose, close, dwell, depart", cell_motion_MOTION_PICK},
      {"place", "approach, descend to --pose, open, dwell, depart", cell_motion_MOTION_PLACE},
      {"track", "straight line to --pose accepting ALTER corrections", cell_motion_MOTION_TRACK},
      {"stop", "stop the robot's motion", cell_motion_MOTION_STOP},
      {"alter-off", "end tracking: rest at destination + total correction",
       cell_motion_MOTION_ALTER_OFF},
  };
  for (const Kind& k : kKinds) {
    CLI::App* sub = group->add_subcommand(k.name, k.help);
    sub->add_option("--robot", args->robot, "robot id")->required();
    if (k.kind == cell_motion_MOTION_MOVE_JOINTS) {
      sub->add_option("--joints", args->joints, "a,b,c,... in deg or mm per joint")->required();
    } else if (k.kind != cell_motion_MOTION_DEPART && k.kind != cell_motion_MOTION_STOP &&
               k.kind != cell_motion_MOTION_ALTER_OFF) {
      sub->add_option("--pose", args->pose, "x,y,z [mm], roll,pitch,yaw [deg] (URDF rpy)")
          ->required();
    }
    if (k.kind == cell_motion_MOTION_MOVE_POSE) {
      sub->add_option("--branch", args->branch, "IK branch name (cellctl kin ik --all lists them)");
    }
    if (k.kind == cell_motion_MOTION_APPROACH || k.kind == cell_motion_MOTION_DEPART ||
        k.kind == cell_motion_MOTION_PICK || k.kind == cell_motion_MOTION_PLACE) {
      sub->add_option("--distance", args->distance_mm, "approach/depart distance [mm]");
    }
    if (k.kind == cell_motion_MOTION_TRACK) {
      sub->add_flag("--cumulative", args->cumulative, "ALTER corrections accumulate");
      sub->add_flag("--tool-frame", args->tool_frame, "ALTER corrections in the tool frame");
    }
    if (k.kind != cell_motion_MOTION_STOP && k.kind != cell_motion_MOTION_ALTER_OFF) {
      sub->add_option("--speed", args->speed, "fraction of the speed limits, (0, 1]");
      sub->add_flag("--preview", args->preview, "plan and show the path; do not move");
    }
    sub->add_option("--wait", args->wait_s, "seconds to wait for the motion to finish");
    const cell_motion_MotionKind kind = k.kind;
    commands.add(sub, [args, kind](Session& s) { return move(s, *args, kind); });
  }
}

}  // namespace cell::cellctl
