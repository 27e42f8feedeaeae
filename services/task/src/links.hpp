#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/common/result.hpp"
#include "cell/kinematics/joints.hpp"
#include "cell/service/directory.hpp"

/// The task service's view of the rest of the cell, one set per worker thread (each owns its
/// readers, so no sample meant for one worker is taken by another): motion requests and their
/// outcome, robot states, located parts, belt encoders, ALTER corrections, robot commands.
/// Every wait is bounded and polls the job's Control, so pause, cancel and a service stop are
/// honoured within a few tens of milliseconds. Not thread-safe: one worker uses one set.
namespace cell::task_service {

using Clock = std::chrono::steady_clock;

/// What a running job is told from outside (set by the service thread, read by the worker).
struct Control {
  std::atomic<bool> pause{false};
  std::atomic<bool> cancel{false};
  std::atomic<bool> stop{false};  ///< the service is stopping: leave the job resumable
  bool interrupted() const noexcept { return cancel.load() || stop.load(); }
};

/// Why a wait ended early.
enum class Interrupt : std::uint8_t { kNone, kCancel, kStop };
Interrupt interrupt_of(const Control& control) noexcept;

/// The latest state of one robot, as the task needs it.
struct RobotView {
  bool known = false;
  kinematics::JointVector q;
  Eigen::Isometry3d base_T_tool = Eigen::Isometry3d::Identity();
  cell_robot_RobotMode mode = cell_robot_MODE_UNCONFIGURED;
  cell_robot_GripperState gripper = cell_robot_GRIPPER_UNKNOWN;
  bool homed = false;
  bool moving = false;
  bool tracking = false;  ///< arrived, following ALTER corrections (a belt)
  std::string trajectory_id;
  std::string fault_text;
  std::string stop_code;  ///< why STOPPED: "command", "supervisor_lost" (the gateway's own stop)
  std::int64_t stamp_ns = 0;  ///< wall clock of the state (when the gateway read the joints)
  Clock::time_point received{};
};

/// Outcome of a motion the task asked for.
struct MotionOutcome {
  cell_motion_MotionState state = cell_motion_MOTION_FAILED;
  std::string reason;
  /// The motion service's code for a refusal or failure (to_string(Errc): "not_ready",
  /// "out_of_range", ...): what the task decides by; the reason is for people.
  std::string error_code;
  std::vector<double> final_joints;
  Interrupt interrupted = Interrupt::kNone;
  bool robot_fault = false;  ///< it failed because the robot faulted (the job pauses)
  /// The outcome could not be seen: the motion service or the robot's gateway was lost or
  /// restarted while the motion ran (the request or its status may be gone). The robot may
  /// still have executed it: the executor verifies before it redoes anything.
  bool unseen = false;
  bool ok() const { return state == cell_motion_MOTION_DONE; }
};

/// A located part in the robot's base frame (from the vision service's Detections).
struct Located {
  std::string class_name;
  double x_mm = 0.0;
  double y_mm = 0.0;
  double yaw_rad = 0.0;
  double quality = 0.0;
  cell_vision_GripClearance grip = cell_vision_GRIP_NOT_TESTED;
  std::int32_t grip_style = -1;
  std::string grip_detail;
  /// Every clear grasp style (vision's clear-grip test, in style order): where the tool goes
  /// (base frame, mm) and its yaw there (the fingers close along the tool's y axis). Empty
  /// when the grip was not tested.
  struct Grasp {
    std::int32_t style = -1;
    std::string name;
    double x_mm = 0.0;
    double y_mm = 0.0;
    double yaw_rad = 0.0;
  };
  std::vector<Grasp> grasps;
  bool touching = false;
  bool has_pose = false;
};

/// One frame's worth of located parts.
struct Frame {
  std::vector<Located> parts;
  std::int64_t exposure_ns = 0;  ///< wall clock, mid-exposure
  std::int64_t belt_count = 0;   ///< encoder count latched at exposure (belt cameras)
  std::uint64_t image_sequence = 0;  ///< the image's (for EdgeRequests on the same image)
  std::string error;             ///< non-empty: the image could not be processed
  std::string calibration;       ///< what mapped pixels to the robot
  double processing_ms = 0.0;
  Clock::time_point received{};
  std::int64_t received_ns = 0;  ///< wall clock when it reached the task service
};

/// A Detections sample as a Frame (parts in the robot's base frame).
Frame to_frame(const cell_vision_Detections& d);

/// The newest encoder reading of a belt.
struct BeltReading {
  std::int64_t count = 0;
  double speed_mm_per_s = 0.0;
  std::int64_t stamp_ns = 0;  ///< wall clock of the reading
  Clock::time_point received{};
};

/// The heartbeats of the services a job needs, from service::ServiceDirectory (3 s liveliness
/// lease): which are alive, and a generation per service that changes whenever it was lost,
/// vanished or came back as another process (its pid changed), so a wait can tell that a
/// request it sent may be gone. Not thread-safe: one worker uses one.
class Peers {
 public:
  /// Throws bus::BusError when the heartbeat reader cannot be created (setup).
  Peers(const bus::Participant& participant, const std::string& client);

