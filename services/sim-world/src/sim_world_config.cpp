#include "sim_world_config.hpp"

#include <fmt/format.h>

#include <array>
#include <cmath>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/service/paths.hpp"

namespace cell::sim_world {

using geometry::deg_to_rad;

Status SimWorldConfig::validate() const {
  if (!(step_hz >= 10.0 && step_hz <= 10000.0)) {
    return Error{Errc::kConfig, fmt::format("step_hz must be in [10, 10000], got {}", step_hz)};
  }
  if (!(world_state_hz > 0.0 && world_state_hz <= step_hz)) {
    return Error{Errc::kConfig, fmt::format("world_state_hz must be in (0, step_hz = {}], got {}",
                                            step_hz, world_state_hz)};
  }
  if (!(belt_state_hz > 0.0 && belt_state_hz <= step_hz)) {
    return Error{Errc::kConfig, fmt::format("belt_state_hz must be in (0, step_hz = {}], got {}",
                                            step_hz, belt_state_hz)};
  }
  if (scene.empty()) {
    return Error{Errc::kConfig, "scene must name a scene file"};
  }
  if (auto s = world.validate(); !s) {
    return Error{Errc::kConfig, s.error().message};
  }
  return ok_status();
}

Result<SimWorldConfig> load_config(const config::Document& doc) {
  SimWorldConfig c;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, c.common);
  root.required("scene", c.scene);
  root.optional("step_hz", c.step_hz);
  root.optional("world_state_hz", c.world_state_hz);
  root.optional("belt_state_hz", c.belt_state_hz);
  if (!(c.step_hz >= 10.0 && c.step_hz <= 10000.0)) {
    root.fail("step_hz", fmt::format("must be in [10, 10000], got {}", c.step_hz));
  }
  for (const char* key : {"world_state_hz", "belt_state_hz"}) {
    const double v = std::string_view(key) == "world_state_hz" ? c.world_state_hz : c.belt_state_hz;
    if (!(v > 0.0 && v <= c.step_hz)) {
      root.fail(key, fmt::format("must be in (0, step_hz = {}], got {}", c.step_hz, v));
    }
  }
  const auto robots = root.sequence("robots", false);
  for (std::size_t i = 0; i < robots.size(); ++i) {
    config::MapReader r = root.element(robots[i], fmt::format("robots[{}]", i));
    world::RobotMount mount;
    std::array<double, 3> xyz{0, 0, 0};
    std::array<double, 3> rpy_deg{0, 0, 0};
    r.required("id", mount.robot_id);
    r.required("xyz_mm", xyz);
    r.optional("rpy_deg", rpy_deg);
    mount.world_T_base = geometry::make_pose(
        Eigen::Vector3d(xyz[0], xyz[1], xyz[2]),
        geometry::Rpy{deg_to_rad(rpy_deg[0]), deg_to_rad(rpy_deg[1]), deg_to_rad(rpy_deg[2])});
    for (const auto& other : c.world.robots) {
      if (other.robot_id == mount.robot_id) {
        r.fail("id", fmt::format("robot '{}' is mounted twice", mount.robot_id));
      }
    }
    c.world.robots.push_back(mount);
    root.absorb(r);
  }
  config::MapReader p = root.child("physics", false);
  double yaw_deg = geometry::rad_to_deg(c.world.capture_yaw_tolerance);
  double tilt_deg = geometry::rad_to_deg(c.world.capture_tilt_tolerance);
  p.optional("capture_tolerance_mm", c.world.capture_tolerance_mm);
  p.optional("capture_yaw_tolerance_deg", yaw_deg);
  p.optional("capture_tilt_tolerance_deg", tilt_deg);
  if (!(c.world.capture_tolerance_mm > 0.0 && c.world.capture_tolerance_mm <= 100.0)) {
    p.fail("capture_tolerance_mm",
           fmt::format("must be in (0, 100] mm, got {}", c.world.capture_tolerance_mm));
  }
  if (!(yaw_deg > 0.0 && yaw_deg <= 180.0)) {
    p.fail("capture_yaw_tolerance_deg", fmt::format("must be in (0, 180], got {}", yaw_deg));
  }
  if (!(tilt_deg > 0.0 && tilt_deg <= 90.0)) {
    p.fail("capture_tilt_tolerance_deg", fmt::format("must be in (0, 90], got {}", tilt_deg));
  }
  c.world.capture_yaw_tolerance = deg_to_rad(yaw_deg);
  c.world.capture_tilt_tolerance = deg_to_rad(tilt_deg);
  root.absorb(p);
  const std::string scene_where = root.where("scene");  // before finish(), which closes root
  CELL_TRY(root.finish());
  c.scene = service::resolve_path(c.scene);
  // The scene must load and build now: a typo in it is a config error at start, with its
  // file:line:col, not a service that runs an empty world.
  const world::Catalogue catalogue = world::Catalogue::standard();
  auto scene = world::load_scene_file(c.scene, catalogue);
  if (!scene) {
    return Error{Errc::kConfig, fmt::format("{}: scene: {}", scene_where, scene.error().message)};
  }
  if (auto built = world::World::create(*scene, catalogue, c.world); !built) {
    return Error{Errc::kConfig, fmt::format("{}: scene: {}", scene_where, built.error().message)};
  }
  CELL_TRY(c.validate());
  return c;
}

}  // namespace cell::sim_world
