#pragma once

#include <atomic>
#include <memory>
#include <thread>

#include "cell/bus/topic.hpp"
#include "cell/bus/writer.hpp"
#include "cell/dpr7545/transport.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/service/runtime.hpp"
#include "sim_config.hpp"
#include "slave.hpp"

namespace cell::sim7545 {

/// The IBM 7545 slave simulator as a service: it creates the DPR shared-memory segment
/// (config shm_name), runs the slave program (slave.hpp) on its own thread (SCHED_FIFO when
/// realtime_priority > 0) and publishes the arm's true state at state_rate_hz.
///
/// Topics: out cell/robot/state (stream) as a RobotState whose robot_id is state_robot_id
/// ("ibm7545.sim"): physical joints (rad, mm) measured from the true home, their velocities,
/// the DAC words as effort_raw, FK of the true joints, the gripper and lighting latches, the
/// error register with its meaning, the slave's mode (IDLE, MOVING = control mode, HOMING),
/// cycle_count = control periods, cycle_jitter_max_us = worst period-start lateness since the
/// last state, cycle_overruns = periods whose master was late past the board's deadline: the
/// deadline errors (0x1000/0x2000) the slave flagged plus those deadline_slack_us covered. setpoint is
/// empty: the slave has none. No input topics: faults are injected through the segment's
/// mailbox (sim_control.hpp; `cell-sim-7545 inject ...`).
class SimService {
 public:
  /// Throws std::runtime_error when the robot config cannot be used or the segment cannot be
  /// created (the message says which and why).
  SimService(service::Context& ctx, const SimConfig& config);
  ~SimService();
  SimService(const SimService&) = delete;
  SimService& operator=(const SimService&) = delete;

  void run(service::Context& ctx);

 private:
  void publish(const SlaveSnapshot& s);

  SimConfig config_;
  kinematics::RobotModel model_;
  std::unique_ptr<dpr7545::Transport> transport_;
  std::unique_ptr<Slave> slave_;
  bus::Topic<cell_robot_RobotState> state_topic_;
  bus::Writer<cell_robot_RobotState> state_writer_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  std::uint64_t seq_ = 0;
};

/// `cell-sim-7545 inject <fault> [--joint J] [--value N] [--shm NAME] [--timeout S]`: posts a
/// fault to a running simulator's mailbox and waits for its acknowledgement. Exit codes: 0
/// injected, 1 refused or not acknowledged (the message says why), 2 usage error.
int run_inject(int argc, char** argv);

}  // namespace cell::sim7545