  /// Reads the heartbeats that arrived (at most every 100 ms unless `force`). The first call
  /// waits up to 3 s for discovery to settle.
  void refresh(bool force = false);

  /// Empty when every id has a live heartbeat; else what is wrong with each of the others,
  /// e.g. "motion: no heartbeat, gateway.ibm7545: not on the bus" (after refresh()).
  std::string missing(const std::vector<std::string>& ids) const;

  /// Changes whenever `id` was lost or vanished, or its heartbeat's pid changed.
  std::uint64_t generation(const std::string& id) const;
  std::vector<std::uint64_t> generations(const std::vector<std::string>& ids) const;

 private:
  struct Seen {
    bool present = false;
    bool lost = false;
    std::int32_t pid = 0;
    std::uint64_t generation = 0;
  };
  service::ServiceDirectory directory_;
  std::map<std::string, Seen, std::less<>> seen_;
  Clock::time_point last_{};
  bool settled_ = false;
};

class Links {
 public:
  /// `client` names this worker on the bus (e.g. "task.ibm7545"). Throws bus::BusError when a
  /// reader or writer cannot be created (setup).
  Links(const bus::Participant& participant, const std::string& client);

  /// Sends `request` (motion_id and robot_id set by the caller) and waits for its end, polling
  /// robot states on the way. Cancel: the robot is stopped (MOTION_STOP) and the outcome says
  /// kCancel; stop: the motion is left to finish by itself (kStop). `on_progress(0..1)` is
  /// called as the motion service reports. Errors: kTimeout-like kProtocol when nobody serves
  /// the motion topic or no end comes within `timeout`.
  /// `abandon`, when given, is asked every poll: a non-empty answer (why) ends the wait with
  /// an outcome marked `unseen` (a service the motion needs was lost or restarted).
  Result<MotionOutcome> move(cell_motion_MotionRequest& request, const Control& control,
                             std::chrono::milliseconds timeout,
                             const std::function<void(double)>& on_progress = {},
                             const std::function<std::string()>& abandon = {});

  /// Non-blocking form: sends the request (its id in the return) ...
  Result<std::uint64_t> send_motion(cell_motion_MotionRequest& request);
  /// ... and the newest status of it that arrived since the last call (nullopt: none new).
  /// duration_s is the planned duration once accepted.
  struct MotionUpdate {
    cell_motion_MotionState state = cell_motion_MOTION_ACCEPTED;
    double progress = 0.0;
    double duration_s = 0.0;
    std::string reason;
    std::string error_code;  ///< REFUSED/FAILED: cell::to_string(Errc), e.g. "out_of_range"
    bool terminal = false;
    /// A track of a moving target: where (base_T_tool) and when (wall clock) it is met;
    /// meet_stamp_ns 0 otherwise.
    Eigen::Isometry3d meet_target = Eigen::Isometry3d::Identity();
    std::int64_t meet_stamp_ns = 0;
    double meet_ramp_mm = 0.0;  ///< the meeting ramp (idl/motion.idl, MotionStatus)
  };
  std::optional<MotionUpdate> poll_motion(std::uint64_t seq);

  /// The last status the motion service published for `motion_id` (transient-local, so a
  /// restarted task service sees what happened to a motion it sent before it died), waiting
  /// up to `wait` for it to arrive; nullopt when there is none.
  std::optional<MotionOutcome> motion_status(const std::string& motion_id,
                                             std::chrono::milliseconds wait);

  /// The latest state of `robot_id` (takes what has arrived).
  RobotView robot(const std::string& robot_id);

  /// Waits until `pred(robot view)` holds or `timeout` or an interrupt; true when it held.
  bool wait_robot(const std::string& robot_id, const std::function<bool(const RobotView&)>& pred,
                  std::chrono::milliseconds timeout, const Control& control);

