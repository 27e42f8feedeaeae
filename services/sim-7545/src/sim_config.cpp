#include "sim_config.hpp"

#include <cmath>

#include <fmt/format.h>

#include "cell/dpr7545/transport.hpp"
#include "cell/service/paths.hpp"

namespace cell::sim7545 {

std::array<JointPlant, dpr7545::kJoints> SimConfig::default_plants() {
  // joint_model.hpp: one acceleration gain for all; the viscous term of each joint is chosen
  // so that its top speed needs about 1000 DAC units (half the DAC range) of torque.
  std::array<JointPlant, dpr7545::kJoints> p{};
  p[0].viscous_per_s = 100.0;  // J1: 39,250 counts/s at 45 deg/s
  p[1].viscous_per_s = 180.0;  // J2: 22,222 counts/s at 50 deg/s
  p[2].viscous_per_s = 100.0;  // Z: 38,096 counts/s at 100 mm/s
  p[3].viscous_per_s = 250.0;  // R: 15,929 counts/s at 70 deg/s
  return p;
}

Result<SimConfig> load_config(const config::Document& doc) {
  SimConfig c;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, c.common);
  root.required("robot_config", c.robot_config);
  root.optional("shm_name", c.shm_name);
  root.optional("state_robot_id", c.state_robot_id);
  root.optional("state_rate_hz", c.state_rate_hz);
  root.optional("realtime_priority", c.realtime_priority);
  root.optional("idle_poll_us", c.idle_poll_us);
  root.optional("delay_s", c.delay_s);
  root.optional("deadline_slack_us", c.deadline_slack_us);
  root.optional("initial_joints", c.initial_joints);
  const auto joints = root.sequence("joints", false);
  if (!joints.empty() && joints.size() != dpr7545::kJoints) {
    root.fail("joints", fmt::format("needs {} entries (J1, J2, Z, R), got {}", dpr7545::kJoints,
                                    joints.size()));
  }
  for (std::size_t j = 0; j < joints.size() && j < dpr7545::kJoints; ++j) {
    config::MapReader r = root.element(joints[j], fmt::format("joints[{}]", j));
    JointPlant& p = c.plants[j];
    r.optional("accel_per_dac_counts_s2", p.accel_per_dac_counts_s2);
    r.optional("viscous_per_s", p.viscous_per_s);
    r.optional("coulomb_dac", p.coulomb_dac);
    r.optional("home_edge_counts", p.home_edge_counts);
    r.optional("index_spacing_counts", p.index_spacing_counts);
    if (!(p.accel_per_dac_counts_s2 > 0)) {
      r.fail("accel_per_dac_counts_s2",
             fmt::format("must be > 0, got {}", p.accel_per_dac_counts_s2));
    }
    if (!(p.viscous_per_s >= 0) || !(p.coulomb_dac >= 0)) {
      r.fail("viscous_per_s", "viscous_per_s and coulomb_dac must be >= 0");
    }
    if (!(p.index_spacing_counts >= 10)) {
      r.fail("index_spacing_counts", fmt::format("must be >= 10, got {}", p.index_spacing_counts));
    }
    if (!(p.home_edge_counts > 0 && p.home_edge_counts < p.index_spacing_counts)) {
      r.fail("home_edge_counts",
             fmt::format("must be in (0, index_spacing_counts = {}) so that the first index "
                         "below the home sensor's edge is home, got {}",
                         p.index_spacing_counts, p.home_edge_counts));
    }
    root.absorb(r);
  }
  config::MapReader faults = root.child("fault_injection", false);
  faults.optional("enabled", c.fault_injection_enabled);
  faults.optional("deadline_miss_after_s", c.deadline_miss_after_s);
  if (!(c.deadline_miss_after_s >= 0)) {
    faults.fail("deadline_miss_after_s",
                fmt::format("must be >= 0 (0: never), got {}", c.deadline_miss_after_s));
  }
  root.absorb(faults);
  if (auto s = dpr7545::validate_shm_name(c.shm_name); !s) {
    root.fail("shm_name", s.error().message);
  }
  if (c.state_robot_id.empty()) {
    root.fail("state_robot_id", "must not be empty");
  }
  if (!(c.state_rate_hz >= 1 && c.state_rate_hz <= 1000)) {
    root.fail("state_rate_hz", fmt::format("must be in [1, 1000], got {}", c.state_rate_hz));
  }
  if (c.realtime_priority < 0 || c.realtime_priority > 99) {
    root.fail("realtime_priority",
              fmt::format("must be 0 (none) or 1..99, got {}", c.realtime_priority));
  }
  if (!(c.idle_poll_us >= 10 && c.idle_poll_us <= 10000)) {
    root.fail("idle_poll_us", fmt::format("must be in [10, 10000], got {}", c.idle_poll_us));
  }
  if (!(c.delay_s >= 0 && c.delay_s <= 10)) {
    root.fail("delay_s", fmt::format("must be in [0, 10], got {}", c.delay_s));
  }
  if (!(c.deadline_slack_us >= 0 && c.deadline_slack_us <= 100'000)) {
    root.fail("deadline_slack_us",
              fmt::format("must be in [0, 100000] (0: the board's deadlines), got {}",
                          c.deadline_slack_us));
  }
  for (double v : c.initial_joints) {
    if (!std::isfinite(v)) {
      root.fail("initial_joints", "must be finite");
    }
  }
  CELL_TRY(root.finish());
  c.robot_config = service::resolve_path(c.robot_config);
  return c;
}

}  // namespace cell::sim7545
