#include "cell/task/job_spec.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>

#include <fmt/format.h>

#include "cell/config/pose.hpp"
#include "cell/config/yaml.hpp"
#include "cell/geometry/angles.hpp"

namespace cell::task {
namespace {

using geometry::kDeg;

std::vector<Slot> read_slots(config::MapReader& r) {
  std::vector<Slot> slots;
  for (const YAML::Node& node : r.sequence("slots", true)) {
    config::MapReader s = r.element(node, "place.slots");
    Slot slot;
    s.required("x_mm", slot.x_mm);
    s.required("y_mm", slot.y_mm);
    s.optional_deg("yaw_deg", slot.yaw_rad);
    r.absorb(s);
    slots.push_back(slot);
  }
  return slots;
}

PlacePattern read_place(config::MapReader& parent) {
  config::MapReader r = parent.child("place", true);
  PlacePattern p;
  std::string kind = "list";
  r.required("pattern", kind);
  if (kind == "list") {
    p.kind = PlacePattern::Kind::kList;
    p.slots = read_slots(r);
    if (p.slots.empty()) {
      r.fail("slots", "a list needs at least one slot");
    }
  } else if (kind == "row" || kind == "column" || kind == "grid") {
    std::array<double, 2> origin{};
    double yaw = 0.0;
    r.required("origin_mm", origin);
    r.optional_deg("yaw_deg", yaw);
    int columns = 1;
    int rows = 1;
    double pitch_x = 0.0;
    double pitch_y = 0.0;
    if (kind == "grid") {
      p.kind = PlacePattern::Kind::kGrid;
      r.required("columns", columns);
      r.required("rows", rows);
      r.required("pitch_x_mm", pitch_x);
      r.required("pitch_y_mm", pitch_y);
    } else {
      int count = 0;
      double pitch = 0.0;
      r.required("count", count);
      r.required("pitch_mm", pitch);
      if (kind == "row") {
        p.kind = PlacePattern::Kind::kRow;
        columns = count;
        pitch_x = pitch;
      } else {
        p.kind = PlacePattern::Kind::kColumn;
        rows = count;
        pitch_y = pitch;
      }
    }
    if (columns < 1 || rows < 1 || columns * rows > 10000) {
      r.fail("", fmt::format("needs 1 to 10000 slots, got {} x {}", columns, rows));
    } else if (!std::isfinite(pitch_x) || !std::isfinite(pitch_y) || !std::isfinite(origin[0]) ||
               !std::isfinite(origin[1])) {
      r.fail("", "origin and pitches must be finite");
    } else {
      for (int row = 0; row < rows; ++row) {
        for (int col = 0; col < columns; ++col) {
          p.slots.push_back(Slot{origin[0] + col * pitch_x, origin[1] + row * pitch_y, yaw});
        }
      }
    }
  } else {
    r.fail("pattern", fmt::format("must be list, row, column or grid, got '{}'", kind));
  }
  parent.absorb(r);
  return p;
}

void read_optional_height(config::MapReader& r, const std::string& key,
                          std::optional<double>& out) {
  if (r.has(key)) {
    double v = 0.0;
    r.required(key, v);
    out = v;
  }
}

void positive(config::MapReader& r, const std::string& key, double value, bool allow_zero) {
  if (!std::isfinite(value) || value < 0.0 || (!allow_zero && value == 0.0)) {
    r.fail(key, fmt::format("must be {}, got {}", allow_zero ? ">= 0" : "> 0", value));
  }
}

void speed(config::MapReader& r, double& out) {
  r.optional("speed_scale", out);
  if (!(out > 0.0 && out <= 1.0)) {
    r.fail("speed_scale", fmt::format("must be in (0, 1], got {}", out));
  }
}

TablePickPlaceSpec read_table(config::MapReader& r, const kinematics::RobotModel* robot) {
  TablePickPlaceSpec s;
  r.required("camera", s.camera);
  const auto windows = r.sequence("windows", true);
  for (std::size_t i = 0; i < windows.size(); ++i) {
    config::MapReader w = r.element(windows[i], fmt::format("windows[{}]", i));
    std::vector<double> joints;
    w.required("joints", joints);
    if (robot != nullptr) {
      const auto specs = robot->joints();
      if (joints.size() != specs.size()) {
        w.fail("joints", fmt::format("robot '{}' has {} joints, got {} values", robot->id(),
                                     specs.size(), joints.size()));
      } else {
        kinematics::JointVector q(static_cast<Eigen::Index>(joints.size()));
        for (std::size_t j = 0; j < joints.size(); ++j) {
          q[static_cast<Eigen::Index>(j)] = specs[j].from_display(joints[j]);
        }
        s.windows.push_back(q);
      }
    }
    r.absorb(w);
  }
  if (windows.empty()) {
    r.fail("windows", "needs at least one image window");
  }
  r.optional("classes", s.classes);
  r.optional("max_parts", s.max_parts);
  r.optional("travel_z_mm", s.travel_z_mm);
  read_optional_height(r, "pick_z_mm", s.pick_z_mm);
  read_optional_height(r, "place_z_mm", s.place_z_mm);
  r.optional("dwell_s", s.dwell_s);
  r.optional("settle_s", s.settle_s);
  r.optional("max_retries", s.max_retries);
  r.optional("return_home", s.return_home);
  if (r.has("lights")) {
    std::string lights;
    r.optional("lights", lights);
    static const std::map<std::string, TablePickPlaceSpec::Lights> kLights = {
        {"keep", TablePickPlaceSpec::Lights::kKeep},
        {"off", TablePickPlaceSpec::Lights::kOff},
        {"fluorescent", TablePickPlaceSpec::Lights::kFluorescent},
        {"halogen", TablePickPlaceSpec::Lights::kHalogen},
        {"both", TablePickPlaceSpec::Lights::kBoth}};
    if (auto it = kLights.find(lights); it != kLights.end()) {
      s.lights = it->second;
    } else {
      r.fail("lights",
             fmt::format("must be keep, off, fluorescent, halogen or both, got '{}'", lights));
    }
  }
  speed(r, s.speed_scale);
  positive(r, "dwell_s", s.dwell_s, true);
  positive(r, "settle_s", s.settle_s, true);
  if (s.max_parts < 0) {
    r.fail("max_parts", fmt::format("must be >= 0, got {}", s.max_parts));
  }
  if (s.max_retries < 0 || s.max_retries > 10) {
    r.fail("max_retries", fmt::format("must be in 0..10, got {}", s.max_retries));
  }
  s.place = read_place(r);
  return s;
}

ConveyorPickSpec read_conveyor(config::MapReader& r) {
  ConveyorPickSpec s;
  r.required("camera", s.camera);
  r.required("belt", s.belt);
  r.optional("duration_s", s.duration_s);
  r.optional("max_parts", s.max_parts);
  if (r.has("window")) {
    config::MapReader w = r.child("window", true);
    w.required("upstream_mm", s.upstream_mm);
    w.required("downstream_mm", s.downstream_mm);
    if (!(s.downstream_mm > s.upstream_mm)) {
      w.fail("downstream_mm", fmt::format("must be beyond upstream_mm ({}), got {}",
                                          s.upstream_mm, s.downstream_mm));
    }
    r.absorb(w);
  }
  r.optional("travel_z_mm", s.travel_z_mm);
  read_optional_height(r, "pick_z_mm", s.pick_z_mm);
  read_optional_height(r, "place_z_mm", s.place_z_mm);
  r.optional("dwell_s", s.dwell_s);
  r.optional("alter_period_s", s.alter_period_s);
  std::string track = "joint";
  r.optional("track_motion", track);
  if (track == "joint" || track == "line") {
    s.track_joint_interpolated = track == "joint";
  } else {
    r.fail("track_motion", fmt::format("must be joint or line, got '{}'", track));
  }
  if (r.has("ready_mm")) {
    std::vector<double> xy;
    r.optional("ready_mm", xy);
    if (xy.size() == 2 && std::isfinite(xy[0]) && std::isfinite(xy[1])) {
      s.ready_mm = Eigen::Vector2d(xy[0], xy[1]);
    } else {
      r.fail("ready_mm", fmt::format("must be [x, y] in mm, got {} value(s)", xy.size()));
    }
  }
  speed(r, s.speed_scale);
  positive(r, "duration_s", s.duration_s, true);
  positive(r, "dwell_s", s.dwell_s, true);
  if (!(s.alter_period_s >= 0.001 && s.alter_period_s <= 0.05)) {
    r.fail("alter_period_s", fmt::format("must be in [0.001, 0.05] s, got {}", s.alter_period_s));
  }
  if (s.max_parts < 0) {
    r.fail("max_parts", fmt::format("must be >= 0, got {}", s.max_parts));
  }
  if (s.duration_s == 0.0 && s.max_parts == 0) {
    r.fail("", "give duration_s or max_parts (or both): the job must end");
  }
  s.place = read_place(r);
  return s;
}

AssemblySpec read_assembly(config::MapReader& r) {
  AssemblySpec s;
  r.optional("program", s.program_path);
  r.optional("source", s.program_text);
  if (s.program_path.empty() == s.program_text.empty()) {
    r.fail("", "give exactly one of program (a file) and source (the text)");
  }
  if (r.has("cameras")) {
    config::MapReader c = r.child("cameras", true);
    for (const auto& kv : c.node()) {
      const std::string name = kv.first.as<std::string>("");
      std::string id;
      c.required(name, id);
      s.cameras[name] = id;
    }
    r.absorb(c);
  }
  std::string method = "actual";
  r.optional("method", method);
  if (method == "actual") {
    s.method = AssemblySpec::Method::kActual;
  } else if (method == "two_step_world") {
    s.method = AssemblySpec::Method::kTwoStepWorld;
  } else if (method == "two_step_destination") {
    s.method = AssemblySpec::Method::kTwoStepDestination;
  } else {
    r.fail("method", fmt::format("must be actual, two_step_world or two_step_destination, got "
                                 "'{}'",
                                 method));
  }
  r.optional("agent", s.agent);
  s.base_T_world = config::read_pose(r, "base_T_world");
  s.agent_T_tool = config::read_pose(r, "agent_T_tool");
  r.optional("verify", s.verify);
  r.optional("max_retries", s.max_retries);
  if (s.max_retries < 0 || s.max_retries > 10) {
    r.fail("max_retries", fmt::format("must be in 0..10, got {}", s.max_retries));
  }
  if (r.has("camera_tolerance")) {
    config::MapReader t = r.child("camera_tolerance", true);
    t.optional("mm", s.camera_tolerance_mm);
    t.optional("deg", s.camera_tolerance_deg);
    if (!(s.camera_tolerance_mm > 0) || !(s.camera_tolerance_deg > 0)) {
      t.fail("", "mm and deg must be positive");
    }
    r.absorb(t);
  }
  speed(r, s.speed_scale);
  return s;
}

}  // namespace

std::string_view to_string(JobKind kind) noexcept {
  switch (kind) {
    case JobKind::kTablePickPlace:
      return "table_pick_place";
    case JobKind::kConveyorPick:
      return "conveyor_pick";
    case JobKind::kAssembly:
      return "assembly";
  }
  return "unknown";
}

Result<JobSpec> parse_job_spec(const std::string& yaml, const std::string& origin,
                               const RobotLookup& robots) {
  auto doc = config::load_string(yaml, origin);
  if (!doc) {
    return std::move(doc).error();
  }
  if (!doc->root.IsMap()) {
    return Error{Errc::kConfig, fmt::format("{}: a job spec must be a YAML mapping", origin)};
  }
  config::MapReader r(*doc, doc->root, "");
  JobSpec job;
  std::string kind;
  r.required("kind", kind);
  r.required("robot", job.robot);
  r.optional("name", job.name);
  const kinematics::RobotModel* robot = robots ? robots(job.robot) : nullptr;
  if (!job.robot.empty() && robot == nullptr) {
    r.fail("robot", fmt::format("unknown robot '{}'", job.robot));
  }
  if (kind == "table_pick_place") {
    job.kind = JobKind::kTablePickPlace;
    job.body = read_table(r, robot);
  } else if (kind == "conveyor_pick") {
    job.kind = JobKind::kConveyorPick;
    job.body = read_conveyor(r);
  } else if (kind == "assembly") {
    job.kind = JobKind::kAssembly;
    job.body = read_assembly(r);
  } else {
    r.fail("kind", fmt::format("must be table_pick_place, conveyor_pick or assembly, got '{}'",
                               kind));
  }
  CELL_TRY(r.finish());
  return job;
}

Eigen::Isometry3d grasp_pose(const kinematics::RobotModel& robot, double x_mm, double y_mm,
                             double z_mm, double yaw_rad) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(x_mm, y_mm, z_mm);
  const Eigen::Matrix3d yaw = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).matrix();
  if (robot.kind() == kinematics::RobotKind::kScara) {
    pose.linear() = yaw;  // the SCARA's tool z is up (core/kinematics scara.hpp)
  } else {
    // A 6-axis arm approaches from above: tool z down, tool x along the part's x.
    pose.linear() = yaw * Eigen::AngleAxisd(std::numbers::pi, Eigen::Vector3d::UnitX()).matrix();
  }
  return pose;
}

