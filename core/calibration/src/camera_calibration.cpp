#include "cell/calibration/camera_calibration.hpp"

#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <numbers>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "cell/bus/view.hpp"
#include "cell/config/pose.hpp"
#include "cell/config/yaml.hpp"
#include "cell/geometry/angles.hpp"
#include "cell/geometry/idl_pose.hpp"
#include "cell/geometry/pose.hpp"
#include "file_util.hpp"

namespace cell::calibration {
namespace {

using geometry::kDeg;

bool finite(std::initializer_list<double> values) {
  for (const double v : values) {
    if (!std::isfinite(v)) {
      return false;
    }
  }
  return true;
}

Error invalid_camera(const std::string& camera_id, const std::string& what) {
  return Error{Errc::kInvalidArgument,
               fmt::format("camera calibration '{}': {}", camera_id, what)};
}

using config::read_pose;

/// 17 significant digits: a double survives the round trip through text exactly.
using detail::exact_number;

}  // namespace

std::string_view to_string(ModelType model) noexcept {
  return model == ModelType::kPinhole ? "pinhole" : "planar_7545";
}

std::string_view to_string(Mounting mounting) noexcept {
  return mounting == Mounting::kFixed ? "fixed" : "eye_in_hand";
}

Status CameraCalibration::validate() const {
  if (camera_id.empty()) {
    return Error{Errc::kInvalidArgument, "camera calibration: camera_id is empty"};
  }
  if (width_px < 1 || width_px > 16384 || height_px < 1 || height_px > 16384) {
    return invalid_camera(camera_id, fmt::format("image size {} x {} px is not in 1..16384", width_px,
                                          height_px));
  }
  if (robot_id.empty()) {
    return invalid_camera(camera_id, "robot_id is empty (the robot whose base frame it refers to)");
  }
  if (!std::isfinite(working_plane_z_mm)) {
    return invalid_camera(camera_id, "working_plane_z_mm is not finite");
  }
  if (model == ModelType::kPinhole) {
    if (auto m = camera_model(); !m) {
      return m.error();
    }
    const Eigen::Matrix4d& m = extrinsics.matrix();
    const Eigen::Matrix3d r = extrinsics.linear();
    if (!m.allFinite() || !(r.transpose() * r).isIdentity(1e-6) || r.determinant() < 0) {
      return invalid_camera(camera_id, "extrinsics are not a finite rigid transform");
    }
    return ok_status();
  }
  const PlanarParameters& p = planar;
  if (!finite({p.c_x_px_per_mm, p.c_y_px_per_mm, p.ref_u_px, p.ref_v_px, p.center_u_px,
               p.center_v_px, p.d_t_c_mm, p.b_angl_rad, p.angl_err_rad, p.link1_mm, p.link2_mm,
               p.camera_height_mm})) {
    return invalid_camera(camera_id, "planar: every parameter must be finite");
  }
  if (!(p.c_x_px_per_mm > 0) || !(p.c_y_px_per_mm > 0)) {
    return invalid_camera(camera_id, fmt::format("planar: pixel scales must be > 0, got c_x {} and c_y "
                                          "{} px/mm",
                                          p.c_x_px_per_mm, p.c_y_px_per_mm));
  }
  if (!(p.link1_mm > 0) || !(p.link2_mm > 0)) {
    return invalid_camera(camera_id, "planar: link1_mm and link2_mm must be > 0");
  }
  return ok_status();
}

Result<render::CameraModel> CameraCalibration::camera_model() const {
  if (model != ModelType::kPinhole) {
    return invalid_camera(camera_id, "a planar_7545 calibration has no pinhole model");
  }
  auto m = render::CameraModel::create(width_px, height_px, pinhole.fx_px, pinhole.fy_px,
                                       pinhole.cx_px, pinhole.cy_px, pinhole.distortion);
  if (!m) {
    return invalid_camera(camera_id, m.error().message);
  }
  return m;
}

namespace {

Result<CameraCalibration> parse_camera_document(const config::Document& doc) {
  CameraCalibration c;
  config::MapReader r(doc, doc.root, "");
  r.required("camera_id", c.camera_id);
  r.optional("version", c.version);
  r.optional("created_utc", c.created_utc);
  r.optional("source", c.source);
  std::string model = "pinhole";
  std::string mounting = "fixed";
  std::string mount_frame;
  r.required("model", model);
  r.required("mounting", mounting);
  r.optional("mount_frame", mount_frame);
  r.required("robot_id", c.robot_id);
  r.required("width_px", c.width_px);
  r.required("height_px", c.height_px);
  r.required("working_plane_z_mm", c.working_plane_z_mm);
  if (model == "pinhole") {
    c.model = ModelType::kPinhole;
  } else if (model == "planar_7545") {
    c.model = ModelType::kPlanar7545;
  } else {
    r.fail("model", fmt::format("must be pinhole or planar_7545, got '{}'", model));
  }
  if (mounting == "fixed") {
    c.mounting = Mounting::kFixed;
  } else if (mounting == "eye_in_hand") {
    c.mounting = Mounting::kEyeInHand;
  } else {
    r.fail("mounting", fmt::format("must be fixed or eye_in_hand, got '{}'", mounting));
  }
  if (c.mounting == Mounting::kEyeInHand) {
    if (mount_frame == "tool") {
      c.mount_frame = render::MountFrame::kTool;
    } else if (mount_frame == "link2") {
      c.mount_frame = render::MountFrame::kLink2;
    } else {
      r.fail("mount_frame", fmt::format("an eye-in-hand camera needs mount_frame tool or link2, "
                                        "got '{}'",
                                        mount_frame));
    }
  }
  if (c.model == ModelType::kPinhole) {
    config::MapReader p = r.child("pinhole", true);
    p.required("fx_px", c.pinhole.fx_px);
    p.required("fy_px", c.pinhole.fy_px);
    p.required("cx_px", c.pinhole.cx_px);
    p.required("cy_px", c.pinhole.cy_px);
    std::array<double, 5> d{};
    p.required("distortion", d);
    c.pinhole.distortion = render::Distortion{d[0], d[1], d[2], d[3], d[4]};
    r.absorb(p);
    c.extrinsics = read_pose(r, "extrinsics");
  } else {
    config::MapReader p = r.child("planar", true);
    PlanarParameters& q = c.planar;
    p.required("c_x_px_per_mm", q.c_x_px_per_mm);
    p.required("c_y_px_per_mm", q.c_y_px_per_mm);
    p.required("ref_u_px", q.ref_u_px);
    p.required("ref_v_px", q.ref_v_px);
    p.required("center_u_px", q.center_u_px);
    p.required("center_v_px", q.center_v_px);
    p.required("d_t_c_mm", q.d_t_c_mm);
    p.required_deg("b_angl_deg", q.b_angl_rad);
    p.required_deg("angl_err_deg", q.angl_err_rad);
    p.required("link1_mm", q.link1_mm);
    p.required("link2_mm", q.link2_mm);
    p.required("camera_height_mm", q.camera_height_mm);
    r.absorb(p);
  }
  if (r.has("quality")) {
    config::MapReader q = r.child("quality", false);
    q.optional("rms_px", c.quality.rms_px);
    q.optional("holdout_rms_px", c.quality.holdout_rms_px);
    q.optional("holdout_mm", c.quality.holdout_mm);
    q.optional("sample_count", c.quality.sample_count);
    r.absorb(q);
  }
  CELL_TRY(r.finish());
  if (auto s = c.validate(); !s) {
    return Error{Errc::kConfig, doc.path + ": " + s.error().message};
  }
  return c;
}

}  // namespace

Result<CameraCalibration> load_camera_calibration(const std::string& path) {
  auto doc = config::load_file(path);
  if (!doc) {
    return std::move(doc).error();
  }
  return parse_camera_document(*doc);
}

Result<CameraCalibration> parse_camera_calibration(const std::string& text,
                                                   const std::string& origin) {
  auto doc = config::load_string(text, origin);
  if (!doc) {
    return std::move(doc).error();
  }
  return parse_camera_document(*doc);
}

std::string format_camera_calibration(const CameraCalibration& c) {
  std::string out;
  out += "# A camera calibration (core/calibration/README.md: keys, frames and units).\n";
  out += fmt::format("camera_id: {}\n", YAML::Dump(YAML::Node(c.camera_id)));
  out += fmt::format("version: {}\n", YAML::Dump(YAML::Node(c.version)));
  out += fmt::format("created_utc: {}\n", YAML::Dump(YAML::Node(c.created_utc)));
  out += fmt::format("source: {}\n", YAML::Dump(YAML::Node(c.source)));
  out += fmt::format("model: {}\n", to_string(c.model));
  out += fmt::format("mounting: {}\n", to_string(c.mounting));
  if (c.mounting == Mounting::kEyeInHand) {
    out += fmt::format("mount_frame: {}\n", render::to_string(c.mount_frame));
  }
  out += fmt::format("robot_id: {}\n", YAML::Dump(YAML::Node(c.robot_id)));
  out += fmt::format("width_px: {}\nheight_px: {}\n", c.width_px, c.height_px);
  out += fmt::format("working_plane_z_mm: {}\n", exact_number(c.working_plane_z_mm));
  if (c.model == ModelType::kPinhole) {
    const auto& p = c.pinhole;
    const auto d = p.distortion.as_array();
    out += fmt::format("pinhole:\n  fx_px: {}\n  fy_px: {}\n  cx_px: {}\n  cy_px: {}\n",
                       exact_number(p.fx_px), exact_number(p.fy_px), exact_number(p.cx_px), exact_number(p.cy_px));
    out += fmt::format("  distortion: [{}, {}, {}, {}, {}]  # k1 k2 p1 p2 k3\n", exact_number(d[0]),
                       exact_number(d[1]), exact_number(d[2]), exact_number(d[3]), exact_number(d[4]));
    const Eigen::Vector3d t = c.extrinsics.translation();
    const geometry::Rpy rpy = geometry::rpy_from_rotation(c.extrinsics.linear());
    out += fmt::format(
        "extrinsics:  # {}\n  xyz_mm: [{}, {}, {}]\n  rpy_deg: [{}, {}, {}]\n",
        c.mounting == Mounting::kFixed ? "base_T_camera" : "mount_T_camera", exact_number(t.x()),
        exact_number(t.y()), exact_number(t.z()), exact_number(rpy.roll / kDeg), exact_number(rpy.pitch / kDeg), exact_number(rpy.yaw / kDeg));
  } else {
    const auto& q = c.planar;
    out += fmt::format(
        "planar:\n  c_x_px_per_mm: {}\n  c_y_px_per_mm: {}\n  ref_u_px: {}\n  ref_v_px: {}\n"
        "  center_u_px: {}\n  center_v_px: {}\n  d_t_c_mm: {}\n  b_angl_deg: {}\n"
        "  angl_err_deg: {}\n  link1_mm: {}\n  link2_mm: {}\n  camera_height_mm: {}\n",
        exact_number(q.c_x_px_per_mm), exact_number(q.c_y_px_per_mm), exact_number(q.ref_u_px), exact_number(q.ref_v_px),
        exact_number(q.center_u_px), exact_number(q.center_v_px), exact_number(q.d_t_c_mm), exact_number(q.b_angl_rad / kDeg),
        exact_number(q.angl_err_rad / kDeg), exact_number(q.link1_mm), exact_number(q.link2_mm), exact_number(q.camera_height_mm));
  }
  out += fmt::format(
      "quality:\n  rms_px: {}\n  holdout_rms_px: {}\n  holdout_mm: {}\n  sample_count: {}\n",
      exact_number(c.quality.rms_px), exact_number(c.quality.holdout_rms_px), exact_number(c.quality.holdout_mm),
      c.quality.sample_count);
  return out;
}

Status save_camera_calibration(const CameraCalibration& calibration, const std::string& path) {
  CELL_TRY(calibration.validate());
  return detail::write_atomically(path, format_camera_calibration(calibration));
}

Result<CameraCalibration> nominal_calibration(const render::CameraDescription& camera,
                                              const std::string& robot_id,
                                              const Eigen::Isometry3d& world_T_base,
                                              double working_plane_z_mm) {
  CameraCalibration c;
  c.camera_id = camera.id;
  c.source = "nominal: " + camera.path;
  c.model = ModelType::kPinhole;
  c.width_px = camera.nominal.model.width_px();
  c.height_px = camera.nominal.model.height_px();
  c.pinhole = PinholeParameters{camera.nominal.model.fx_px(), camera.nominal.model.fy_px(),
                                camera.nominal.model.cx_px(), camera.nominal.model.cy_px(),
                                camera.nominal.model.distortion()};
  c.working_plane_z_mm = working_plane_z_mm;
  if (camera.mount == render::MountKind::kEyeInHand) {
    c.mounting = Mounting::kEyeInHand;
    c.mount_frame = camera.robot.frame;
    c.robot_id = camera.robot.robot_id;
    c.extrinsics = camera.nominal.pose;
  } else {
    if (robot_id.empty()) {
      return invalid_camera(camera.id, "a fixed camera's calibration needs the robot whose base frame "
                                "it refers to");
    }
    c.mounting = Mounting::kFixed;
    c.robot_id = robot_id;
    c.extrinsics = world_T_base.inverse() * camera.nominal.pose;
  }
  CELL_TRY(c.validate());
  return c;
}

cell_calibration_CameraCalibration to_idl(const CameraCalibration& c, IdlHolder& holder,
                                          std::int64_t stamp_ns) {
  holder.mount_frame =
      c.mounting == Mounting::kEyeInHand ? std::string(render::to_string(c.mount_frame)) : "";
  holder.frame_id = c.robot_id + "/base";
  const auto d = c.pinhole.distortion.as_array();
  holder.distortion.assign(d.begin(), d.end());
  cell_calibration_CameraCalibration m{};
  m.camera_id = bus::borrow(c.camera_id);
  m.header.stamp_ns = stamp_ns;
  m.header.frame_id = bus::borrow(holder.frame_id);
  m.model = c.model == ModelType::kPinhole ? cell_calibration_CAMERA_PINHOLE
                                           : cell_calibration_CAMERA_PLANAR_7545;
  m.mounting = c.mounting == Mounting::kFixed ? cell_calibration_MOUNT_FIXED
                                              : cell_calibration_MOUNT_EYE_IN_HAND;
  m.robot_id = bus::borrow(c.robot_id);
  m.width_px = static_cast<std::uint32_t>(c.width_px);
  m.height_px = static_cast<std::uint32_t>(c.height_px);
  m.fx_px = c.pinhole.fx_px;
  m.fy_px = c.pinhole.fy_px;
  m.cx_px = c.pinhole.cx_px;
  m.cy_px = c.pinhole.cy_px;
  bus::borrow(m.distortion, holder.distortion);
  m.extrinsics = geometry::pose_to_idl(c.extrinsics);
  m.working_plane_z_mm = c.working_plane_z_mm;
  const PlanarParameters& p = c.planar;
  m.c_x_px_per_mm = p.c_x_px_per_mm;
  m.c_y_px_per_mm = p.c_y_px_per_mm;
  m.ref_u_px = p.ref_u_px;
  m.ref_v_px = p.ref_v_px;
  m.center_u_px = p.center_u_px;
  m.center_v_px = p.center_v_px;
  m.d_t_c_mm = p.d_t_c_mm;
  m.b_angl_rad = p.b_angl_rad;
  m.angl_err_rad = p.angl_err_rad;
  m.link1_mm = p.link1_mm;
  m.link2_mm = p.link2_mm;
  m.camera_height_mm = p.camera_height_mm;
  m.rms_px = c.quality.rms_px;
  m.holdout_rms_mm = c.quality.holdout_mm;
  m.holdout_rms_px = c.quality.holdout_rms_px;
  m.sample_count = c.quality.sample_count;
  m.version = bus::borrow(c.version);
  m.mount_frame = bus::borrow(holder.mount_frame);
  m.source = bus::borrow(c.source);
  return m;
}

Result<CameraCalibration> from_idl(const cell_calibration_CameraCalibration& sample) {
  CameraCalibration c;
  c.camera_id = std::string(bus::str(sample.camera_id));
  // Any value may come off the wire: the enums are read as integers (bus::raw).
  switch (bus::raw(sample.model)) {
    case cell_calibration_CAMERA_PINHOLE:
      c.model = ModelType::kPinhole;
      break;
    case cell_calibration_CAMERA_PLANAR_7545:
      c.model = ModelType::kPlanar7545;
      break;
    default:
      return invalid_camera(c.camera_id,
                            fmt::format("unknown model type {}", bus::raw(sample.model)));
  }
  switch (bus::raw(sample.mounting)) {
    case cell_calibration_MOUNT_FIXED:
      c.mounting = Mounting::kFixed;
      break;
    case cell_calibration_MOUNT_EYE_IN_HAND:
      c.mounting = Mounting::kEyeInHand;
      break;
    default:
      return invalid_camera(c.camera_id,
                            fmt::format("unknown mounting {}", bus::raw(sample.mounting)));
  }
  const std::string_view frame = bus::str(sample.mount_frame);
  if (c.mounting == Mounting::kEyeInHand) {
    if (frame == "tool") {
      c.mount_frame = render::MountFrame::kTool;
    } else if (frame == "link2") {
      c.mount_frame = render::MountFrame::kLink2;
    } else {
      return invalid_camera(c.camera_id, fmt::format("mount_frame must be tool or link2, got '{}'",
                                              frame));
    }
  }
  c.robot_id = std::string(bus::str(sample.robot_id));
  c.width_px = static_cast<int>(std::min<std::uint32_t>(sample.width_px, 1U << 30));
  c.height_px = static_cast<int>(std::min<std::uint32_t>(sample.height_px, 1U << 30));
  const auto d = bus::span(sample.distortion);
  if (!d.empty() && d.size() != 5) {
    return invalid_camera(c.camera_id, fmt::format("distortion has {} coefficients; 0 or 5 (k1 k2 p1 p2 "
                                            "k3) expected",
                                            d.size()));
  }
  c.pinhole = PinholeParameters{sample.fx_px, sample.fy_px, sample.cx_px, sample.cy_px, {}};
  if (d.size() == 5) {
    c.pinhole.distortion = render::Distortion{d[0], d[1], d[2], d[3], d[4]};
  }
  if (c.model == ModelType::kPinhole) {
    auto pose = geometry::pose_from_idl(sample.extrinsics);
    if (!pose) {
      return invalid_camera(c.camera_id, "extrinsics: " + pose.error().message);
    }
    c.extrinsics = *pose;
  }
  c.working_plane_z_mm = sample.working_plane_z_mm;
  c.planar = PlanarParameters{sample.c_x_px_per_mm, sample.c_y_px_per_mm, sample.ref_u_px,
                              sample.ref_v_px,      sample.center_u_px,   sample.center_v_px,
                              sample.d_t_c_mm,      sample.b_angl_rad,    sample.angl_err_rad,
                              sample.link1_mm,      sample.link2_mm,      sample.camera_height_mm};
  c.quality =
      Quality{sample.rms_px, sample.holdout_rms_px, sample.holdout_rms_mm, sample.sample_count};
  c.version = std::string(bus::str(sample.version));
  c.source = std::string(bus::str(sample.source));
  CELL_TRY(c.validate());
  return c;
}

}  // namespace cell::calibration