  /// Every Detections of `camera_id` that arrived since the last call, whichever request (or
  /// none: a photocell-triggered camera's own frames) it answered. Non-blocking.
  std::vector<Frame> take_frames(const std::string& camera_id);
  /// Blocks until a Detections sample (of any camera) is there to take, or `timeout`; true
  /// when one is. Lets a job waiting for parts react to a frame at once instead of polling.
  bool wait_frames(std::chrono::milliseconds timeout);

  /// Asks `camera_id` for one frame (now, or at the next photocell edge) and waits for the
  /// vision service's detections of exactly that frame. Errors: kProtocol naming what did not
  /// answer (no camera on the bus, no detections within `timeout`); interrupts: kNotReady.
  Result<Frame> locate(const std::string& camera_id, cell_vision_TriggerKind trigger,
                       std::chrono::milliseconds timeout, const Control& control);

  /// The calibration service's BeltCalibration of `belt_id` (robot base frame), when one has
  /// been published (transient-local: a late joiner gets the current one).
  struct BeltCalibrationView {
    std::string robot_id;
    double mm_per_count = 0.0;
    Eigen::Vector3d direction = Eigen::Vector3d::UnitX();
    Eigen::Vector3d origin_mm = Eigen::Vector3d::Zero();
    std::string version;
  };
  std::optional<BeltCalibrationView> belt_calibration(const std::string& belt_id);

  /// The newest reading of `belt_id` (nullopt until one arrived).
  std::optional<BeltReading> belt(const std::string& belt_id);

  /// Writes an ALTER correction (world/base frame translation and its rate) for the robot's
  /// running trajectory, valid at `stamp_ns` (wall clock; 0: now): the gateway extrapolates
  /// it with its rate from then, so the age of a belt reading does not make the arm lag, for
  /// at most `extrapolate_s` past the stamp (0: the gateway's horizon).
  Status alter(const std::string& robot_id, const std::string& trajectory_id,
               std::uint64_t cycle, const Eigen::Vector3d& translation_mm,
               const Eigen::Vector3d& velocity_mm_per_s, std::int64_t stamp_ns = 0,
               double extrapolate_s = 0.0);

  /// Sends a robot command (gripper, alter-off, stop) and waits for the gateway's answer.
  Status command(const std::string& robot_id, cell_robot_RobotCommandKind kind,
                 std::chrono::milliseconds timeout);
  /// The same for a command with its parameters filled in (lights, gripper width, ...).
  Status command(cell_robot_RobotCommand& command, std::chrono::milliseconds timeout);
  /// The same, calling `between` until the answer comes (it paces itself: e.g. one ALTER
  /// correction per cycle, so a gripper closing on a tracked part keeps following it however
  /// long the link takes to carry the command and its answer).
  Status command(const std::string& robot_id, cell_robot_RobotCommandKind kind,
                 std::chrono::milliseconds timeout, const std::function<void()>& between);

  const std::string& client_id() const noexcept { return motions_.client_id(); }

  /// The worker's participant (for an executor's own readers and requesters).
  const bus::Participant& participant() const noexcept { return participant_; }

  /// The heartbeats of the cell's services (this worker's own directory).
  Peers& peers() noexcept { return peers_; }

 private:
  static Status command_answer(const std::string& robot_id,
                               const bus::Owned<cell_robot_RobotCommandReply>& reply);
  void take_states();
  void take_belts();

  const bus::Participant& participant_;
  bus::Requester<cell_motion_MotionRequest, cell_motion_MotionStatus> motions_;
  bus::Requester<cell_vision_ImageRequest, cell_vision_Detections> images_;
  bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply> commands_;
  bus::Topic<cell_motion_MotionStatus> status_topic_;
  bus::Reader<cell_motion_MotionStatus> status_reader_;  ///< all statuses (restart recovery)
  bus::Topic<cell_robot_RobotState> state_topic_;
  bus::Reader<cell_robot_RobotState> state_reader_;
  bus::Topic<cell_world_BeltState> belt_topic_;
  bus::Reader<cell_world_BeltState> belt_reader_;
  bus::Topic<cell_motion_AlterCorrection> alter_topic_;
  bus::Writer<cell_motion_AlterCorrection> alter_writer_;
  std::map<std::string, RobotView, std::less<>> robots_;
  std::map<std::string, BeltReading, std::less<>> belts_;
  std::map<std::string, MotionOutcome, std::less<>> statuses_;
  bus::Topic<cell_calibration_BeltCalibration> belt_cal_topic_;
  bus::Reader<cell_calibration_BeltCalibration> belt_cal_reader_;
  std::map<std::string, BeltCalibrationView, std::less<>> belt_cals_;
  Peers peers_;
};

}  // namespace cell::task_service
