#include "calibration_config.hpp"

#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/service/paths.hpp"

namespace cell::calibration_service {
namespace {

using geometry::kDeg;

Eigen::Isometry3d read_pose(config::MapReader& parent, const std::string& key) {
  config::MapReader r = parent.child(key, true);
  std::array<double, 3> xyz{};
  std::array<double, 3> rpy{};
  r.required("xyz_mm", xyz);
  r.optional("rpy_deg", rpy);
  parent.absorb(r);
  return geometry::make_pose(Eigen::Vector3d(xyz[0], xyz[1], xyz[2]),
                             geometry::Rpy{rpy[0] * kDeg, rpy[1] * kDeg, rpy[2] * kDeg});
}

void read_board(config::MapReader& parent, calibration::BoardSpec& board) {
  config::MapReader r = parent.child("board", true);
  std::string kind = "chessboard";
  r.optional("kind", kind);
  r.required("columns", board.columns);
  r.required("rows", board.rows);
  r.required("square_mm", board.square_mm);
  r.optional("marker_mm", board.marker_mm);
  r.optional("dictionary", board.dictionary);
  if (kind == "chessboard") {
    board.kind = calibration::BoardKind::kChessboard;
  } else if (kind == "charuco") {
    board.kind = calibration::BoardKind::kCharuco;
  } else {
    r.fail("kind", fmt::format("must be chessboard or charuco, got '{}'", kind));
  }
  if (auto s = board.validate(); !s) {
    r.fail("", s.error().message);
  }
  parent.absorb(r);
}

void read_sim(config::MapReader& parent, SimSetup& sim) {
  if (!parent.has("sim")) {
    return;
  }
  config::MapReader r = parent.child("sim", false);
  sim.enabled = true;
  r.required("scene_file", sim.scene_file);
  r.optional("restore", sim.restore);
  if (!sim.scene_file.empty()) {
    sim.scene_file = service::resolve_path(sim.scene_file);
    std::ifstream f(sim.scene_file);
    if (!f) {
      r.fail("scene_file", fmt::format("cannot read '{}'", sim.scene_file));
    } else {
      std::stringstream ss;
      ss << f.rdbuf();
      sim.scene_text = ss.str();
    }
  }
  if (r.has("board_on_table")) {
    config::MapReader b = r.child("board_on_table", false);
    std::array<double, 3> xyz{};
    double yaw_deg = 0.0;
    b.required("xyz_mm", xyz);
    b.optional("yaw_deg", yaw_deg);
    sim.board_on_table = true;
    sim.board_world_mm = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
    sim.board_yaw_rad = yaw_deg * kDeg;
    r.absorb(b);
  }
  for (const YAML::Node& node : r.sequence("markers", false)) {
    config::MapReader m = r.element(node, "markers[]");
    SimSetup::Marker marker;
    m.required("class", marker.class_name);
    m.required("x_mm", marker.x_mm);
    m.required("y_mm", marker.y_mm);
    sim.markers.push_back(marker);
    r.absorb(m);
  }
  parent.absorb(r);
}

/// Joint values in the robot file's display units (deg, mm) -> rad, mm.
kinematics::JointVector joints_from_display(const kinematics::RobotModel& robot,
                                            const std::vector<double>& values) {
  kinematics::JointVector q(robot.dof());
  for (int j = 0; j < robot.dof(); ++j) {
    q[j] = robot.joints()[static_cast<std::size_t>(j)].from_display(
        values[static_cast<std::size_t>(j)]);
  }
  return q;
}

void read_capture(config::MapReader& parent, const kinematics::RobotModel* robot,
                  BoardCapture& c) {
  read_board(parent, c.board);
  if (parent.has("board_nominal")) {
    c.base_T_board_nominal = read_pose(parent, "board_nominal");
  }
  parent.optional("speed_scale", c.speed_scale);
  parent.optional("settle_s", c.settle_s);
  if (!(c.speed_scale > 0.0 && c.speed_scale <= 1.0)) {
    parent.fail("speed_scale", fmt::format("must be in (0, 1], got {}", c.speed_scale));
  }
  if (!(c.settle_s >= 0.0)) {
    parent.fail("settle_s", fmt::format("must be >= 0, got {}", c.settle_s));
  }
  if (parent.has("lights")) {
    config::MapReader l = parent.child("lights", false);
    l.required("robot_id", c.lights_robot_id);
    l.optional("halogen", c.halogen);
    l.optional("fluorescent", c.fluorescent);
    parent.absorb(l);
  }
  config::MapReader p = parent.child("pose_set", true);
  p.optional("generate", c.generate);
  if (c.generate) {
    p.optional("count", c.count);
    std::int64_t seed = 1;
    p.optional("seed", seed);
    c.seed = static_cast<std::uint64_t>(seed);
    p.optional("margin_px", c.margin_px);
    if (c.count < 3) {
      p.fail("count", fmt::format("must be >= 3, got {}", c.count));
    }
    for (const YAML::Node& node : p.sequence("joint_ranges", true)) {
      if (!node.IsSequence() || node.size() != 2) {
        p.fail("joint_ranges", "each entry is [low, high] in the robot's units (deg, mm)");
        continue;
      }
      c.joint_ranges.emplace_back(node[0].as<double>(0.0), node[1].as<double>(0.0));
    }
    if (robot != nullptr) {
      if (static_cast<int>(c.joint_ranges.size()) != robot->dof()) {
        p.fail("joint_ranges", fmt::format("robot '{}' has {} joints, {} ranges given",
                                           robot->id(), robot->dof(), c.joint_ranges.size()));
      } else {
        for (int j = 0; j < robot->dof(); ++j) {
          auto& range = c.joint_ranges[static_cast<std::size_t>(j)];
          const auto& spec = robot->joints()[static_cast<std::size_t>(j)];
          range = {spec.from_display(range.first), spec.from_display(range.second)};
          if (range.second < range.first) {
            p.fail("joint_ranges", fmt::format("joint {}: low above high", spec.name));
          }
        }
      }
    }
  } else {
    for (const YAML::Node& node : p.sequence("poses", true)) {
      std::vector<double> values;
      try {
        values = node.as<std::vector<double>>();
      } catch (const YAML::Exception&) {
        p.fail("poses", "each pose is a list of joint values (deg, mm)");
        continue;
      }
      if (robot != nullptr && static_cast<int>(values.size()) != robot->dof()) {
        p.fail("poses", fmt::format("robot '{}' has {} joints, a pose gives {}", robot->id(),
                                    robot->dof(), values.size()));
        continue;
      }
      if (robot != nullptr) {
        c.poses.push_back(joints_from_display(*robot, values));
      }
    }
    if (c.poses.size() < 3 && robot != nullptr) {
      p.fail("poses", fmt::format("at least 3 poses needed, got {}", c.poses.size()));
    }
  }
  parent.absorb(p);
}

Result<config::Document> load_procedure_file(const std::string& path) {
  return config::load_file(service::resolve_path(path));
}

}  // namespace

const CameraEntry* CalibrationConfig::camera(const std::string& id) const {
  for (const auto& c : cameras) {
    if (c.camera.id == id) {
      return &c;
    }
  }
  return nullptr;
}
const BeltEntry* CalibrationConfig::belt_entry(const std::string& id) const {
  for (const auto& b : belts) {
    if (b.belt_id == id) {
      return &b;
    }
  }
  return nullptr;
}
const HandEyeProcedure* CalibrationConfig::hand_eye_for(const std::string& id) const {
  for (const auto& p : hand_eye) {
    if (p.camera_id == id) {
      return &p;
    }
  }
  return nullptr;
}
const PlanarProcedure* CalibrationConfig::planar_for(const std::string& id) const {
  for (const auto& p : planar) {
    if (p.camera_id == id) {
      return &p;
    }
  }
  return nullptr;
}
const BeltProcedure* CalibrationConfig::belt_for(const std::string& id) const {
  for (const auto& p : belt) {
    if (p.belt_id == id) {
      return &p;
    }
  }
  return nullptr;
}
const kinematics::RobotModel* CalibrationConfig::robot(const std::string& id) const {
  const auto it = robots.find(id);
  return it == robots.end() ? nullptr : &it->second;
}

Result<CalibrationConfig> load_config(const config::Document& doc) {
  CalibrationConfig c;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, c.common);
  root.optional("store_dir", c.store_dir);
  root.optional("robots_dir", c.robots_dir);
  const std::string robots_dir = service::resolve_path(c.robots_dir);
  auto robot_for = [&](config::MapReader& r, const std::string& key,
                       const std::string& id) -> const kinematics::RobotModel* {
    if (id.empty()) {
      return nullptr;
    }
    if (auto it = c.robots.find(id); it != c.robots.end()) {
      return &it->second;
    }
    auto model = kinematics::load_robot(robots_dir + "/" + id + ".yaml");
    if (!model) {
      r.fail(key, fmt::format("robot '{}': {}", id, model.error().message));
      return nullptr;
    }
    return &c.robots.emplace(id, std::move(*model)).first->second;
  };
  for (const YAML::Node& node : root.sequence("cameras", true)) {
    config::MapReader r = root.element(node, "cameras[]");
    std::string file;
    CameraEntry e;
    r.required("camera_file", file);
    r.optional("robot_id", e.robot_id);
    r.required("working_plane_z_mm", e.working_plane_z_mm);
    if (r.has("robot_world_T_base")) {
      e.robot_world_T_base = read_pose(r, "robot_world_T_base");
    }
    auto camera = render::load_camera(service::resolve_path(file));
    if (!camera) {
      r.fail("camera_file", camera.error().message);
    } else {
      e.camera = std::move(*camera);
      if (e.camera.mount == render::MountKind::kEyeInHand) {
        e.robot_id = e.camera.robot.robot_id;
      } else if (e.robot_id.empty()) {
        r.fail("robot_id", fmt::format("fixed camera '{}' needs the robot whose base its "
                                       "calibration refers to",
                                       e.camera.id));
      }
      (void)robot_for(r, "robot_id", e.robot_id);
      auto nominal = calibration::nominal_calibration(e.camera, e.robot_id, e.robot_world_T_base,
                                                      e.working_plane_z_mm);
      if (!nominal) {
        r.fail("", nominal.error().message);
      } else {
        e.nominal = std::move(*nominal);
      }
      if (c.camera(e.camera.id) != nullptr) {
        r.fail("camera_file", fmt::format("camera '{}' listed twice", e.camera.id));
      }
      c.cameras.push_back(std::move(e));
    }
    root.absorb(r);
  }
  for (const YAML::Node& node : root.sequence("belts", false)) {
    config::MapReader r = root.element(node, "belts[]");
    BeltEntry b;
    r.required("belt_id", b.belt_id);
    r.required("robot_id", b.robot_id);
    r.required("camera_id", b.camera_id);
    r.required("surface_z_mm", b.surface_z_mm);
    if (!b.camera_id.empty() && c.camera(b.camera_id) == nullptr) {
      r.fail("camera_id", fmt::format("camera '{}' is not among the cameras", b.camera_id));
    }
    c.belts.push_back(b);
    root.absorb(r);
  }
  if (root.has("intrinsics")) {
    config::MapReader r = root.child("intrinsics", false);
    std::string lens = "radial_tangential";
    r.optional("lens", lens);
    r.optional("holdout_fraction", c.intrinsics.holdout_fraction);
    r.optional("huber_px", c.intrinsics.huber_px);
    r.optional("outlier_factor", c.intrinsics.outlier_factor);
    r.optional("min_fit_views", c.intrinsics.min_fit_views);
    if (lens == "none") {
      c.intrinsics.lens = calibration::LensModel::kNone;
    } else if (lens == "radial") {
      c.intrinsics.lens = calibration::LensModel::kRadial2;
    } else if (lens == "radial_tangential") {
      c.intrinsics.lens = calibration::LensModel::kRadialTangential;
    } else if (lens == "full") {
      c.intrinsics.lens = calibration::LensModel::kFull;
    } else {
      r.fail("lens", fmt::format("must be none, radial, radial_tangential or full, got '{}'", lens));
    }
    if (auto s = c.intrinsics.validate(); !s) {
      r.fail("", s.error().message);
    }
    root.absorb(r);
  }
  if (root.has("timeouts")) {
    config::MapReader r = root.child("timeouts", false);
    r.optional("motion_s", c.timeouts.motion_s);
    r.optional("image_s", c.timeouts.image_s);
    r.optional("world_s", c.timeouts.world_s);
    r.optional("discovery_s", c.timeouts.discovery_s);
    for (const auto& [key, v] : {std::pair{"motion_s", c.timeouts.motion_s},
                                 std::pair{"image_s", c.timeouts.image_s},
                                 std::pair{"world_s", c.timeouts.world_s},
                                 std::pair{"discovery_s", c.timeouts.discovery_s}}) {
      if (!(v > 0.0)) {
        r.fail(key, fmt::format("must be > 0, got {}", v));
      }
    }
    root.absorb(r);
  }
  std::vector<std::string> files;
  root.optional("procedures", files);
  CELL_TRY(root.finish());

