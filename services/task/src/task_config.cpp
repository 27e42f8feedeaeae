#include "task_config.hpp"

#include <array>
#include <cmath>

#include <fmt/format.h>

#include "cell/service/paths.hpp"

namespace cell::task_service {
namespace {

template <typename Entry>
void unique(config::MapReader& r, const std::vector<Entry>& entries, const std::string& id,
            const char* what) {
  for (const auto& e : entries) {
    if (e.id == id) {
      r.fail("id", fmt::format("{} '{}' is listed twice", what, id));
    }
  }
}

bool listed(const std::vector<RobotEntry>& robots, const std::string& id) {
  for (const auto& r : robots) {
    if (r.id == id) {
      return true;
    }
  }
  return false;
}

}  // namespace

Result<TaskConfig> load_config(const config::Document& doc) {
  TaskConfig c;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, c.common);
  root.optional("journal", c.journal);
  c.journal = service::resolve_path(c.journal);
  const auto robots = root.sequence("robots");
  for (std::size_t i = 0; i < robots.size(); ++i) {
    config::MapReader r = root.element(robots[i], fmt::format("robots[{}]", i));
    RobotEntry e;
    r.required("id", e.id);
    r.required("config", e.config);
    r.optional("gateway", e.gateway);
    if (e.gateway.empty()) {
      e.gateway = "gateway." + e.id;
    }
    e.config = service::resolve_path(e.config);
    unique(r, c.robots, e.id, "robot");
    c.robots.push_back(e);
    root.absorb(r);
  }
  if (robots.empty()) {
    root.fail("robots", "at least one robot is needed");
  }
  const auto cameras = root.sequence("cameras", false);
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    config::MapReader r = root.element(cameras[i], fmt::format("cameras[{}]", i));
    CameraEntry e;
    r.required("id", e.id);
    r.required("robot", e.robot);
    r.required("working_plane_z_mm", e.working_plane_z_mm);
    r.optional("service", e.service);
    if (e.service.empty()) {
      e.service = "camera." + e.id;
    }
    unique(r, c.cameras, e.id, "camera");
    if (!listed(c.robots, e.robot)) {
      r.fail("robot", fmt::format("robot '{}' is not in robots", e.robot));
    }
    c.cameras.push_back(e);
    root.absorb(r);
  }
  const auto belts = root.sequence("belts", false);
  for (std::size_t i = 0; i < belts.size(); ++i) {
    config::MapReader r = root.element(belts[i], fmt::format("belts[{}]", i));
    BeltEntry e;
    std::array<double, 3> direction{1, 0, 0};
    std::array<double, 3> nearest{0, 0, 0};
    r.required("id", e.id);
    r.required("robot", e.robot);
    r.required("mm_per_count", e.mm_per_count);
    r.required("direction", direction);
    r.required("nearest_mm", nearest);
    e.direction = Eigen::Vector3d(direction[0], direction[1], direction[2]);
    e.nearest_mm = Eigen::Vector3d(nearest[0], nearest[1], nearest[2]);
    if (!(e.mm_per_count > 0) || !std::isfinite(e.mm_per_count)) {
      r.fail("mm_per_count", fmt::format("must be > 0, got {}", e.mm_per_count));
    }
    if (!e.direction.allFinite() || e.direction.norm() < 1e-9) {
      r.fail("direction", "must be a non-zero vector");
    } else {
      e.direction.normalize();
    }
    unique(r, c.belts, e.id, "belt");
    if (!listed(c.robots, e.robot)) {
      r.fail("robot", fmt::format("robot '{}' is not in robots", e.robot));
    }
    c.belts.push_back(e);
    root.absorb(r);
  }
  root.optional("scenes", c.scenes);
  for (auto& path : c.scenes) {
    path = service::resolve_path(path);
  }
  config::MapReader t = root.child("timeouts", false);
  t.optional("motion_s", c.motion_timeout_s);
  t.optional("locate_s", c.locate_timeout_s);
  t.optional("photocell_s", c.photocell_timeout_s);
  t.optional("robot_state_s", c.robot_state_timeout_s);
  for (const auto& [key, v] : {std::pair{"motion_s", c.motion_timeout_s},
                               {"locate_s", c.locate_timeout_s},
                               {"photocell_s", c.photocell_timeout_s},
                               {"robot_state_s", c.robot_state_timeout_s}}) {
    if (!(v > 0)) {
      t.fail(key, fmt::format("must be > 0, got {}", v));
    }
  }
  root.absorb(t);
  config::MapReader svc = root.child("services", false);
  svc.optional("motion", c.motion_service);
  svc.optional("vision", c.vision_service);
  if (c.motion_service.empty()) {
    svc.fail("motion", "must name the motion service's id, e.g. motion");
  }
  if (c.vision_service.empty()) {
    svc.fail("vision", "must name the vision service's id, e.g. vision");
  }
  root.absorb(svc);
  root.optional("status_period_s", c.status_period_s);
  root.optional("keep_finished", c.keep_finished);
  if (!(c.status_period_s > 0)) {
    root.fail("status_period_s", fmt::format("must be > 0, got {}", c.status_period_s));
  }
  if (c.keep_finished < 1) {
    root.fail("keep_finished", fmt::format("must be >= 1, got {}", c.keep_finished));
  }
  CELL_TRY(root.finish());
  return c;
}

}  // namespace cell::task_service
