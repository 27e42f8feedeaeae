#pragma once

#include <dds/dds.h>

#include "bench.h"
#include "calibration.h"
#include "common.h"
#include "health.h"
#include "motion.h"
#include "robot.h"
#include "task.h"
#include "vision.h"
#include "world.h"

namespace cell::bus {

/// idlc C type -> its topic descriptor. Only types registered here can be used with Topic,
/// Reader and Writer: an unregistered type does not compile.
template <typename T>
inline constexpr const dds_topic_descriptor_t* kDescriptor = nullptr;
/// Whether T is registered. A flag of its own: the address of a descriptor compared with
/// nullptr is no constant expression where null-pointer checks are kept (-fsanitize=undefined).
template <typename T>
inline constexpr bool kRegistered = false;

template <typename T>
concept IdlType = kRegistered<T>;

#define CELL_BUS_REGISTER(type)                                                    \
  template <>                                                                      \
  inline constexpr const dds_topic_descriptor_t* kDescriptor<type> = &type##_desc; \
  template <>                                                                      \
  inline constexpr bool kRegistered<type> = true

CELL_BUS_REGISTER(cell_health_ServiceHeartbeat);
CELL_BUS_REGISTER(cell_health_CellEvent);
CELL_BUS_REGISTER(cell_health_PingRequest);
CELL_BUS_REGISTER(cell_health_PingReply);
CELL_BUS_REGISTER(cell_robot_RobotState);
CELL_BUS_REGISTER(cell_robot_RobotCommand);
CELL_BUS_REGISTER(cell_robot_RobotCommandReply);
CELL_BUS_REGISTER(cell_motion_Trajectory);
CELL_BUS_REGISTER(cell_motion_AlterCorrection);
CELL_BUS_REGISTER(cell_motion_MotionRequest);
CELL_BUS_REGISTER(cell_motion_MotionStatus);
CELL_BUS_REGISTER(cell_vision_Image);
CELL_BUS_REGISTER(cell_vision_Detections);
CELL_BUS_REGISTER(cell_vision_EdgeRequest);
CELL_BUS_REGISTER(cell_vision_EdgeResult);
CELL_BUS_REGISTER(cell_vision_ImageRequest);
CELL_BUS_REGISTER(cell_vision_ImageTruth);
CELL_BUS_REGISTER(cell_world_BeltState);
CELL_BUS_REGISTER(cell_world_PhotocellEvent);
CELL_BUS_REGISTER(cell_world_WorldState);
CELL_BUS_REGISTER(cell_world_WorldRequest);
CELL_BUS_REGISTER(cell_world_WorldReply);
CELL_BUS_REGISTER(cell_calibration_CameraCalibration);
CELL_BUS_REGISTER(cell_calibration_BeltCalibration);
CELL_BUS_REGISTER(cell_calibration_CalibrationRequest);
CELL_BUS_REGISTER(cell_calibration_CalibrationProgress);
CELL_BUS_REGISTER(cell_calibration_CalibrationResult);
CELL_BUS_REGISTER(cell_task_JobRequest);
CELL_BUS_REGISTER(cell_task_JobCommand);
CELL_BUS_REGISTER(cell_task_JobStatus);
CELL_BUS_REGISTER(cell_task_JobCommandReply);
CELL_BUS_REGISTER(cell_bench_Small);
CELL_BUS_REGISTER(cell_bench_Blob);

#undef CELL_BUS_REGISTER

}  // namespace cell::bus
