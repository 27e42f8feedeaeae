#pragma once

// Loading the shipped robot files (config/robots/*.yaml) in tests.

#include <string>

#include "cell/kinematics/robot_config.hpp"
#include "cell/testing/env.hpp"

namespace cell::kinematics::test {

/// The robot of config/robots/<name>.yaml in this checkout.
inline Result<RobotModel> load_shipped(const std::string& name) {
  return load_robot(cell::testing::source_dir() + "/config/robots/" + name + ".yaml");
}

}  // namespace cell::kinematics::test
