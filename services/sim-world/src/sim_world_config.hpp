#pragma once

#include <string>

#include "cell/config/yaml.hpp"
#include "cell/service/common_config.hpp"
#include "cell/world/world.hpp"

namespace cell::sim_world {

/// config/sim-world.yaml (services/sim-world/README.md has every key):
///
///   service: {id: sim-world}
///   scene: config/scenes/table_ics.yaml     # the world at start and on an empty reset
///   step_hz: 1000                            # internal world step
///   world_state_hz: 100                      # cell/world/state rate
///   belt_state_hz: 500                       # cell/world/belt rate
///   robots:                                  # where each robot's base stands in the world
///     - {id: ibm7545, xyz_mm: [0, 0, 981.51], rpy_deg: [0, 0, 0]}
///   physics:
///     capture_tolerance_mm: 2.0
///     capture_yaw_tolerance_deg: 10
///     capture_tilt_tolerance_deg: 10
struct SimWorldConfig {
  service::CommonConfig common;
  std::string scene;  ///< resolved path of the scene file
  double step_hz = 1000.0;
  double world_state_hz = 100.0;
  double belt_state_hz = 500.0;
  world::WorldOptions world;  ///< robots' mounts and capture tolerances

  /// Ok, or kConfig naming the key and the rule (rates: step_hz in [10, 10000], the others in
  /// (0, step_hz]).
  Status validate() const;
};

/// Parses and validates a sim-world config document, and loads its scene once so that a bad
/// scene stops the service at start with the scene's file:line:col (exit code 2).
/// Errors: kConfig, every problem at once, one per line.
Result<SimWorldConfig> load_config(const config::Document& doc);

}  // namespace cell::sim_world