namespace {

bool known(const std::vector<std::string>& ids, const std::string& id) {
  return std::find(ids.begin(), ids.end(), id) != ids.end();
}

/// Grasp heights of the classes a job may carry: the top of each part on the working plane.
std::vector<double> class_heights(const std::vector<std::string>& classes,
                                  const world::Catalogue& catalogue, double plane_z,
                                  std::vector<std::string>& reasons) {
  std::vector<double> heights;
  for (const auto& name : classes) {
    auto cls = catalogue.find(name);
    if (!cls) {
      reasons.push_back(fmt::format("unknown part class '{}' (known: {})", name, catalogue.list()));
      continue;
    }
    heights.push_back(plane_z + cls->part_T_grasp.translation().z());
  }
  return heights;
}

void check_slots(const kinematics::RobotModel& robot, const PlacePattern& place,
                 const std::vector<double>& place_heights, double travel_z,
                 std::vector<std::string>& reasons) {
  const kinematics::JointVector seed = kinematics::JointVector::Zero(robot.dof());
  for (std::size_t i = 0; i < place.slots.size(); ++i) {
    const Slot& slot = place.slots[i];
    std::vector<double> heights = place_heights;
    heights.push_back(travel_z);
    for (const double z : heights) {
      const auto pose = grasp_pose(robot, slot.x_mm, slot.y_mm, z, slot.yaw_rad);
      if (auto s = robot.cartesian_limits().check(pose.translation()); !s) {
        reasons.push_back(fmt::format("place slot {} at ({:.1f}, {:.1f}, {:.1f}) mm: {}", i,
                                      slot.x_mm, slot.y_mm, z, s.error().message));
        break;
      }
      if (auto q = robot.inverse(pose, seed); !q) {
        reasons.push_back(fmt::format("place slot {} at ({:.1f}, {:.1f}, {:.1f}) mm is not "
                                      "reachable: {}",
                                      i, slot.x_mm, slot.y_mm, z, q.error().message));
        break;
      }
    }
  }
}

}  // namespace

