#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "calibration_config.hpp"
#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/sample.hpp"
#include "cell/bus/topics.hpp"
#include "cell/bus/writer.hpp"
#include "cell/common/result.hpp"
#include "cell/kinematics/joints.hpp"

/// What a guided procedure asks of the rest of the cell, over the bus: move a robot (the
/// motion service), take a frame (a camera service), switch lights (a gateway), set the
/// simulated world up (cell-sim-world). Every call waits with a deadline and gives up early
/// when the procedure is cancelled (kNotReady "cancelled"). Used from the procedure's worker
/// thread only (one call at a time).
namespace cell::calibration_service {

/// A frame and what came with it.
struct Frame {
  cv::Mat gray;                      ///< mono8, owned (copied out of the sample)
  std::string camera_id;
  std::uint64_t seq = 0;
  std::int64_t stamp_ns = 0;         ///< mid-exposure
  std::string robot_id;              ///< eye-in-hand: the carrying robot
  kinematics::JointVector joints;    ///< its joints at the exposure
  std::string belt_id;
  std::int64_t belt_count = 0;       ///< latched at the exposure
  std::string request_key;           ///< "<client>#<seq>": the request it answers
};

class CellLink {
 public:
  /// Creates the readers and writers (throws bus::BusError on a DDS failure: setup).
  CellLink(const bus::Participant& participant, const Timeouts& timeouts,
           const std::atomic<bool>& cancel);

  /// Joint move; returns the final joints once the motion is DONE. Errors: kTimeout (no motion
  /// service, or no end in motion_s), kProtocol (refused or failed, with the motion service's
  /// reason), kNotReady (cancelled).
  Result<kinematics::JointVector> move_joints(const std::string& robot_id,
                                              const kinematics::JointVector& q, double speed_scale);

  /// One frame, taken now. Errors: kTimeout (no camera service or no frame in image_s),
  /// kProtocol (the camera refused, with its reason), kInvalidArgument (a malformed image),
  /// kNotReady (cancelled).
  Result<Frame> grab(const std::string& camera_id);

  /// Lights of a robot's gateway (RobotCommand CMD_LIGHTS). Errors: kTimeout, kProtocol.
  Status lights(const std::string& robot_id, bool halogen, bool fluorescent);

  /// Resets the simulated world to `scene_yaml` ("" = its configured scene). Errors: kTimeout
  /// (no cell-sim-world), kProtocol (refused, with the reason).
  Status reset_world(const std::string& scene_yaml, const std::string& name);

  /// Waits `seconds` (or until cancelled: kNotReady).
  Status pause(double seconds);

 private:
  bool cancelled() const noexcept { return cancel_.load(); }

  Timeouts timeouts_;
  const std::atomic<bool>& cancel_;
  std::string client_id_;
  std::uint64_t motion_count_ = 0;
  bus::Requester<cell_motion_MotionRequest, cell_motion_MotionStatus> motion_;
  bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply> robot_;
  bus::Requester<cell_world_WorldRequest, cell_world_WorldReply> world_;
  bus::Topic<cell_vision_ImageRequest> image_request_topic_;
  bus::Topic<cell_vision_Image> image_topic_;
  bus::Topic<cell_vision_ImageTruth> truth_topic_;
  bus::Writer<cell_vision_ImageRequest> image_requests_;
  bus::Reader<cell_vision_Image> images_;
  bus::Reader<cell_vision_ImageTruth> truths_;
  std::uint64_t image_seq_ = 0;
};

}  // namespace cell::calibration_service