  // The procedure files: each reports its own errors with its own file:line.
  std::vector<std::string> errors;
  for (const std::string& file : files) {
    auto pdoc = load_procedure_file(file);
    if (!pdoc) {
      errors.push_back(pdoc.error().message);
      continue;
    }
    config::MapReader r(*pdoc, pdoc->root, "");
    std::string kind;
    r.required("procedure", kind);
    if (kind == "hand_eye" || kind == "planar") {
      std::string camera_id;
      std::string robot_id;
      r.required("camera_id", camera_id);
      r.optional("robot_id", robot_id);
      const CameraEntry* cam = c.camera(camera_id);
      if (cam == nullptr) {
        r.fail("camera_id", fmt::format("camera '{}' is not among config/calibration.yaml's "
                                        "cameras",
                                        camera_id));
      } else if (robot_id.empty()) {
        robot_id = cam->robot_id;
      }
      const kinematics::RobotModel* robot = robot_for(r, "robot_id", robot_id);
      BoardCapture capture;
      read_capture(r, robot, capture);
      SimSetup sim;
      read_sim(r, sim);
      if (kind == "hand_eye") {
        HandEyeProcedure p;
        p.camera_id = camera_id;
        p.robot_id = robot_id;
        p.capture = capture;
        p.sim = sim;
        if (cam != nullptr) {
          p.options.setup = cam->camera.mount == render::MountKind::kEyeInHand
                                ? calibration::HandEyeSetup::kEyeInHand
                                : calibration::HandEyeSetup::kEyeToHand;
        }
        p.options.planar = robot != nullptr && robot->scara() != nullptr;
        config::MapReader h = r.child("hand_eye", false);
        h.optional("planar", p.options.planar);
        h.optional("planar_target_z_mm", p.options.planar_target_z_mm);
        h.optional("planar_target_level", p.options.planar_target_level);
        h.optional("pixel_sigma_px", p.options.pixel_sigma_px);
        h.optional("robot_rotation_sigma_deg", p.options.robot_rotation_sigma_deg);
        h.optional("robot_translation_sigma_mm", p.options.robot_translation_sigma_mm);
        h.optional("holdout_fraction", p.options.holdout_fraction);
        h.optional("min_rotation_deg", p.options.min_rotation_deg);
        if (auto s = p.options.validate(); !s) {
          h.fail("", s.error().message);
        }
        r.absorb(h);
        c.hand_eye.push_back(p);
      } else {
        PlanarProcedure p;
        p.camera_id = camera_id;
        p.robot_id = robot_id;
        p.capture = capture;
        p.sim = sim;
        config::MapReader h = r.child("planar", false);
        std::array<double, 2> ref{3.0, 457.0};
        h.optional("ref_px", ref);
        p.ref_px = Eigen::Vector2d(ref[0], ref[1]);
        h.optional("refine_links", p.refine_links);
        r.absorb(h);
        if (robot != nullptr && robot->scara() == nullptr) {
          r.fail("robot_id", fmt::format("the planar model is a SCARA's; '{}' is not one",
                                         robot_id));
        }
        c.planar.push_back(p);
      }
    } else if (kind == "belt") {
      BeltProcedure p;
      r.required("belt_id", p.belt_id);
      if (!p.belt_id.empty() && c.belt_entry(p.belt_id) == nullptr) {
        r.fail("belt_id", fmt::format("belt '{}' is not among config/calibration.yaml's belts",
                                      p.belt_id));
      }
      config::MapReader m = r.child("marker", false);
      m.optional("bright", p.marker.bright);
      m.optional("min_area_px", p.marker.min_area_px);
      m.optional("max_area_px", p.marker.max_area_px);
      m.optional("threshold", p.marker.threshold);
      m.optional("background_px", p.marker.background_px);
      m.optional("height_mm", p.marker_height_mm);
      if (auto s = p.marker.validate(); !s) {
        m.fail("", s.error().message);
      }
      r.absorb(m);
      r.optional("samples", p.samples);
      r.optional("period_s", p.period_s);
      r.optional("max_duration_s", p.max_duration_s);
      r.optional("track_gate_mm", p.track_gate_mm);
      if (p.samples < 3) {
        r.fail("samples", fmt::format("must be >= 3, got {}", p.samples));
      }
      if (!(p.period_s > 0.0) || !(p.max_duration_s > p.period_s)) {
        r.fail("period_s", "need 0 < period_s < max_duration_s");
      }
      read_sim(r, p.sim);
      c.belt.push_back(p);
    } else {
      r.fail("procedure", fmt::format("must be hand_eye, planar or belt, got '{}'", kind));
    }
    if (auto s = r.finish(); !s) {
      errors.push_back(s.error().message);
    }
  }
  if (!errors.empty()) {
    std::string all;
    for (const auto& e : errors) {
      all += (all.empty() ? "" : "\n") + e;
    }
    return Error{Errc::kConfig, all};
  }
  if (auto s = c.common.validate(); !s) {
    return with_context(s.error(), doc.path);
  }
  return c;
}

