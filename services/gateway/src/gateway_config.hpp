#pragma once

#include <string>
#include <vector>

#include "cell/config/yaml.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "cell/service/common_config.hpp"
#include "drivers.hpp"

namespace cell::gateway {

/// config/gateway-<robot>.yaml.
///
///   service: {id: gateway.ibm7545}
///   robot_config: config/robots/ibm7545.yaml   # the robot this gateway drives
///   cycle_hz: 1000            # servo cycle (the 7545's DPR sample period is 1 ms)
///   state_rate_hz: 100        # RobotState stream rate, 1..cycle_hz
///   realtime_priority: 0      # SCHED_FIFO priority of the servo thread; 0: normal scheduling
///   start_tolerance_deg: 0.5  # a trajectory must start this close to the current setpoint
///   start_tolerance_mm: 0.5
///   supervisors: [task]       # service ids; when every one has lost its heartbeat, the
///                             # gateway stops the robot, moving or not (empty: none)
///   driver:
///     kind: ideal             # one of drivers.cpp's table; the other keys are the driver's
///     ...                     # own (see each driver's header and the gateway README)
struct GatewayConfig {
  service::CommonConfig common;
  std::string robot_config;
  double cycle_hz = 1000.0;
  double state_rate_hz = 100.0;
  int realtime_priority = 0;
  double start_tolerance_rad = 0.5 * 3.141592653589793 / 180.0;
  double start_tolerance_mm = 0.5;
  /// Service ids whose heartbeats the gateway watches (service::ServiceDirectory): when all
  /// of them are lost (3 s liveliness lease), the robot is stopped as by a STOP command, moving
  /// or not (unless already in FAULT or STOPPED), stop_code "supervisor_lost". Empty (the
  /// default): none.
  std::vector<std::string> supervisors;
  std::string driver_kind;
  DriverFactory make_driver;  ///< from the driver's parser; builds it once the robot is known
};

/// Parses a gateway config (robot_config is resolved against CELL_HOME when relative).
Result<GatewayConfig> load_config(const config::Document& doc);

}  // namespace cell::gateway
