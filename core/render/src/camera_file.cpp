#include "cell/render/camera_file.hpp"

#include <array>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

#include "cell/config/pose.hpp"
#include "cell/geometry/pose.hpp"

namespace cell::render {
namespace {


using config::read_pose;

Eigen::Vector3d read_vec3(config::MapReader& r, const std::string& key,
                          const Eigen::Vector3d& fallback) {
  std::array<double, 3> v{fallback.x(), fallback.y(), fallback.z()};
  r.optional(key, v);
  return {v[0], v[1], v[2]};
}

CameraSetup read_setup(config::MapReader& root, const std::string& key, int width, int height,
                       MountKind mount) {
  config::MapReader r = root.child(key, true);
  double fx = 0.0;
  double fy = 0.0;
  double cx = 0.0;
  double cy = 0.0;
  std::array<double, 5> k{};
  r.required("fx_px", fx);
  r.required("fy_px", fy);
  r.required("cx_px", cx);
  r.required("cy_px", cy);
  r.optional("distortion", k);
  CameraSetup setup;
  const char* pose_key = mount == MountKind::kFixed ? "world_T_camera" : "mount_T_camera";
  setup.pose = read_pose(r, pose_key);
  if (width > 0 && height > 0 && r.node().IsMap()) {
    auto model =
        CameraModel::create(width, height, fx, fy, cx, cy, Distortion{k[0], k[1], k[2], k[3], k[4]});
    if (model) {
      setup.model = *model;
    } else {
      r.fail("", model.error().message);
    }
  }
  root.absorb(r);
  return setup;
}

}  // namespace

std::string_view to_string(MountKind kind) noexcept {
  return kind == MountKind::kFixed ? "fixed" : "eye_in_hand";
}

std::string_view to_string(MountFrame frame) noexcept {
  return frame == MountFrame::kTool ? "tool" : "link2";
}

Eigen::Isometry3d CameraDescription::world_T_camera(const CameraSetup& setup,
                                                    const Eigen::Isometry3d& base_T_mount) const {
  if (mount == MountKind::kFixed) {
    return setup.pose;
  }
  return robot.world_T_base * base_T_mount * setup.pose;
}

Result<CameraDescription> parse_camera(const config::Document& doc) {
  CameraDescription c;
  c.path = doc.path;
  config::MapReader root(doc, doc.root, "");
  root.required("id", c.id);
  root.optional("description", c.description);
  int width = 0;
  int height = 0;
  root.required("width_px", width);
  root.required("height_px", height);
  if (width < 1 || width > 16384) {
    root.fail("width_px", fmt::format("must be 1..16384, got {}", width));
    width = 0;
  }
  if (height < 1 || height > 16384) {
    root.fail("height_px", fmt::format("must be 1..16384, got {}", height));
    height = 0;
  }
  config::MapReader m = root.child("mount", true);
  std::string kind;
  m.required("kind", kind);
  if (kind == "fixed") {
    c.mount = MountKind::kFixed;
  } else if (kind == "eye_in_hand") {
    c.mount = MountKind::kEyeInHand;
    m.required("robot_id", c.robot.robot_id);
    std::string frame = "tool";
    m.optional("frame", frame);
    if (frame == "tool") {
      c.robot.frame = MountFrame::kTool;
    } else if (frame == "link2") {
      c.robot.frame = MountFrame::kLink2;
    } else {
      m.fail("frame", fmt::format("must be tool or link2, got '{}'", frame));
    }
    c.robot.world_T_base = read_pose(m, "world_T_base");
  } else if (!kind.empty()) {
    m.fail("kind", fmt::format("must be fixed or eye_in_hand, got '{}'", kind));
  }
  root.absorb(m);
  c.nominal = read_setup(root, "nominal", width, height, c.mount);
  c.truth = read_setup(root, "truth", width, height, c.mount);
  root.optional("exposure_s", c.exposure_s);
  if (!(std::isfinite(c.exposure_s) && c.exposure_s >= 0.0 && c.exposure_s <= 10.0)) {
    root.fail("exposure_s", fmt::format("must be in [0, 10] s, got {}", c.exposure_s));
  }
  config::MapReader lights = root.child("lights", false);
  lights.optional("switched_by", c.lights_robot_id);
  lights.optional("lamp_on", c.lights.lamp_on);
  lights.optional("fluorescent_on", c.lights.fluorescent_on);
  root.absorb(lights);
  config::MapReader l = root.child("lighting", false);
  Lighting& g = c.lighting;
  l.optional("ambient", g.ambient);
  g.fluorescent_position_world_mm =
      read_vec3(l, "fluorescent_position_world_mm", g.fluorescent_position_world_mm);
  l.optional("fluorescent_irradiance_at_1m", g.fluorescent_irradiance_at_1m);
  l.optional("fluorescent_specular", g.fluorescent_specular);
  g.lamp_position_camera_mm = read_vec3(l, "lamp_position_camera_mm", g.lamp_position_camera_mm);
  g.lamp_axis_camera = read_vec3(l, "lamp_axis_camera", g.lamp_axis_camera);
  l.optional("lamp_irradiance_at_1m", g.lamp_irradiance_at_1m);
  l.optional("lamp_spot_exponent", g.lamp_spot_exponent);
  l.optional("lamp_specular", g.lamp_specular);
  l.optional("shininess", g.shininess);
  if (auto s = g.validate(); !s) {
    l.fail("", s.error().message);
  }
  root.absorb(l);
  CELL_TRY(root.finish());
  return c;
}

Result<CameraDescription> load_camera(const std::string& path) {
  auto doc = config::load_file(path);
  if (!doc) {
    return std::move(doc).error();
  }
  return parse_camera(*doc);
}

}  // namespace cell::render
