#pragma once

// The shipped robot files, as the monitor's tests load them.

#include <string>

#include "cell/kinematics/robot_model.hpp"
#include "test_robots.hpp"

namespace cell::monitor::test {

/// The robot of config/robots/<id>.yaml (the test fails with an exception if it does not load).
inline kinematics::RobotModel robot(const std::string& id) {
  return kinematics::test::load_shipped(id).value();
}

}  // namespace cell::monitor::test
