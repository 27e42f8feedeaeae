#pragma once

#include <string>

#include "cell/common/result.hpp"
#include "cell/config/yaml.hpp"
#include "cell/kinematics/robot_model.hpp"

/// Loading robot models from config/robots/*.yaml. The keys are documented in
/// core/kinematics/README.md and in the shipped files (ibm7545.yaml, scara_picker.yaml,
/// excalibur.yaml). Degrees and mm in the file; radians and mm in the model.
namespace cell::kinematics {

/// Reads and validates a robot file. Errors: kConfig with every problem at once, one per line,
/// each "file:line:col: key 'a.b': what was wrong" (missing or unknown keys, wrong types,
/// unknown kind, wrong joint count or type for the kind, and every rule of the model's
/// validate(), e.g. "robots/x.yaml:9:13: key 'scara.link2_mm': must be > 0, got -250").
/// Thread-safe (no shared state).
Result<RobotModel> load_robot(const std::string& path);

/// As load_robot, from an already parsed document (its path names the errors).
Result<RobotModel> parse_robot(const config::Document& doc);

}  // namespace cell::kinematics
