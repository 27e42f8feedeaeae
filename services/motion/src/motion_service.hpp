#pragma once

#include <chrono>
#include <deque>
#include <map>
#include <optional>
#include <string>

#include "cell/bus/reader.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/motion/planner.hpp"
#include "cell/service/runtime.hpp"
#include "motion_config.hpp"

namespace cell::motion_service {

/// The motion service: accepts MotionRequests, plans with each robot's model, sends the
/// Trajectory to the robot's gateway and reports MotionStatus (accepted / refused with the
/// reason / running with progress / done / failed; preview with the planned path).
/// Every request is answered. One motion per robot at a time: a request for a busy robot is
/// refused (except stop and alter-off).
///
/// Topics: in cell/motion/request (command), cell/robot/state (stream),
/// cell/robot/command_reply (recent); out cell/motion/status (state, keyed by motion_id),
/// cell/motion/trajectory (command), cell/robot/command (command), cell/health/event.
class MotionService {
 public:
  MotionService(service::Context& ctx, const MotionConfig& config);
  void run(service::Context& ctx);

 private:
  using SteadyTime = std::chrono::steady_clock::time_point;

  struct RobotView {  // latest RobotState of one robot
    trajectory::JointVector q;
    cell_robot_RobotMode mode = cell_robot_MODE_UNCONFIGURED;
    bool homed = false;
    bool moving = false;
    bool tracking = false;
    std::string trajectory_id;
    double progress = 0.0;
    std::string fault_text;
    SteadyTime received{};
  };

  /// A moving target's meeting (MOTION_TRACK with a velocity): in every status of the motion.
  struct Meeting {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  ///< base_T_tool
    std::int64_t stamp_ns = 0;                               ///< wall clock
    double ramp_mm = 0.0;                                    ///< the meeting ramp (Intercept)
  };

  struct Active {  // a motion sent to a gateway, not finished yet
    std::string motion_id;
    std::string robot_id;
    cell_common_RequestId request_id{};  // strings below own the client id
    std::string client_id;
    std::string trajectory_id;
    std::uint64_t gateway_seq = 0;
    bool gateway_accepted = false;
    bool started = false;         // the robot's state has named this trajectory
    SteadyTime mismatch_since{};  // since when, after it started, the state names another
    SteadyTime sent{};
    double duration_s = 0.0;
    std::vector<double> final_joints;
    std::optional<Meeting> meeting;
    SteadyTime last_status{};
  };

  struct Robot {
    std::unique_ptr<motion::Planner> planner;
    RobotView view;
    std::optional<Active> active;
  };

  void handle_request(const cell_motion_MotionRequest& request);
  /// Plans `request` from the robot's current joints; a track of a moving target also gives
  /// where and when it is met (`meeting`).
  Result<motion::Plan> plan(const cell_motion_MotionRequest& request, Robot& robot,
                            std::optional<Meeting>& meeting) const;
  void handle_state(const cell_robot_RobotState& state);
  void handle_gateway_reply(const cell_robot_RobotCommandReply& reply);
  void supervise();
  void send_command(const std::string& robot_id, cell_robot_RobotCommandKind kind);

  /// Publishes a status for `motion_id`.
  void publish(const std::string& motion_id, const cell_common_RequestId& request_id,
               const std::string& robot_id, cell_motion_MotionState state,
               const Error* error = nullptr, double progress = 0.0, double duration_s = 0.0,
               const std::vector<Eigen::Isometry3d>* path = nullptr,
               const std::vector<double>* final_joints = nullptr,
               const Meeting* meeting = nullptr);
  void finish(Robot& robot, cell_motion_MotionState state, const Error* error);

  MotionConfig config_;
  std::string client_id_;
  std::uint64_t seq_ = 0;
  std::map<std::string, Robot> robots_;
  std::deque<std::string> finished_;  // motion ids, oldest first (disposed beyond keep_finished)
  /// Requests for a robot whose state has not arrived yet (the cell just started): held up to
  /// state_timeout_s, then answered either way.
  struct Waiting {
    bus::Owned<cell_motion_MotionRequest> request;
    SteadyTime since;
  };
  std::vector<Waiting> waiting_;
  void take_requests();

  bus::Topic<cell_motion_MotionRequest> request_topic_;
  bus::Topic<cell_motion_MotionStatus> status_topic_;
  bus::Topic<cell_motion_Trajectory> trajectory_topic_;
  bus::Topic<cell_robot_RobotState> state_topic_;
  bus::Topic<cell_robot_RobotCommand> command_topic_;
  bus::Topic<cell_robot_RobotCommandReply> reply_topic_;
  bus::Reader<cell_motion_MotionRequest> request_reader_;
  bus::Writer<cell_motion_MotionStatus> status_writer_;
  bus::Writer<cell_motion_Trajectory> trajectory_writer_;
  bus::Reader<cell_robot_RobotState> state_reader_;
  bus::Writer<cell_robot_RobotCommand> command_writer_;
  bus::Reader<cell_robot_RobotCommandReply> reply_reader_;
};

/// Name of a motion kind ("move_joints", "pick", ...).
std::string_view to_string(cell_motion_MotionKind kind) noexcept;

}  // namespace cell::motion_service
