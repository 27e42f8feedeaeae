#include "cell/protocols/excalibur/angles.hpp"

#include <cmath>
#include <numbers>

namespace cell::protocols::excalibur {
namespace {
constexpr double kDegPerRad = 180.0 / std::numbers::pi;
}  // namespace

ControllerAngles to_wire(const kinematics::ExcaliburModel& model,
                         const kinematics::JointVector& q) noexcept {
  kinematics::ExcaliburJoints dh;
  for (Eigen::Index i = 0; i < 6; ++i) {
    dh(i) = q(i);
  }
  const kinematics::ExcaliburJoints star = kinematics::to_controller(model, dh);
  ControllerAngles out{};
  for (std::size_t i = 0; i < kJointCount; ++i) {
    out[i] = star(static_cast<Eigen::Index>(i)) * kDegPerRad;
  }
  return out;
}

kinematics::JointVector from_wire(const kinematics::ExcaliburModel& model,
                                  const ControllerAngles& q_controller_deg) noexcept {
  kinematics::ExcaliburJoints star;
  for (std::size_t i = 0; i < kJointCount; ++i) {
    star(static_cast<Eigen::Index>(i)) = q_controller_deg[i] / kDegPerRad;
  }
  const kinematics::ExcaliburJoints dh = kinematics::from_controller(model, star);
  kinematics::JointVector out(6);
  for (Eigen::Index i = 0; i < 6; ++i) {
    out(i) = dh(i);
  }
  return out;
}

double max_difference_deg(const ControllerAngles& a,
                          const ControllerAngles& b,
                          std::size_t* joint) noexcept {
  double worst = 0.0;
  std::size_t where = 0;
  for (std::size_t i = 0; i < kJointCount; ++i) {
    const double d = std::abs(a[i] - b[i]);
    if (d > worst || std::isnan(d)) {
      worst = d;
      where = i;
    }
  }
  if (joint != nullptr) {
    *joint = where;
  }
  return worst;
}

}  // namespace cell::protocols::excalibur
