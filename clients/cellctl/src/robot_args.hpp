#pragma once

#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "cell/common/result.hpp"
#include "cell/kinematics/robot_model.hpp"

/// Parsing and printing of robot quantities at cellctl's edge: joints in the robot's display
/// units (deg for revolute joints, mm for prismatic ones), poses as x,y,z [mm] and roll, pitch,
/// yaw [deg] in the URDF convention (R = Rz(yaw) * Ry(pitch) * Rx(roll), fixed axes).
namespace cell::cellctl {

/// The robot model of `robot_id` from config/robots/<robot_id>.yaml (under CELL_HOME).
/// Errors name the file and what is wrong with it.
Result<kinematics::RobotModel> load_robot_by_id(const std::string& robot_id);

/// "a,b,c,..." -> numbers. Errors name the bad element and `what` (e.g. "--joints").
Result<std::vector<double>> parse_numbers(const std::string& text, const std::string& what);

/// Joints given in display units to internal units; the count must match the robot.
Result<kinematics::JointVector> joints_from_display(const kinematics::RobotModel& model,
                                                    const std::vector<double>& values,
                                                    const std::string& what);

/// "x,y,z,roll,pitch,yaw" (mm, deg) -> base_T_tool.
Result<Eigen::Isometry3d> pose_from_text(const std::string& text, const std::string& what);

/// JSON of a pose: {"x_mm", "y_mm", "z_mm", "roll_deg", "pitch_deg", "yaw_deg"}.
nlohmann::json pose_json(const Eigen::Isometry3d& pose);
/// "x=... mm y=... mm z=... mm roll=... deg pitch=... deg yaw=... deg".
std::string pose_text(const Eigen::Isometry3d& pose);

/// JSON array of the joints: [{"name", "value", "unit"}].
nlohmann::json joints_json(const kinematics::RobotModel& model, const kinematics::JointVector& q);
/// "j1=45.000 deg j2=105.000 deg z=0.000 mm r=0.000 deg".
std::string joints_text(const kinematics::RobotModel& model, const kinematics::JointVector& q);

}  // namespace cell::cellctl
