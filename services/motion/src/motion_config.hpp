#pragma once

#include <string>
#include <vector>

#include "cell/config/yaml.hpp"
#include "cell/motion/planner.hpp"
#include "cell/service/common_config.hpp"

namespace cell::motion_service {

/// config/motion.yaml.
///
///   service: {id: motion}
///   robots:                                  # robots this service plans for
///     - {id: ibm7545, config: config/robots/ibm7545.yaml}
///     - {id: scara_picker, config: ..., planner: {linear_speed_mm_s: 2000}}  # own keys
///   planner:                                 # every robot's, unless it overrides a key
///     linear_speed_mm_s: 250                 # straight-line tool speed
///     linear_accel_mm_s2: 1000
///     angular_speed_deg_s: 90
///     angular_accel_deg_s2: 360
///     knot_period_s: 0.008
///     gripper_dwell_s: 0.5                   # thesis: 0.5 s after open/close
///     approach_mm: 30                        # default approach/depart distance
///     via_settle_s: 0.2                      # thesis: +0.2 s per via segment
///   gateway_timeout_s: 2.0                   # a gateway must accept a trajectory this fast
///   state_timeout_s: 1.0                     # robot state older than this: robot offline
///   status_rate_hz: 10                       # RUNNING progress updates
///   keep_finished: 200                       # finished motions kept on the status topic
///   track_start_latency_s: 0.01              # a track's request to the robot moving
///   max_target_age_s: 2.0                    # a moving target's stamp at most this old
struct RobotEntry {
  std::string id;
  std::string config;  ///< resolved path
  motion::PlannerOptions planner;  ///< the service's planner with this robot's overrides
};

struct MotionConfig {
  service::CommonConfig common;
  std::vector<RobotEntry> robots;
  motion::PlannerOptions planner;
  double gateway_timeout_s = 2.0;
  double state_timeout_s = 1.0;
  double status_rate_hz = 10.0;
  int keep_finished = 200;
  /// From a track's request to the robot moving (planning, the trajectory to the gateway,
  /// its next cycle): a moving target is met as if the robot started this long after now.
  double track_start_latency_s = 0.01;
  /// A moving target's stamp this far from the clock is refused (stale, or clocks apart).
  double max_target_age_s = 2.0;
};

Result<MotionConfig> load_config(const config::Document& doc);

}  // namespace cell::motion_service
