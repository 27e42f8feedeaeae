#include "cell/kinematics/robot_config.hpp"

#include <array>
#include <memory>
#include <optional>
#include <vector>

#include <fmt/format.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "model_issues.hpp"

namespace cell::kinematics {
namespace {

using geometry::deg_to_rad;

// The node at a dotted key path ("joints[2].upper_mm"), or the deepest existing ancestor, for
// error locations. Works on const nodes only: yaml-cpp's non-const operator[] may insert.
YAML::Node find_node(const YAML::Node& node, std::string_view path) {
  if (path.empty()) {
    return node;
  }
  const std::size_t dot = path.find('.');
  const std::string_view segment = path.substr(0, dot);
  const std::string_view rest = dot == std::string_view::npos ? "" : path.substr(dot + 1);
  const std::size_t bracket = segment.find('[');
  const std::string name(segment.substr(0, bracket));
  if (!node.IsMap()) {
    return node;
  }
  const YAML::Node child = node[name];
  if (!child.IsDefined()) {
    return node;
  }
  if (bracket == std::string_view::npos) {
    return find_node(child, rest);
  }
  const std::size_t index =
      std::strtoul(std::string(segment.substr(bracket + 1)).c_str(), nullptr, 10);
  if (!child.IsSequence() || index >= child.size()) {
    return child;
  }
  const YAML::Node element = child[index];
  return find_node(element, rest);
}

Error located(const config::Document& doc, const detail::Issues& issues) {
  std::string message;
  for (const detail::ConfigIssue& issue : issues) {
    message += message.empty() ? "" : "\n";
    message +=
        fmt::format("{}: key '{}': {}", config::location(doc.path, find_node(doc.root, issue.key)),
                    issue.key, issue.what);
  }
  return Error{Errc::kConfig, std::move(message)};
}

// Reads an enumerated string; records an error listing the choices when the value is unknown.
template <typename Enum, std::size_t N>
void read_enum(config::MapReader& r,
               const std::string& key,
               const std::array<std::pair<std::string_view, Enum>, N>& choices,
               Enum& out) {
  std::string text;
  r.optional(key, text);
  if (text.empty()) {
    return;
  }
  std::string names;
  for (const auto& [name, value] : choices) {
    if (name == text) {
      out = value;
      return;
    }
    names += names.empty() ? "" : " or ";
    names += name;
  }
  r.fail(key, fmt::format("must be {}, got '{}'", names, text));
}

void read_interval(config::MapReader& r, const std::string& key, std::optional<Interval>& out) {
  if (r.has(key)) {
    std::array<double, 2> bounds{};
    r.required(key, bounds);
    out = Interval{bounds[0], bounds[1]};
  }
}

JointSpec read_joint(config::MapReader& r) {
  JointSpec j;
  r.required("name", j.name);
  std::string type;
  r.required("type", type);
  static constexpr std::array<const char*, 10> kUnitKeys = {
      "lower_deg", "upper_deg", "max_speed_deg_s", "max_accel_deg_s2", "counts_per_deg",
      "lower_mm",  "upper_mm",  "max_speed_mm_s",  "max_accel_mm_s2",  "counts_per_mm"};
  if (type != "revolute" && type != "prismatic") {
    if (!type.empty()) {
      r.fail("type", fmt::format("must be revolute or prismatic, got '{}'", type));
    }
    for (const char* key : kUnitKeys) {
      (void)r.has(key);  // do not also report them as unknown
    }
    return j;
  }
  const bool revolute = type == "revolute";
  j.type = revolute ? JointType::kRevolute : JointType::kPrismatic;
  const std::string unit = revolute ? "deg" : "mm";
  double lower = 0.0;
  double upper = 0.0;
  double speed = 0.0;
  double counts = 0.0;
  r.required("lower_" + unit, lower);
  r.required("upper_" + unit, upper);
  r.required("max_speed_" + unit + "_s", speed);
  r.optional("counts_per_" + unit, counts);
  double accel = 4.0 * speed;  // default: full speed in 0.25 s (documented in JointSpec)
  r.optional("max_accel_" + unit + "_s2", accel);
  j.lower = j.from_display(lower);
  j.upper = j.from_display(upper);
  j.max_speed = j.from_display(speed);
  j.max_accel = j.from_display(accel);
  j.counts_per_unit = counts / j.from_display(1.0);  // counts per deg -> counts per rad
  if (r.has("overrun_counts")) {
    std::array<std::int64_t, 2> overrun{};
    r.required("overrun_counts", overrun);
    j.overrun_counts = overrun;
  }
  return j;
}

Eigen::Isometry3d read_tool(config::MapReader& root) {
  config::MapReader r = root.child("tool", false);
  std::array<double, 3> xyz{};
  std::array<double, 3> rpy_deg{};
  r.optional("xyz_mm", xyz);
  r.optional("rpy_deg", rpy_deg);
  root.absorb(r);
  return geometry::make_pose(
      Eigen::Vector3d(xyz[0], xyz[1], xyz[2]),
      geometry::Rpy{deg_to_rad(rpy_deg[0]), deg_to_rad(rpy_deg[1]), deg_to_rad(rpy_deg[2])});
}

CartesianLimits read_cartesian_limits(config::MapReader& root) {
  config::MapReader r = root.child("cartesian_limits", false);
  CartesianLimits limits;
  read_interval(r, "x_mm", limits.x);
  read_interval(r, "y_mm", limits.y);
  read_interval(r, "z_mm", limits.z);
  if (r.has("base_guard")) {
    config::MapReader g = r.child("base_guard");
    BaseGuard guard;
    g.required("radius_mm", guard.radius_mm);
    g.required("height_mm", guard.height_mm);
    r.absorb(g);
    limits.base_guard = guard;
  }
  root.absorb(r);
  return limits;
}

void read_scara(config::MapReader& root, ScaraModel& m) {
  config::MapReader r = root.child("scara");
  r.required("link1_mm", m.link1_mm);
  r.required("link2_mm", m.link2_mm);
  r.optional("z_at_zero_mm", m.z_at_zero_mm);
  read_enum(r, "z_positive",
            std::array{std::pair{std::string_view("up"), ZDirection::kUp},
                       std::pair{std::string_view("down"), ZDirection::kDown}},
            m.z_direction);
  read_enum(r, "roll_reference",
            std::array{std::pair{std::string_view("link2"), RollReference::kLink2},
                       std::pair{std::string_view("world"), RollReference::kWorld}},
            m.roll_reference);
  read_enum(
      r, "roll_positive",
      std::array{std::pair{std::string_view("counterclockwise"), RotationSense::kCounterClockwise},
                 std::pair{std::string_view("clockwise"), RotationSense::kClockwise}},
      m.roll_sense);
  root.absorb(r);
}

void read_excalibur(config::MapReader& root, ExcaliburModel& m) {
  config::MapReader r = root.child("excalibur");
  r.required("d1_mm", m.d1_mm);
  r.required("a2_mm", m.a2_mm);
  r.required("d4_mm", m.d4_mm);
  r.required("d6_mm", m.d6_mm);
  std::array<double, 6> offsets_deg{};
  r.optional("controller_offsets_deg", offsets_deg);
  for (std::size_t i = 0; i < 6; ++i) {
    m.controller_offset[i] = deg_to_rad(offsets_deg[i]);
  }
  read_enum(r, "wrist_singularity",
            std::array{std::pair{std::string_view("zero_theta4"), WristSingularity::kZeroTheta4},
                       std::pair{std::string_view("keep_theta4"), WristSingularity::kKeepTheta4}},
            m.wrist_singularity);
  root.absorb(r);
}

template <std::size_t N>
bool copy_joints(const std::vector<JointSpec>& joints, std::array<JointSpec, N>& out) {
  if (joints.size() != N) {
    return false;
  }
  std::copy(joints.begin(), joints.end(), out.begin());
  return true;
}

}  // namespace

Result<RobotModel> parse_robot(const config::Document& doc) {
  config::MapReader root(doc, doc.root, "");
  std::string id;
  std::string kind_text;
  std::string description;
  root.required("id", id);
  root.required("kind", kind_text);
  root.optional("description", description);
  std::optional<RobotKind> kind;
  if (kind_text == "scara") {
    kind = RobotKind::kScara;
  } else if (kind_text == "excalibur") {
    kind = RobotKind::kExcalibur;
  } else if (!kind_text.empty()) {
    root.fail("kind", fmt::format("must be scara or excalibur, got '{}'", kind_text));
  }

  std::vector<JointSpec> joints;
  const std::vector<YAML::Node> joint_nodes = root.sequence("joints");
  for (std::size_t i = 0; i < joint_nodes.size(); ++i) {
    config::MapReader jr = root.element(joint_nodes[i], fmt::format("joints[{}]", i));
    joints.push_back(read_joint(jr));
    root.absorb(jr);
  }
  const Eigen::Isometry3d tool = read_tool(root);
  const CartesianLimits limits = read_cartesian_limits(root);

  ScaraModel scara;
  ExcaliburModel excalibur;
  if (kind == RobotKind::kScara) {
    read_scara(root, scara);
  } else if (kind == RobotKind::kExcalibur) {
    read_excalibur(root, excalibur);
  } else {
    (void)root.has("scara");  // the kind error says it all; do not add unknown-key noise
    (void)root.has("excalibur");
  }
  const Status read = root.finish();
  if (!read) {
    return read.error();
  }

  detail::Issues issues;
  if (kind == RobotKind::kScara) {
    if (!copy_joints(joints, scara.joints)) {
      issues.push_back(
          {"joints", fmt::format("a scara needs 4 joints (J1, J2, Z, R), got {}", joints.size())});
      return located(doc, issues);
    }
    scara.flange_T_tool = tool;
    scara.cartesian_limits = limits;
    issues = detail::scara_issues(scara);
    if (!issues.empty()) {
      return located(doc, issues);
    }
    return RobotModel::create(id, std::move(scara), description);
  }
  if (!copy_joints(joints, excalibur.joints)) {
    issues.push_back({"joints", fmt::format("an excalibur needs 6 joints (theta1..theta6), got {}",
                                            joints.size())});
    return located(doc, issues);
  }
  excalibur.flange_T_tool = tool;
  excalibur.cartesian_limits = limits;
  issues = detail::excalibur_issues(excalibur);
  if (!issues.empty()) {
    return located(doc, issues);
  }
  return RobotModel::create(id, std::move(excalibur), description);
}

Result<RobotModel> load_robot(const std::string& path) {
  auto doc = config::load_file(path);
  if (!doc) {
    return std::move(doc).error();
  }
  return parse_robot(*doc);
}

}  // namespace cell::kinematics
