#pragma once

// What the teach tests share: tolerances, degrees and the shipped 7545 model.

#include <numbers>
#include <string>

#include "cell/geometry/angles.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/teach/task_file.hpp"
#include "test_robots.hpp"

namespace cell::teach::test {

inline constexpr double kTolRad = 1e-9;
inline constexpr double kTolMm = 1e-6;

inline double deg(double d) { return d * geometry::kDeg; }

/// The robots of config/robots/<id>.yaml, as the task files name them.
inline RobotLookup lookup() {
  return [](const std::string& id) { return kinematics::test::load_shipped(id); };
}

inline kinematics::RobotModel ibm7545() { return lookup()("ibm7545").value(); }

/// 7545 joints from J1, J2 [deg], Z [mm], R [deg].
inline kinematics::JointVector q7545(double j1, double j2, double z, double r) {
  kinematics::JointVector q(4);
  q << deg(j1), deg(j2), z, deg(r);
  return q;
}

}  // namespace cell::teach::test
