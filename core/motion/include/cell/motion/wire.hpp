#pragma once

#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/bus/idl_types.hpp"
#include "cell/common/result.hpp"
#include "cell/trajectory/joint_trajectory.hpp"

/// Conversions between the motion library's C++ types and the bus contract's C structs
/// (idl/motion.idl, idl/common.idl). Shared by the motion service, the gateway and the clients
/// so that a trajectory means the same thing on both ends of the wire.
namespace cell::motion {

/// A gripper action at a time along a trajectory (IDL TrajectoryEvent).
struct GripperEvent {
  double t_s = 0.0;
  bool close = false;    ///< true: close, false: open
  double dwell_s = 0.0;  ///< the trajectory holds still this long after t_s
};

/// A trajectory plus what travels with it to the gateway.
struct Plan {
  trajectory::JointTrajectory trajectory;
  std::vector<GripperEvent> events;
  bool alter_enabled = false;
  bool alter_cumulative = false;
  bool alter_world_frame = true;
};

/// Storage that the C struct filled by to_idl() points into: keep it alive while the struct
/// is written. (idlc's C types hold raw pointers; bus::borrow semantics.)
struct TrajectoryWire {
  cell_motion_Trajectory message{};
  std::string robot_id;
  std::string trajectory_id;
  std::string motion_id;
  std::string frame_id;
  std::vector<std::vector<double>> positions;
  std::vector<std::vector<double>> velocities;
  std::vector<cell_motion_TrajectoryKnot> knots;
  std::vector<cell_motion_TrajectoryEvent> events;
};

/// Fills `wire` from a plan (message points into wire's own storage).
void to_idl(const Plan& plan, const std::string& robot_id, const std::string& trajectory_id,
            const std::string& motion_id, TrajectoryWire& wire);

/// Parses a received Trajectory. Errors (kInvalidArgument) name what is malformed: no knots,
/// knot i with a wrong number of joints (expected `dof`), non-increasing or non-finite times,
/// unknown event kind, negative dwell.
Result<Plan> from_idl(const cell_motion_Trajectory& message, int dof);

/// Pose conversions: IDL Pose (mm, unit quaternion w x y z) <-> Isometry3d. from_idl
/// normalises the quaternion; errors: kInvalidArgument for non-finite values or a quaternion
/// far from unit length (|q| outside [0.9, 1.1]: almost surely not a rotation).
cell_common_Pose to_idl(const Eigen::Isometry3d& pose);
Result<Eigen::Isometry3d> from_idl(const cell_common_Pose& pose);

}  // namespace cell::motion
