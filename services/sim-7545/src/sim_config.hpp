#pragma once

#include <array>
#include <string>

#include "cell/config/yaml.hpp"
#include "cell/dpr7545/registers.hpp"
#include "cell/service/common_config.hpp"

namespace cell::sim7545 {

/// The plant of one joint, in encoder counts and DAC units (joint_model.hpp explains the
/// choice of the defaults).
struct JointPlant {
  /// Acceleration per DAC unit of torque word above 0x800 [counts/s^2 per DAC unit]: the
  /// amplifier-motor-gear gain over the joint's inertia.
  double accel_per_dac_counts_s2 = 4000.0;
  /// Viscous friction / back-EMF damping [1/s]: deceleration per unit of velocity.
  double viscous_per_s = 100.0;
  /// Coulomb (and static) friction expressed in DAC units of torque.
  double coulomb_dac = 30.0;
  /// The home sensor is active while the joint is below this position [counts from the index
  /// that defines home].
  double home_edge_counts = 1000.0;
  /// Encoder index pulses every this many counts (one per motor turn); one lies at home.
  double index_spacing_counts = 2000.0;
};

/// config/sim-7545.yaml.
///
///   service: {id: sim.ibm7545}
///   robot_config: config/robots/ibm7545.yaml  # scales, overrun limits, FK for the truth
///   shm_name: /cell-dpr7545                  # the DPR segment this simulator creates
///   state_robot_id: ibm7545.sim               # robot_id of the published true state
///   state_rate_hz: 100                        # true-state publication rate
///   realtime_priority: 0                      # SCHED_FIFO priority of the slave thread
///   idle_poll_us: 100                         # idle loop pass period (command latency)
///   delay_s: 0.25                             # the slave's `delay` routine
///   deadline_slack_us: 0                      # grace past each handshake deadline (below)
///   initial_joints: [45, 105, 0, 0]           # physical pose at power-up [deg, deg, mm, deg]
///   joints: [{...JointPlant...} x 4]          # optional, per joint in J1, J2, Z, R order
///   fault_injection: {enabled: true, deadline_miss_after_s: 0}
struct SimConfig {
  service::CommonConfig common;
  std::string robot_config;
  std::string shm_name = "/cell-dpr7545";
  std::string state_robot_id = "ibm7545.sim";
  double state_rate_hz = 100.0;
  int realtime_priority = 0;
  double idle_poll_us = 100.0;
  double delay_s = 0.25;
  /// Extra time the simulated board grants the master past each of a period's two deadlines
  /// (torques by the end of the period, 0x1000; the loop's end, 0x2000) [us]. 0 is the board
  /// of Appendix C. A host without a real-time kernel, a virtual machine above all, stalls even
  /// a SCHED_FIFO thread now and then for several sample periods (bench/servo's "wakes > 1 ms
  /// late"); with 0 each such stall of the gateway is a fault, as it would be on the board.
  /// The slave still runs on its period's grid: a late master costs the periods it missed.
  double deadline_slack_us = 0.0;
  std::array<double, dpr7545::kJoints> initial_joints{};  ///< display units (deg, deg, mm, deg)
  std::array<JointPlant, dpr7545::kJoints> plants = default_plants();
  bool fault_injection_enabled = true;
  double deadline_miss_after_s = 0.0;

  /// The defaults of joint_model.hpp: J1, J2, Z, R.
  static std::array<JointPlant, dpr7545::kJoints> default_plants();
};

/// Parses and validates a simulator config; robot_config is resolved against CELL_HOME.
/// Errors: kConfig with file:line:col, the key, the value and the rule.
Result<SimConfig> load_config(const config::Document& doc);

}  // namespace cell::sim7545
