#include "motion_config.hpp"

#include <numbers>

#include <fmt/format.h>

#include "cell/service/paths.hpp"

namespace cell::motion_service {

namespace {

/// The planner keys of `p` over `base` (the service's planner, or a robot's override of it).
void read_planner(config::MapReader& p, motion::PlannerOptions& out) {
  auto& lin = out.linear;
  p.optional("linear_speed_mm_s", lin.max_speed_mm_s);
  p.optional("linear_accel_mm_s2", lin.max_accel_mm_s2);
  double angular_speed_deg = lin.max_angular_speed_rad_s * 180 / std::numbers::pi;
  double angular_accel_deg = lin.max_angular_accel_rad_s2 * 180 / std::numbers::pi;
  p.optional("angular_speed_deg_s", angular_speed_deg);
  p.optional("angular_accel_deg_s2", angular_accel_deg);
  lin.max_angular_speed_rad_s = angular_speed_deg * std::numbers::pi / 180;
  lin.max_angular_accel_rad_s2 = angular_accel_deg * std::numbers::pi / 180;
  p.optional("knot_period_s", lin.knot_period_s);
  p.optional("gripper_dwell_s", out.gripper_dwell_s);
  p.optional("approach_mm", out.default_approach_mm);
  p.optional("via_settle_s", out.via_settle_s);
  double start_bounds_deg = out.start_bounds_tolerance_rad * 180 / std::numbers::pi;
  p.optional("start_bounds_tolerance_deg", start_bounds_deg);
  out.start_bounds_tolerance_rad = start_bounds_deg * std::numbers::pi / 180;
  p.optional("start_bounds_tolerance_mm", out.start_bounds_tolerance_mm);
  if (!(start_bounds_deg >= 0)) {
    p.fail("start_bounds_tolerance_deg", fmt::format("must be >= 0, got {}", start_bounds_deg));
  }
  if (!(out.start_bounds_tolerance_mm >= 0)) {
    p.fail("start_bounds_tolerance_mm",
           fmt::format("must be >= 0, got {}", out.start_bounds_tolerance_mm));
  }
  auto positive = [&](const char* key, double v) {
    if (!(v > 0)) {
      p.fail(key, fmt::format("must be > 0, got {}", v));
    }
  };
  positive("linear_speed_mm_s", lin.max_speed_mm_s);
  positive("linear_accel_mm_s2", lin.max_accel_mm_s2);
  positive("angular_speed_deg_s", angular_speed_deg);
  positive("angular_accel_deg_s2", angular_accel_deg);
  positive("knot_period_s", lin.knot_period_s);
  positive("approach_mm", out.default_approach_mm);
  if (out.gripper_dwell_s < 0) {
    p.fail("gripper_dwell_s", "must be >= 0");
  }
  if (out.via_settle_s < 0) {
    p.fail("via_settle_s", "must be >= 0");
  }
}

}  // namespace

Result<MotionConfig> load_config(const config::Document& doc) {
  MotionConfig c;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, c.common);
  config::MapReader p = root.child("planner", false);
  read_planner(p, c.planner);
  root.absorb(p);
  const auto robots = root.sequence("robots");
  for (std::size_t i = 0; i < robots.size(); ++i) {
    config::MapReader r = root.element(robots[i], fmt::format("robots[{}]", i));
    RobotEntry entry;
    r.required("id", entry.id);
    r.required("config", entry.config);
    entry.config = service::resolve_path(entry.config);
    entry.planner = c.planner;
    if (r.has("planner")) {
      config::MapReader own = r.child("planner");
      read_planner(own, entry.planner);
      r.absorb(own);
    }
    for (const auto& other : c.robots) {
      if (other.id == entry.id) {
        r.fail("id", fmt::format("robot '{}' is listed twice", entry.id));
      }
    }
    c.robots.push_back(entry);
    root.absorb(r);
  }
  if (robots.empty()) {
    root.fail("robots", "at least one robot is needed");
  }
  root.optional("gateway_timeout_s", c.gateway_timeout_s);
  root.optional("state_timeout_s", c.state_timeout_s);
  root.optional("status_rate_hz", c.status_rate_hz);
  root.optional("keep_finished", c.keep_finished);
  root.optional("track_start_latency_s", c.track_start_latency_s);
  root.optional("max_target_age_s", c.max_target_age_s);
  if (!(c.track_start_latency_s >= 0 && c.track_start_latency_s <= 1.0)) {
    root.fail("track_start_latency_s",
              fmt::format("must be in [0, 1] s, got {}", c.track_start_latency_s));
  }
  for (const auto& [key, v] : {std::pair{"gateway_timeout_s", c.gateway_timeout_s},
                               std::pair{"state_timeout_s", c.state_timeout_s},
                               std::pair{"status_rate_hz", c.status_rate_hz},
                               std::pair{"max_target_age_s", c.max_target_age_s}}) {
    if (!(v > 0)) {
      root.fail(key, fmt::format("must be > 0, got {}", v));
    }
  }
  if (c.keep_finished < 1) {
    root.fail("keep_finished", "must be >= 1");
  }
  CELL_TRY(root.finish());
  return c;
}

}  // namespace cell::motion_service
