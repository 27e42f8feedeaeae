#include "model_issues.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/geometry/pose.hpp"

namespace cell::kinematics::detail {

std::string joint_key(const JointSpec& joint, std::string_view field) {
  const bool revolute = joint.type == JointType::kRevolute;
  if (field == "max_speed") {
    return revolute ? "max_speed_deg_s" : "max_speed_mm_s";
  }
  if (field == "max_accel") {
    return revolute ? "max_accel_deg_s2" : "max_accel_mm_s2";
  }
  if (field == "counts_per") {
    return revolute ? "counts_per_deg" : "counts_per_mm";
  }
  return fmt::format("{}_{}", field, revolute ? "deg" : "mm");
}

void joint_issues(std::span<const JointSpec> joints,
                  std::span<const JointType> expected_types,
                  std::string_view kind_description,
                  Issues& out) {
  if (joints.size() != expected_types.size()) {
    out.push_back({"joints", fmt::format("{} needs {} joints, got {}", kind_description,
                                         expected_types.size(), joints.size())});
    return;
  }
  for (std::size_t i = 0; i < joints.size(); ++i) {
    const JointSpec& j = joints[i];
    const std::string prefix = fmt::format("joints[{}].", i);
    if (j.name.empty()) {
      out.push_back({prefix + "name", "must not be empty"});
    }
    for (std::size_t k = 0; k < i; ++k) {
      if (!j.name.empty() && joints[k].name == j.name) {
        out.push_back(
            {prefix + "name", fmt::format("'{}' is already the name of joints[{}]", j.name, k)});
      }
    }
    if (j.type != expected_types[i]) {
      out.push_back({prefix + "type",
                     fmt::format("joint {} of {} must be {}, got {}", i + 1, kind_description,
                                 to_string(expected_types[i]), to_string(j.type))});
      continue;  // the unit-dependent keys below would be misnamed
    }
    if (!std::isfinite(j.lower)) {
      out.push_back({prefix + joint_key(j, "lower"), "must be finite"});
    }
    if (!std::isfinite(j.upper)) {
      out.push_back({prefix + joint_key(j, "upper"), "must be finite"});
    } else if (std::isfinite(j.lower) && !(j.upper > j.lower)) {
      out.push_back({prefix + joint_key(j, "upper"),
                     fmt::format("must be greater than {} ({}), got {}", joint_key(j, "lower"),
                                 j.to_display(j.lower), j.to_display(j.upper))});
    }
    if (!(j.max_speed > 0.0) || !std::isfinite(j.max_speed)) {
      out.push_back({prefix + joint_key(j, "max_speed"),
                     fmt::format("must be > 0, got {}", j.to_display(j.max_speed))});
    }
    if (!(j.max_accel > 0.0) || !std::isfinite(j.max_accel)) {
      out.push_back({prefix + joint_key(j, "max_accel"),
                     fmt::format("must be > 0, got {}", j.to_display(j.max_accel))});
    }
    if (!(j.counts_per_unit >= 0.0) || !std::isfinite(j.counts_per_unit)) {
      out.push_back(
          {prefix + joint_key(j, "counts_per"),
           fmt::format("must be > 0 when given, got {}", j.counts_per_unit / j.to_display(1.0))});
    }
    if (j.overrun_counts && !((*j.overrun_counts)[0] < (*j.overrun_counts)[1])) {
      out.push_back(
          {prefix + "overrun_counts", fmt::format("must be [min, max] with min < max, got [{}, {}]",
                                                  (*j.overrun_counts)[0], (*j.overrun_counts)[1])});
    }
  }
}

namespace {

void interval_issue(const std::optional<Interval>& interval, std::string_view key, Issues& out) {
  if (interval && !(interval->lower < interval->upper)) {
    out.push_back({std::string(key), fmt::format("must be [lower, upper] with lower < upper, "
                                                 "got [{}, {}]",
                                                 interval->lower, interval->upper)});
  }
}

void positive(double value, std::string_view key, Issues& out) {
  if (!(value > 0.0) || !std::isfinite(value)) {
    out.push_back({std::string(key), fmt::format("must be > 0, got {}", value)});
  }
}

void non_negative(double value, std::string_view key, Issues& out) {
  if (!(value >= 0.0) || !std::isfinite(value)) {
    out.push_back({std::string(key), fmt::format("must be >= 0, got {}", value)});
  }
}

}  // namespace

void cartesian_issues(const CartesianLimits& limits, Issues& out) {
  interval_issue(limits.x, "cartesian_limits.x_mm", out);
  interval_issue(limits.y, "cartesian_limits.y_mm", out);
  interval_issue(limits.z, "cartesian_limits.z_mm", out);
  if (limits.base_guard) {
    positive(limits.base_guard->radius_mm, "cartesian_limits.base_guard.radius_mm", out);
    positive(limits.base_guard->height_mm, "cartesian_limits.base_guard.height_mm", out);
  }
}

void tool_issues(const Eigen::Isometry3d& flange_T_tool, Issues& out) {
  const Status rigid = geometry::check_rigid(flange_T_tool, "flange_T_tool");
  if (!rigid) {
    out.push_back({"tool", rigid.error().message});
  }
}

Issues scara_issues(const ScaraModel& model) {
  Issues out;
  static constexpr std::array<JointType, 4> kTypes = {JointType::kRevolute, JointType::kRevolute,
                                                      JointType::kPrismatic, JointType::kRevolute};
  joint_issues(model.joints, kTypes, "a scara (J1, J2, Z, R)", out);
  positive(model.link1_mm, "scara.link1_mm", out);
  positive(model.link2_mm, "scara.link2_mm", out);
  if (!std::isfinite(model.z_at_zero_mm)) {
    out.push_back({"scara.z_at_zero_mm", "must be finite"});
  }
  tool_issues(model.flange_T_tool, out);
  cartesian_issues(model.cartesian_limits, out);
  return out;
}

Issues excalibur_issues(const ExcaliburModel& model) {
  Issues out;
  static constexpr std::array<JointType, 6> kTypes = {JointType::kRevolute, JointType::kRevolute,
                                                      JointType::kRevolute, JointType::kRevolute,
                                                      JointType::kRevolute, JointType::kRevolute};
  joint_issues(model.joints, kTypes, "an excalibur (theta1..theta6)", out);
  non_negative(model.d1_mm, "excalibur.d1_mm", out);
  positive(model.a2_mm, "excalibur.a2_mm", out);
  positive(model.d4_mm, "excalibur.d4_mm", out);
  non_negative(model.d6_mm, "excalibur.d6_mm", out);
  for (std::size_t i = 0; i < model.controller_offset.size(); ++i) {
    if (!std::isfinite(model.controller_offset[i])) {
      out.push_back({fmt::format("excalibur.controller_offsets_deg[{}]", i), "must be finite"});
    }
  }
  tool_issues(model.flange_T_tool, out);
  cartesian_issues(model.cartesian_limits, out);
  return out;
}

Status to_status(const Issues& issues) {
  if (issues.empty()) {
    return ok_status();
  }
  std::string message;
  for (const ConfigIssue& issue : issues) {
    message += message.empty() ? "" : "\n";
    message += fmt::format("key '{}': {}", issue.key, issue.what);
  }
  return Error{Errc::kConfig, std::move(message)};
}

}  // namespace cell::kinematics::detail
