#pragma once

#include <string>

#include <gtest/gtest.h>

#include "camera_config.hpp"
#include "cell/config/yaml.hpp"

/// Camera service configs from YAML text in tests.
namespace cell::camera::testing {

/// The config of `yaml` (as if read from camera.yaml); a test failure when it does not load.
inline CameraConfig config_from(const std::string& yaml) {
  auto doc = config::load_string(yaml, "camera.yaml");
  EXPECT_TRUE(doc);
  auto c = load_config(*doc);
  EXPECT_TRUE(c) << c.error().message;
  return *c;
}

}  // namespace cell::camera::testing
