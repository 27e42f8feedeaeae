#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <string>

#include "cell/bus/participant.hpp"
#include "cell/bus/reader.hpp"
#include "cell/bus/request_reply.hpp"
#include "cell/teach/playback.hpp"

/// Task playback on the robot: each action goes to the cell's services over the bus.
namespace cell::teach {

/// Settings of a BusRunner.
struct BusRunnerOptions {
  std::string client_name = "teach";  ///< prefix of request ids and motion ids
  std::string operator_id;            ///< RobotCommand.operator_id ("" for none)
  std::chrono::milliseconds match_timeout{5000};  ///< to find the motion service / gateway
  /// A move may take its planned duration plus this long before it is given up (stopped).
  std::chrono::milliseconds move_margin{10000};
  /// Plan and publish the path only (MotionRequest.preview_only): the arm does not move and
  /// gripper steps are skipped (StepOutcome::path holds the planned tool path).
  bool preview = false;
};

/// Runs actions for one robot: moves as MotionRequests (MOVE_JOINTS to the recorded joints, or
/// MOVE_LINEAR to their FK pose) answered by the motion service's MotionStatus, gripper steps as
/// RobotCommands to the robot's gateway, waits by waiting. Every wait has a deadline and blocks
/// on the bus (never polls).
///
/// Threads: run() on one thread; cancel() from any other (it stops the arm with a MOTION_STOP
/// and makes run() return kNotReady "cancelled"). The participant must outlive the runner.
/// Constructor throws bus::BusError on setup failure.
class BusRunner final : public StepRunner {
 public:
  BusRunner(const bus::Participant& participant, std::string robot_id, BusRunnerOptions options);
  ~BusRunner() override;

  /// Errors: kTimeout (no motion service / gateway, or no final status in time: the arm is
  /// then stopped), kOutOfRange/kInvalidArgument with the service's reason for a refusal,
  /// kProtocol for a failed motion, kNotReady after cancel().
  Result<StepOutcome> run(const Action& action) override;

  /// Stops what runs (thread-safe) and refuses further actions until reset_cancel().
  void cancel() noexcept;
  /// Accepts actions again after cancel().
  void reset_cancel() noexcept;
  /// True between cancel() and reset_cancel().
  bool cancelled() const noexcept { return cancelled_; }

 private:
  Result<StepOutcome> move(const Action& action);
  Result<StepOutcome> gripper(const Action& action);
  Result<StepOutcome> wait(const Action& action);

  const bus::Participant& participant_;
  std::string robot_id_;
  BusRunnerOptions options_;
  std::unique_ptr<bus::Requester<cell_motion_MotionRequest, cell_motion_MotionStatus>> motion_;
  std::unique_ptr<bus::Requester<cell_robot_RobotCommand, cell_robot_RobotCommandReply>> robot_;
  bus::GuardCondition wake_;
  std::atomic<bool> cancelled_{false};
  std::atomic<bool> stop_sent_{false};
  std::uint64_t counter_ = 0;
};

}  // namespace cell::teach
