#include "vision_config.hpp"

#include <fmt/format.h>

#include <array>
#include <cmath>
#include <numbers>
#include <set>

#include "cell/config/pose.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/service/paths.hpp"
#include "cell/vision/options.hpp"

namespace cell::vision {

using config::read_pose;

const CameraEntry* VisionConfig::camera(const std::string& id) const {
  for (const CameraEntry& c : cameras) {
    if (c.id == id) {
      return &c;
    }
  }
  return nullptr;
}

Result<VisionConfig> load_config(const config::Document& doc) {
  VisionConfig c;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, c.common);
  std::string camera_dir = "config/cameras";
  std::string robot_dir = "config/robots";
  root.optional("camera_dir", camera_dir);
  root.optional("robot_dir", robot_dir);
  c.camera_dir = service::resolve_path(camera_dir);
  c.robot_dir = service::resolve_path(robot_dir);
  root.optional("history_frames", c.history_frames);
  if (c.history_frames < 1 || c.history_frames > 256) {
    root.fail("history_frames", fmt::format("must be in 1..256, got {}", c.history_frames));
  }
  root.optional("edge_image_timeout_s", c.edge_image_timeout_s);
  if (!(c.edge_image_timeout_s > 0.0 && c.edge_image_timeout_s <= 600.0)) {
    root.fail("edge_image_timeout_s",
              fmt::format("must be in (0, 600] s, got {}", c.edge_image_timeout_s));
  }
  root.optional("max_pending_edges", c.max_pending_edges);
  if (c.max_pending_edges < 1 || c.max_pending_edges > 4096) {
    root.fail("max_pending_edges", fmt::format("must be in 1..4096, got {}", c.max_pending_edges));
  }
  // The global locate section first: a camera's own `locate:` keys go over it.
  if (root.has("locate")) {
    config::MapReader locate = root.child("locate", false);
    read_locate_options(locate, c.locate);
    root.absorb(locate);
  }
  std::set<std::string> ids;
  const auto cameras = root.sequence("cameras", false);
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    const std::string name = fmt::format("cameras[{}]", i);
    config::MapReader e = root.element(cameras[i], name);
    CameraEntry entry;
    entry.where = config::location(doc.path, cameras[i]);
    e.required("id", entry.id);
    e.optional("camera_file", entry.camera_file);
    e.optional("robot_id", entry.robot_id);
    if (e.has("world_T_base")) {
      entry.world_T_base = read_pose(e, "world_T_base");
    }
    e.required("working_plane_z_mm", entry.working_plane_z_mm);
    if (!std::isfinite(entry.working_plane_z_mm)) {
      e.fail("working_plane_z_mm", "must be finite");
    }
    if (e.has("locate")) {
      config::MapReader locate = e.child("locate", false);
      entry.locate = c.locate;
      read_locate_options(locate, *entry.locate);
      e.absorb(locate);
    }
    if (!entry.id.empty() && !ids.insert(entry.id).second) {
      e.fail("id", fmt::format("camera '{}' is listed twice", entry.id));
    }
    entry.camera_file = entry.camera_file.empty() ? c.camera_dir + "/" + entry.id + ".yaml"
                                                  : service::resolve_path(entry.camera_file);
    root.absorb(e);
    c.cameras.push_back(std::move(entry));
  }
  if (root.has("edges")) {
    config::MapReader edges = root.child("edges", false);
    read_edge_options(edges, c.edges);
    root.absorb(edges);
  }
  CELL_TRY(root.finish());
  return c;
}

}  // namespace cell::vision
