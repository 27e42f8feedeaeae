// `cellctl world ...`: the simulated world's ground truth and edits, through cell-sim-world's
// request/reply pair (cell/world/request, answered on cell/world/reply).
#include <fmt/format.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <fstream>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cell/bus/request_reply.hpp"
#include "cell/bus/view.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/world/wire.hpp"
#include "commands.hpp"
#include "robot_args.hpp"
#include "table.hpp"

namespace cell::cellctl {
namespace {

using geometry::deg_to_rad;
using geometry::rad_to_deg;
using nlohmann::json;

struct WorldArgs {
  std::string scene;
  std::string class_name;
  std::string pose;
  std::string id;
  std::vector<std::string> ids;
  std::string belt;
  double speed_mm_s = 0.0;
  std::uint32_t count = 0;
  std::string classes;
  std::uint64_t seed = 1;
};

std::string_view kind_name(cell_world_WorldRequestKind kind) {
  switch (kind) {
    case cell_world_WORLD_QUERY:
      return "parts";
    case cell_world_WORLD_RESET:
      return "reset";
    case cell_world_WORLD_SPAWN:
      return "spawn";
    case cell_world_WORLD_REMOVE:
      return "remove";
    case cell_world_WORLD_SET_BELT:
      return "belt";
    case cell_world_WORLD_SCATTER:
      return "scatter";
  }
  return "request";
}

/// One part as JSON: pose in mm and deg (URDF roll, pitch, yaw), its grasp point in the world.
json part_json(const cell_world_WorldPart& p) {
  json out{{"id", std::string(bus::str(p.part_id))},
           {"class", std::string(bus::str(p.class_name))},
           {"support", std::string(bus::str(p.support))},
           {"length_mm", p.length_mm},
           {"width_mm", p.width_mm},
           {"height_mm", p.height_mm}};
  auto world_T_part = world::pose_from_idl(p.world_T_part);
  auto part_T_grasp = world::pose_from_idl(p.part_T_grasp);
  if (world_T_part && part_T_grasp) {
    out["pose"] = pose_json(*world_T_part);
    out["grasp"] = pose_json(*world_T_part * *part_T_grasp);
  }
  if (p.pins > 0) {
    out["pins"] = p.pins;
  }
  return out;
}

void print_parts(Session& session, std::span<const cell_world_WorldPart> parts) {
  Table table({"id", "class", "x [mm]", "y [mm]", "z [mm]", "yaw [deg]", "support"});
  for (const auto& p : parts) {
    auto pose = world::pose_from_idl(p.world_T_part);
    if (!pose) {
      table.add_row({std::string(bus::str(p.part_id)), std::string(bus::str(p.class_name)), "?",
                     "?", "?", "?", std::string(bus::str(p.support))});
      continue;
    }
    const Eigen::Vector3d t = pose->translation();
    const double yaw = std::atan2(pose->linear()(1, 0), pose->linear()(0, 0));
    table.add_row({std::string(bus::str(p.part_id)), std::string(bus::str(p.class_name)),
                   fmt::format("{:.2f}", t.x()), fmt::format("{:.2f}", t.y()),
                   fmt::format("{:.2f}", t.z()), fmt::format("{:.1f}", rad_to_deg(yaw)),
                   std::string(bus::str(p.support))});
  }
  table.print(session.out());
}

/// Sends `request`, prints the reply (parts as a table, or everything as JSON) and returns the
/// exit code: 0 accepted, 1 refused or no answer.
int send(Session& session, cell_world_WorldRequest& request, const std::string& done) {
  const std::string_view what = kind_name(request.kind);
  bus::Requester<cell_world_WorldRequest, cell_world_WorldReply> requester(
      session.participant(), bus::topics::kWorldRequest, bus::topics::kWorldReply,
      bus::make_client_id("cellctl"));
  auto reply = requester.call(request, session.timeout());
  if (!reply) {
    return session.fail(fmt::format("world {}: {} (is sim-world running on {}?)", what,
                                    reply.error().message, session.describe_bus()));
  }
  const cell_world_WorldReply& r = reply->get();
  const auto parts = bus::span(r.parts);
  if (session.json()) {
    json out{{"request", std::string(what)},
             {"accepted", r.status.accepted},
             {"world_seq", r.world_seq}};
    if (!r.status.accepted) {
      out["error_code"] = std::string(bus::str(r.status.error_code));
      out["reason"] = std::string(bus::str(r.status.reason));
    }
    json list = json::array();
    for (const auto& p : parts) {
      list.push_back(part_json(p));
    }
    out["parts"] = list;
    session.out() << out.dump(2) << "\n";
  }
  if (!r.status.accepted) {
    return session.fail(fmt::format("world {} refused: {}", what, bus::str(r.status.reason)));
  }
  if (!session.json()) {
    if (request.kind == cell_world_WORLD_QUERY || !parts.empty()) {
      print_parts(session, parts);
    }
    if (!done.empty()) {
      session.out() << done << "\n";
    }
  }
  return kExitOk;
}

int parts(Session& session) {
  cell_world_WorldRequest request{};
  request.kind = cell_world_WORLD_QUERY;
  return send(session, request, "");
}

int reset(Session& session, const WorldArgs& args) {
  cell_world_WorldRequest request{};
  request.kind = cell_world_WORLD_RESET;
  std::string text;
  if (!args.scene.empty()) {
    std::ifstream in(args.scene);
    if (!in) {
      return session.fail(
          fmt::format("--scene {}: cannot open: {}", args.scene, std::strerror(errno)), kExitUsage);
    }
    std::stringstream buffer;
    buffer << in.rdbuf();
    text = buffer.str();
    if (text.empty()) {
      return session.fail(fmt::format("--scene {}: the file is empty", args.scene), kExitUsage);
    }
  }
  request.scene_yaml = bus::borrow(text);
  request.scene_name = bus::borrow(args.scene);  // errors come back as "<file>:line:col"
  return send(session, request,
              args.scene.empty() ? "reset to the configured scene" : "reset to " + args.scene);
}

int spawn(Session& session, const WorldArgs& args) {
  auto values = parse_numbers(args.pose, "--pose");
  if (!values) {
    return session.fail(values.error().message, kExitUsage);
  }
  if (values->size() != 3) {
    return session.fail(
        fmt::format("--pose: expected x,y,yaw_deg (3 values), got {}", values->size()), kExitUsage);
  }
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.linear() =
      Eigen::AngleAxisd(deg_to_rad((*values)[2]), Eigen::Vector3d::UnitZ()).toRotationMatrix();
  pose.translation() = Eigen::Vector3d((*values)[0], (*values)[1], 0.0);
  std::vector<cell_world_WorldPart> parts(1);
  parts[0].part_id = bus::borrow(args.id);
  parts[0].class_name = bus::borrow(args.class_name);
  parts[0].world_T_part = world::pose_to_idl(pose);  // z is ignored: it drops onto what is below
  parts[0].part_T_grasp = world::pose_to_idl(Eigen::Isometry3d::Identity());
  cell_world_WorldRequest request{};
  request.kind = cell_world_WORLD_SPAWN;
  bus::borrow(request.parts, parts);
  return send(session, request, "");
}

int remove(Session& session, const WorldArgs& args) {
  std::vector<char*> ids;
  for (const auto& id : args.ids) {
    ids.push_back(bus::borrow(id));
  }
  cell_world_WorldRequest request{};
  request.kind = cell_world_WORLD_REMOVE;
  bus::borrow(request.part_ids, ids);
  std::string done = "removed";
  for (const auto& id : args.ids) {
    done += " " + id;
  }
  return send(session, request, done);
}

int belt(Session& session, const WorldArgs& args) {
  if (!std::isfinite(args.speed_mm_s)) {
    return session.fail("--speed must be a finite number of mm/s", kExitUsage);
  }
  cell_world_WorldRequest request{};
  request.kind = cell_world_WORLD_SET_BELT;
  request.belt_id = bus::borrow(args.belt);
  request.speed_mm_per_s = args.speed_mm_s;
  return send(session, request,
              fmt::format("belt '{}': speed {:.1f} mm/s", args.belt, args.speed_mm_s));
}

int scatter(Session& session, const WorldArgs& args) {
  if (args.count == 0) {
    return session.fail("--count must be > 0", kExitUsage);
  }
  std::vector<std::string> classes;
  std::stringstream in(args.classes);
  for (std::string c; std::getline(in, c, ',');) {
    if (c.empty()) {
      return session.fail(fmt::format("--classes '{}': an empty class name", args.classes),
                          kExitUsage);
    }
    classes.push_back(c);
  }
  std::vector<char*> names;
  names.reserve(classes.size());
  for (const auto& c : classes) {
    names.push_back(bus::borrow(c));
  }
  cell_world_WorldRequest request{};
  request.kind = cell_world_WORLD_SCATTER;
  request.count = args.count;
  request.seed = args.seed;
  bus::borrow(request.classes, names);
  return send(session, request, fmt::format("scattered {} parts (seed {})", args.count, args.seed));
}

}  // namespace

void add_world_commands(CLI::App& app, Commands& commands) {
  auto args = std::make_shared<WorldArgs>();
  CLI::App* group =
      app.add_subcommand("world", "the simulated world (cell-sim-world): ground truth and edits");
  group->require_subcommand(1);

  CLI::App* list = group->add_subcommand("parts", "every part: class, pose [mm, deg], support");
  commands.add(list, [](Session& s) { return parts(s); });

  CLI::App* rst = group->add_subcommand("reset", "replace the world by a scene file");
  rst->add_option("--scene", args->scene,
                  "scene YAML (config/scenes/*.yaml); omitted: the configured scene");
  commands.add(rst, [args](Session& s) { return reset(s, *args); });

  CLI::App* sp = group->add_subcommand("spawn", "add a part, dropped onto what is below it");
  sp->add_option("--class", args->class_name, "part class, e.g. dip14")->required();
  sp->add_option("--pose", args->pose, "x,y,yaw: mm, mm, deg (world frame)")->required();
  sp->add_option("--id", args->id, "part id (default: assigned)");
  commands.add(sp, [args](Session& s) { return spawn(s, *args); });

  CLI::App* rm = group->add_subcommand("remove", "remove parts");
  rm->add_option("--id", args->ids, "part id (repeat for several)")->required();
  commands.add(rm, [args](Session& s) { return remove(s, *args); });

  CLI::App* bt = group->add_subcommand("belt", "set a belt's speed");
  bt->add_option("--id", args->belt, "belt id")->required();
  bt->add_option("--speed", args->speed_mm_s, "mm/s, signed")->required();
  commands.add(bt, [args](Session& s) { return belt(s, *args); });

  CLI::App* sc = group->add_subcommand(
      "scatter", "add parts at random in the scene's scatter region (seeded: reproducible)");
  sc->add_option("--count", args->count, "how many parts")->required();
  sc->add_option("--classes", args->classes,
                 "a,b,...: classes to draw from (default: the scene's)");
  sc->add_option("--seed", args->seed, "random seed");
  commands.add(sc, [args](Session& s) { return scatter(s, *args); });
}

}  // namespace cell::cellctl
