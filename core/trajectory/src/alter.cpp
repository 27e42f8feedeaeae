#include "cell/trajectory/alter.hpp"

#include <algorithm>

namespace cell::trajectory {

double MeetingRamp::displacement(double d_mm) const noexcept {
  const double ramp = length_mm;
  if (ramp <= 0.0 || d_mm >= ramp) {
    return ramp <= 0.0 ? std::max(0.0, d_mm) : d_mm;
  }
  if (d_mm <= -ramp) {
    return 0.0;
  }
  return (d_mm + ramp) * (d_mm + ramp) / (4.0 * ramp);
}

double MeetingRamp::rate(double d_mm) const noexcept {
  const double ramp = length_mm;
  if (ramp <= 0.0) {
    return d_mm > 0.0 ? 1.0 : 0.0;
  }
  return std::clamp((d_mm + ramp) / (2.0 * ramp), 0.0, 1.0);
}

void AlterState::submit(const AlterCorrection& correction) noexcept {
  pending_ = correction;  // last one in a cycle wins
  has_pending_ = true;
}

void AlterState::begin_cycle() noexcept {
  if (!has_pending_) {
    return;
  }
  if (mode_.cumulative) {
    const AlterCorrection base = effective_at(pending_.stamp_s);
    effective_.translation_mm = base.translation_mm + pending_.translation_mm;
    effective_.rotation_rad = effective_.rotation_rad + pending_.rotation_rad;
    effective_.velocity_mm_s = pending_.velocity_mm_s;
    effective_.stamp_s = pending_.stamp_s;
    effective_.horizon_s = pending_.horizon_s;
  } else {
    effective_ = pending_;
  }
  has_pending_ = false;
  ++applied_;
}

AlterCorrection AlterState::effective_at(double now_s) const noexcept {
  AlterCorrection out = effective_;
  const double horizon = effective_.horizon_s > 0.0
                             ? std::min(effective_.horizon_s, kExtrapolationHorizonS)
                             : kExtrapolationHorizonS;
  const double dt = std::min(now_s - effective_.stamp_s, horizon);
  out.translation_mm += effective_.velocity_mm_s * dt;
  out.stamp_s = now_s;
  return out;
}

Eigen::Isometry3d AlterState::apply(const Eigen::Isometry3d& base_T_tool,
                                    const AlterCorrection& correction) const noexcept {
  const Eigen::Matrix3d rotation =
      (Eigen::AngleAxisd(correction.rotation_rad.z(), Eigen::Vector3d::UnitZ()) *
       Eigen::AngleAxisd(correction.rotation_rad.y(), Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(correction.rotation_rad.x(), Eigen::Vector3d::UnitX()))
          .toRotationMatrix();
  Eigen::Isometry3d out = base_T_tool;
  if (mode_.world_frame) {
    out.linear() = rotation * base_T_tool.linear();
    out.translation() = base_T_tool.translation() + correction.translation_mm;
  } else {
    out.linear() = base_T_tool.linear() * rotation;
    out.translation() = base_T_tool.translation() + base_T_tool.linear() * correction.translation_mm;
  }
  return out;
}

}  // namespace cell::trajectory
