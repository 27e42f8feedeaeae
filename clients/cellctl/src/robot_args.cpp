#include "robot_args.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>

#include <fmt/format.h>

#include "cell/geometry/angles.hpp"
#include "cell/geometry/pose.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/service/paths.hpp"

namespace cell::cellctl {

Result<kinematics::RobotModel> load_robot_by_id(const std::string& robot_id) {
  if (robot_id.empty() || robot_id.find_first_of("/\\.") != std::string::npos) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("--robot '{}' is not a robot id (e.g. ibm7545, excalibur)", robot_id)};
  }
  const std::string path = service::resolve_path("config/robots/" + robot_id + ".yaml");
  if (!std::filesystem::exists(path)) {
    std::string known;
    const auto dir = std::filesystem::path(service::resolve_path("config/robots"));
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
      if (entry.path().extension() == ".yaml") {
        known += (known.empty() ? "" : ", ") + entry.path().stem().string();
      }
    }
    return Error{Errc::kInvalidArgument,
                 fmt::format("unknown robot '{}' (no {}); known robots: {}", robot_id, path,
                             known.empty() ? "none" : known)};
  }
  return kinematics::load_robot(path);
}

Result<std::vector<double>> parse_numbers(const std::string& text, const std::string& what) {
  std::vector<double> out;
  std::size_t start = 0;
  int index = 0;
  while (start <= text.size()) {
    const auto comma = text.find(',', start);
    const std::string item = text.substr(start, comma == std::string::npos ? comma : comma - start);
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || end != item.c_str() + item.size() || errno != 0 || !std::isfinite(v)) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("{}: element {} ('{}') is not a number", what, index, item)};
    }
    out.push_back(v);
    ++index;
    if (comma == std::string::npos) {
      break;
    }
    start = comma + 1;
  }
  return out;
}

Result<kinematics::JointVector> joints_from_display(const kinematics::RobotModel& model,
                                                    const std::vector<double>& values,
                                                    const std::string& what) {
  if (static_cast<int>(values.size()) != model.dof()) {
    std::string units;
    for (const auto& j : model.joints()) {
      units += fmt::format("{}{} [{}]", units.empty() ? "" : ", ", j.name, j.display_unit());
    }
    return Error{Errc::kInvalidArgument,
                 fmt::format("{}: {} values given; robot '{}' has {} joints: {}", what,
                             values.size(), model.id(), model.dof(), units)};
  }
  kinematics::JointVector q(model.dof());
  for (int j = 0; j < model.dof(); ++j) {
    q[j] = model.joints()[static_cast<std::size_t>(j)].from_display(values[static_cast<std::size_t>(j)]);
  }
  return q;
}

Result<Eigen::Isometry3d> pose_from_text(const std::string& text, const std::string& what) {
  auto v = parse_numbers(text, what);
  if (!v) {
    return std::move(v).error();
  }
  if (v->size() != 6) {
    return Error{Errc::kInvalidArgument,
                 fmt::format("{}: expected x,y,z,roll,pitch,yaw (mm, deg), got {} values", what,
                             v->size())};
  }
  const auto& p = *v;
  return geometry::make_pose(Eigen::Vector3d(p[0], p[1], p[2]),
                             {.roll = geometry::deg_to_rad(p[3]),
                              .pitch = geometry::deg_to_rad(p[4]),
                              .yaw = geometry::deg_to_rad(p[5])});
}

nlohmann::json pose_json(const Eigen::Isometry3d& pose) {
  const geometry::Rpy rpy = geometry::rpy_from_rotation(pose.linear());
  const Eigen::Vector3d t = pose.translation();
  return {{"x_mm", t.x()},
          {"y_mm", t.y()},
          {"z_mm", t.z()},
          {"roll_deg", geometry::rad_to_deg(rpy.roll)},
          {"pitch_deg", geometry::rad_to_deg(rpy.pitch)},
          {"yaw_deg", geometry::rad_to_deg(rpy.yaw)}};
}

std::string pose_text(const Eigen::Isometry3d& pose) {
  const geometry::Rpy rpy = geometry::rpy_from_rotation(pose.linear());
  const Eigen::Vector3d t = pose.translation();
  return fmt::format("x={:.3f} mm y={:.3f} mm z={:.3f} mm roll={:.3f} deg pitch={:.3f} deg "
                     "yaw={:.3f} deg",
                     t.x(), t.y(), t.z(), geometry::rad_to_deg(rpy.roll),
                     geometry::rad_to_deg(rpy.pitch), geometry::rad_to_deg(rpy.yaw));
}

nlohmann::json joints_json(const kinematics::RobotModel& model, const kinematics::JointVector& q) {
  nlohmann::json out = nlohmann::json::array();
  for (int j = 0; j < model.dof(); ++j) {
    const auto& spec = model.joints()[static_cast<std::size_t>(j)];
    out.push_back({{"name", spec.name},
                   {"value", spec.to_display(q[j])},
                   {"unit", std::string(spec.display_unit())}});
  }
  return out;
}

std::string joints_text(const kinematics::RobotModel& model, const kinematics::JointVector& q) {
  std::string out;
  for (int j = 0; j < model.dof(); ++j) {
    const auto& spec = model.joints()[static_cast<std::size_t>(j)];
    out += fmt::format("{}{}={:.3f} {}", out.empty() ? "" : " ", spec.name, spec.to_display(q[j]),
                       spec.display_unit());
  }
  return out;
}

}  // namespace cell::cellctl
