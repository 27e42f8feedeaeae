#pragma once

#include <span>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/kinematics/excalibur.hpp"
#include "cell/kinematics/joints.hpp"
#include "cell/kinematics/scara.hpp"
#include "cell/kinematics/workspace.hpp"

// Validation rules of the robot models, shared by validate() (messages name the key) and the
// config loader (which adds the file:line:col of each key). Keys are dotted paths of the YAML
// file, e.g. "joints[2].upper_mm", "scara.link2_mm".
namespace cell::kinematics::detail {

struct ConfigIssue {
  std::string key;   // dotted YAML path
  std::string what;  // the rule and the value, e.g. "must be > 0, got -250"
};
using Issues = std::vector<ConfigIssue>;

void joint_issues(std::span<const JointSpec> joints,
                  std::span<const JointType> expected_types,
                  std::string_view kind_description,
                  Issues& out);
void cartesian_issues(const CartesianLimits& limits, Issues& out);
void tool_issues(const Eigen::Isometry3d& flange_T_tool, Issues& out);
Issues scara_issues(const ScaraModel& model);
Issues excalibur_issues(const ExcaliburModel& model);

// kConfig with "key 'k': what" per issue, one per line; ok when there are none.
Status to_status(const Issues& issues);

// The joint config key for `field` ("lower", "upper", "max_speed", "counts_per") in the joint's
// display unit: lower_deg / lower_mm, max_speed_deg_s, counts_per_deg...
std::string joint_key(const JointSpec& joint, std::string_view field);

}  // namespace cell::kinematics::detail