Status check_job(const JobSpec& job, const CellFacts& cell) {
  std::vector<std::string> reasons;
  const kinematics::RobotModel* robot = cell.robots ? cell.robots(job.robot) : nullptr;
  if (robot == nullptr) {
    reasons.push_back(fmt::format("unknown robot '{}'", job.robot));
  }
  const auto camera_known = [&](const std::string& id) {
    if (!known(cell.cameras, id)) {
      reasons.push_back(fmt::format("unknown camera '{}'", id));
    }
  };
  const auto plane = [&](const std::string& camera) -> std::optional<double> {
    return cell.working_plane_z_mm ? cell.working_plane_z_mm(camera) : std::nullopt;
  };
  const auto heights = [&](const std::vector<std::string>& classes, const std::string& camera,
                           const std::optional<double>& given) -> std::vector<double> {
    if (given) {
      return {*given};
    }
    const auto z = plane(camera);
    if (!z) {
      reasons.push_back(fmt::format("camera '{}' has no known working plane: give pick_z_mm",
                                    camera));
      return {};
    }
    if (cell.catalogue == nullptr) {
      return {};
    }
    std::vector<std::string> names = classes.empty() ? cell.catalogue->names() : classes;
    if (classes.empty()) {  // any class: the flat parts a gripper of this cell can take
      std::erase_if(names, [&](const std::string& n) {
        auto c = cell.catalogue->find(n);
        return !c || c->shape == world::Shape::kPolyhedron || c->shape == world::Shape::kBox;
      });
    }
    return class_heights(names, *cell.catalogue, *z, reasons);
  };
  if (const auto* t = job.table(); t != nullptr) {
    camera_known(t->camera);
    if (robot != nullptr) {
      for (std::size_t i = 0; i < t->windows.size(); ++i) {
        if (auto s = robot->check_limits(t->windows[i]); !s) {
          reasons.push_back(fmt::format("window {}: {}", i, s.error().message));
        }
      }
      const auto pick = heights(t->classes, t->camera, t->pick_z_mm);
      const auto place = t->place_z_mm ? std::vector<double>{*t->place_z_mm} : pick;
      check_slots(*robot, t->place, place, t->travel_z_mm, reasons);
    }
    if (t->max_parts > static_cast<int>(t->place.slots.size())) {
      reasons.push_back(fmt::format("max_parts {} exceeds the {} place slots", t->max_parts,
                                    t->place.slots.size()));
    }
  } else if (const auto* c = job.conveyor(); c != nullptr) {
    camera_known(c->camera);
    if (!known(cell.belts, c->belt)) {
      reasons.push_back(fmt::format("unknown belt '{}'", c->belt));
    }
    if (robot != nullptr) {
      const auto pick = heights({}, c->camera, c->pick_z_mm);
      const auto place = c->place_z_mm ? std::vector<double>{*c->place_z_mm} : pick;
      check_slots(*robot, c->place, place, c->travel_z_mm, reasons);
      if (c->ready_mm) {
        PlacePattern ready;
        ready.slots.push_back(Slot{c->ready_mm->x(), c->ready_mm->y(), 0.0});
        std::vector<std::string> why;
        check_slots(*robot, ready, {}, c->travel_z_mm, why);
        for (auto& w : why) {
          reasons.push_back("ready_mm: " + w.substr(w.find(" at (") + 1));
        }
      }
    }
  } else if (const auto* a = job.assembly(); a != nullptr) {
    for (const auto& [name, id] : a->cameras) {
      camera_known(id);
    }
  }
  if (reasons.empty()) {
    return ok_status();
  }
  std::string text;
  for (const auto& r : reasons) {
    text += (text.empty() ? "" : "\n") + r;
  }
  return Error{Errc::kOutOfRange, text};
}

}  // namespace cell::task