std::string sim_scene_yaml(const SimSetup& sim, const calibration::BoardSpec* board) {
  YAML::Node scene = YAML::Load(sim.scene_text);
  scene.remove("parts");
  scene.remove("scatter");
  scene["min_separation_mm"] = 0.0;
  YAML::Node classes = scene["classes"];
  YAML::Node parts(YAML::NodeType::Sequence);
  if (sim.board_on_table && board != nullptr) {
    // Black squares stuck on the white table: square (i, j) of the board is black when i + j
    // is even (render::Chessboard's convention, board.hpp). A hair smaller than the square so
    // that diagonal neighbours do not touch (the world refuses overlapping parts).
    YAML::Node cls;
    cls["name"] = "calibration_square";
    cls["shape"] = "square";
    cls["length_mm"] = board->square_mm - 0.002;
    cls["height_mm"] = 0.2;
    cls["reflectance"] = 0.05;
    cls["description"] = "a black square of a chessboard sticker (calibration)";
    classes.push_back(cls);
    const double c = std::cos(sim.board_yaw_rad);
    const double s = std::sin(sim.board_yaw_rad);
    int k = 0;
    for (int j = 0; j <= board->rows; ++j) {
      for (int i = 0; i <= board->columns; ++i) {
        if ((i + j) % 2 != 0) {
          continue;
        }
        const double bx = (i + 0.5) * board->square_mm;
        const double by = (j + 0.5) * board->square_mm;
        YAML::Node p;
        p["id"] = fmt::format("calib_sq{}", k++);
        p["class"] = "calibration_square";
        p["x_mm"] = sim.board_world_mm.x() + c * bx - s * by;
        p["y_mm"] = sim.board_world_mm.y() + s * bx + c * by;
        p["yaw_deg"] = sim.board_yaw_rad / kDeg;
        parts.push_back(p);
      }
    }
  }
  int m = 0;
  for (const SimSetup::Marker& marker : sim.markers) {
    YAML::Node p;
    p["id"] = fmt::format("calib_marker{}", m++);
    p["class"] = marker.class_name;
    p["x_mm"] = marker.x_mm;
    p["y_mm"] = marker.y_mm;
    p["yaw_deg"] = 0.0;
    parts.push_back(p);
  }
  scene["classes"] = classes;
  scene["parts"] = parts;
  YAML::Emitter out;
  out.SetDoublePrecision(12);
  out << scene;
  return out.c_str();
}

}  // namespace cell::calibration_service
