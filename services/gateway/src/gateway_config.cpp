#include "gateway_config.hpp"

#include <numbers>

#include <fmt/format.h>

#include "cell/service/paths.hpp"

namespace cell::gateway {

Result<GatewayConfig> load_config(const config::Document& doc) {
  GatewayConfig c;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, c.common);
  root.required("robot_config", c.robot_config);
  root.optional("cycle_hz", c.cycle_hz);
  root.optional("state_rate_hz", c.state_rate_hz);
  root.optional("realtime_priority", c.realtime_priority);
  root.optional_deg("start_tolerance_deg", c.start_tolerance_rad);
  root.optional("start_tolerance_mm", c.start_tolerance_mm);
  root.optional("supervisors", c.supervisors);
  for (std::size_t i = 0; i < c.supervisors.size(); ++i) {
    if (c.supervisors[i].empty()) {
      root.fail("supervisors", fmt::format("entry {} is empty: list service ids, e.g. [task]", i));
    }
  }
  config::MapReader driver = root.child("driver");
  driver.required("kind", c.driver_kind);
  if (const DriverParser parse = find_driver(c.driver_kind); parse != nullptr) {
    c.make_driver = parse(driver);
  } else if (!c.driver_kind.empty()) {
    std::string known;
    for (const auto& d : driver_kinds()) {
      known += fmt::format("{}{}", known.empty() ? "" : ", ", d.name);
    }
    driver.fail("kind", fmt::format("unknown driver '{}' (known: {})", c.driver_kind, known));
  }
  root.absorb(driver);
  if (!(c.cycle_hz >= 10 && c.cycle_hz <= 4000)) {
    root.fail("cycle_hz", fmt::format("must be in [10, 4000], got {}", c.cycle_hz));
  }
  if (!(c.state_rate_hz >= 1 && c.state_rate_hz <= c.cycle_hz)) {
    root.fail("state_rate_hz",
              fmt::format("must be in [1, cycle_hz = {}], got {}", c.cycle_hz, c.state_rate_hz));
  }
  if (c.realtime_priority < 0 || c.realtime_priority > 99) {
    root.fail("realtime_priority",
              fmt::format("must be 0 (none) or a SCHED_FIFO priority 1..99, got {}",
                          c.realtime_priority));
  }
  if (!(c.start_tolerance_rad > 0) || !(c.start_tolerance_mm > 0)) {
    root.fail("start_tolerance_deg", "start tolerances must be > 0");
  }
  CELL_TRY(root.finish());
  c.robot_config = service::resolve_path(c.robot_config);
  return c;
}

}  // namespace cell::gateway
