#pragma once

#include "cell/bus/idl_types.hpp"
#include "cell/bus/qos.hpp"

/// Every topic of the cell: its name, its type and its QoS profile, in one place, so a writer
/// and a reader of a topic cannot disagree.
namespace cell::bus {

enum class QosProfile { kState, kStream, kReliableStream, kCommand, kRecent, kHeartbeat };

/// A topic's name bound to its IDL type and QoS profile.
template <IdlType T>
struct TopicDef {
  const char* name;
  QosProfile profile;
  std::int32_t depth = 8;  ///< history depth for the stream and recent profiles
};

/// The QoS of a topic definition's profile.
template <IdlType T>
Qos make_qos(const TopicDef<T>& def) {
  switch (def.profile) {
    case QosProfile::kState:
      return qos::state();
    case QosProfile::kStream:
      return qos::stream(def.depth);
    case QosProfile::kReliableStream:
      return qos::reliable_stream(def.depth);
    case QosProfile::kCommand:
      return qos::command();
    case QosProfile::kRecent:
      return qos::recent(def.depth);
    case QosProfile::kHeartbeat:
      return qos::heartbeat();
  }
  return qos::command();
}

namespace topics {

// health.idl
inline constexpr TopicDef<cell_health_ServiceHeartbeat> kHeartbeat{"cell/health/heartbeat",
                                                                   QosProfile::kHeartbeat};
inline constexpr TopicDef<cell_health_CellEvent> kCellEvent{"cell/health/event",
                                                            QosProfile::kRecent, 100};
inline constexpr TopicDef<cell_health_PingRequest> kPingRequest{"cell/health/ping",
                                                                QosProfile::kCommand};
inline constexpr TopicDef<cell_health_PingReply> kPingReply{"cell/health/pong",
                                                            QosProfile::kRecent, 32};
// robot.idl
// Depth 64: a reader descheduled for up to 64 ms still loses nothing of a 1 kHz stream.
inline constexpr TopicDef<cell_robot_RobotState> kRobotState{"cell/robot/state",
                                                             QosProfile::kStream, 64};
inline constexpr TopicDef<cell_robot_RobotState> kRobotStateLatest{"cell/robot/state_latest",
                                                                   QosProfile::kState};
inline constexpr TopicDef<cell_robot_RobotCommand> kRobotCommand{"cell/robot/command",
                                                                 QosProfile::kCommand};
inline constexpr TopicDef<cell_robot_RobotCommandReply> kRobotCommandReply{
    "cell/robot/command_reply", QosProfile::kRecent, 32};
// motion.idl
inline constexpr TopicDef<cell_motion_Trajectory> kTrajectory{"cell/motion/trajectory",
                                                              QosProfile::kCommand};
inline constexpr TopicDef<cell_motion_AlterCorrection> kAlter{"cell/motion/alter",
                                                              QosProfile::kStream, 1};
inline constexpr TopicDef<cell_motion_MotionRequest> kMotionRequest{"cell/motion/request",
                                                                    QosProfile::kCommand};
inline constexpr TopicDef<cell_motion_MotionStatus> kMotionStatus{"cell/motion/status",
                                                                  QosProfile::kState};
// vision.idl
inline constexpr TopicDef<cell_vision_Image> kImage{"cell/vision/image", QosProfile::kStream, 2};
// The same images at a reduced rate (the camera's preview_hz), sent only while someone reads
// them: what crosses to other PCs, where a multi-host profile keeps cell/vision/image home.
inline constexpr TopicDef<cell_vision_Image> kImagePreview{"cell/vision/image_preview",
                                                           QosProfile::kStream, 1};
inline constexpr TopicDef<cell_vision_Detections> kDetections{"cell/vision/detections",
                                                              QosProfile::kStream, 8};
inline constexpr TopicDef<cell_vision_EdgeRequest> kEdgeRequest{"cell/vision/edge_request",
                                                                QosProfile::kCommand};
inline constexpr TopicDef<cell_vision_EdgeResult> kEdgeResult{"cell/vision/edge_result",
                                                              QosProfile::kRecent, 32};
inline constexpr TopicDef<cell_vision_ImageRequest> kImageRequest{"cell/vision/image_request",
                                                                  QosProfile::kCommand};
inline constexpr TopicDef<cell_vision_ImageTruth> kImageTruth{"cell/vision/image_truth",
                                                              QosProfile::kRecent, 8};
// calibration.idl
inline constexpr TopicDef<cell_calibration_CameraCalibration> kCameraCalibration{
    "cell/calibration/camera", QosProfile::kState};
inline constexpr TopicDef<cell_calibration_BeltCalibration> kBeltCalibration{
    "cell/calibration/belt", QosProfile::kState};
inline constexpr TopicDef<cell_calibration_CalibrationRequest> kCalibrationRequest{
    "cell/calibration/request", QosProfile::kCommand};
inline constexpr TopicDef<cell_calibration_CalibrationProgress> kCalibrationProgress{
    "cell/calibration/progress", QosProfile::kRecent, 64};
inline constexpr TopicDef<cell_calibration_CalibrationResult> kCalibrationResult{
    "cell/calibration/result", QosProfile::kRecent, 32};
// task.idl
inline constexpr TopicDef<cell_task_JobRequest> kJobRequest{"cell/task/job_request",
                                                            QosProfile::kCommand};
inline constexpr TopicDef<cell_task_JobCommand> kJobCommand{"cell/task/job_command",
                                                            QosProfile::kCommand};
inline constexpr TopicDef<cell_task_JobStatus> kJobStatus{"cell/task/job_status",
                                                          QosProfile::kState};
inline constexpr TopicDef<cell_task_JobCommandReply> kJobCommandReply{
    "cell/task/job_command_reply", QosProfile::kRecent, 64};

// world.idl
inline constexpr TopicDef<cell_world_BeltState> kBeltState{"cell/world/belt", QosProfile::kStream,
                                                           64};
inline constexpr TopicDef<cell_world_PhotocellEvent> kPhotocell{"cell/world/photocell",
                                                                QosProfile::kCommand};
inline constexpr TopicDef<cell_world_WorldState> kWorldState{"cell/world/state",
                                                             QosProfile::kStream, 1};
inline constexpr TopicDef<cell_world_WorldRequest> kWorldRequest{"cell/world/request",
                                                                 QosProfile::kCommand};
inline constexpr TopicDef<cell_world_WorldReply> kWorldReply{"cell/world/reply",
                                                             QosProfile::kRecent, 32};

}  // namespace topics
}  // namespace cell::bus
