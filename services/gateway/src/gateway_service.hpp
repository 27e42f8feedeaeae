#pragma once

#include <atomic>
#include <memory>
#include <optional>
#include <string>
#include <thread>

#include "cell/bus/reader.hpp"
#include "cell/common/time.hpp"
#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/service/directory.hpp"
#include "cell/service/runtime.hpp"
#include "gateway_config.hpp"
#include "servo.hpp"

namespace cell::gateway {

/// One robot's gateway: the servo thread (cycle_hz) runs Servo::cycle and publishes
/// RobotState every 1/state_rate_hz; the main thread serves the bus: Trajectory and
/// RobotCommand (answered on cell/robot/command_reply), AlterCorrection, and turns servo
/// events into CellEvents. Only messages whose robot_id is this gateway's robot are taken
/// into account.
///
/// Topics: in cell/motion/trajectory (command), cell/motion/alter (stream),
/// cell/robot/command (command); out cell/robot/state (stream), cell/robot/state_latest
/// (state, 10 Hz), cell/robot/command_reply (recent), cell/health/event.
class GatewayService {
 public:
  /// Throws std::runtime_error when the robot config or the driver cannot be set up.
  GatewayService(service::Context& ctx, const GatewayConfig& config);
  ~GatewayService();
  GatewayService(const GatewayService&) = delete;
  GatewayService& operator=(const GatewayService&) = delete;

  void run(service::Context& ctx);

 private:
  void servo_loop();
  void publish_state(const ServoSnapshot& snapshot, const bus::Writer<cell_robot_RobotState>& w);
  void handle_trajectory(const cell_motion_Trajectory& message);
  void handle_command(const cell_robot_RobotCommand& message);
  void handle_alter(const cell_motion_AlterCorrection& message);
  void reply(const cell_common_RequestId& id, const Status& status);
  /// Watches the supervisors' heartbeats; stops the robot, moving or not, when every one is lost.
  void watch_supervisors(const ServoSnapshot& snapshot);

  service::Context& ctx_;
  GatewayConfig config_;
  kinematics::RobotModel model_;
  std::unique_ptr<Servo> servo_;

  bus::Topic<cell_motion_Trajectory> trajectory_topic_;
  bus::Topic<cell_motion_AlterCorrection> alter_topic_;
  bus::Topic<cell_robot_RobotCommand> command_topic_;
  bus::Topic<cell_robot_RobotCommandReply> reply_topic_;
  bus::Topic<cell_robot_RobotState> state_topic_;
  bus::Topic<cell_robot_RobotState> latest_topic_;
  bus::Reader<cell_motion_Trajectory> trajectory_reader_;
  bus::Reader<cell_motion_AlterCorrection> alter_reader_;
  bus::Reader<cell_robot_RobotCommand> command_reader_;
  bus::Writer<cell_robot_RobotCommandReply> reply_writer_;
  bus::Writer<cell_robot_RobotState> state_writer_;
  bus::Writer<cell_robot_RobotState> latest_writer_;

  // The servo thread asks the publisher thread to write a state (kPublishStream,
  // kPublishLatest bits; kPublishStop ends it): a DDS write takes Cyclone's locks, which its
  // own threads hold at normal priority, so it never runs on the real-time thread.
  static constexpr std::uint32_t kPublishStream = 1;
  static constexpr std::uint32_t kPublishLatest = 2;
  static constexpr std::uint32_t kPublishStop = 4;
  void publisher_loop();
  std::atomic<std::uint32_t> publish_request_{0};
  std::atomic<bool> stop_servo_{false};
  std::thread publisher_thread_;
  std::thread servo_thread_;
  std::uint64_t state_seq_ = 0;

  // Supervisor watch (main thread only).
  std::optional<service::ServiceDirectory> directory_;
  bool supervisors_lost_ = false;  ///< every supervisor lost, and the robot stopped for it once
  /// When this gateway started (wall clock, ns): a trajectory stamped before it was sent to a
  /// predecessor (the topic keeps recent commands for late joiners) and is never run.
  std::int64_t started_wall_ns_ = wall_time_ns();
};

}  // namespace cell::gateway
