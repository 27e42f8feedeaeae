#pragma once

#include <cstdint>
#include <optional>
#include <string>

#include "cell/common/log.hpp"
#include "cell/common/result.hpp"
#include "cell/config/yaml.hpp"

namespace cell::service {

/// The `service:` section every service's YAML carries.
///
///   service:
///     id: vision              # unique instance name on the bus (default: the kind)
///     domain_id: 0            # DDS domain
///     partition: cell         # DDS partition: one per cell sharing a domain
///     heartbeat_period_s: 1.0
///     stall_timeout_s: 3.0    # main loop silent this long -> heartbeat says degraded
///     log_level: info         # debug | info | warn | error
///
/// Precedence: command line (--id, --domain, --partition, --log-level) over environment
/// (CELL_SERVICE_ID, CELL_DOMAIN_ID, CELL_PARTITION, CELL_LOG_LEVEL) over the file.
struct CommonConfig {
  std::string service_id;
  std::uint32_t domain_id = 0;
  std::string partition = "cell";
  double heartbeat_period_s = 1.0;
  double stall_timeout_s = 3.0;
  log::Level log_level = log::Level::kInfo;

  /// Ok, or kConfig naming the key, the value and the rule.
  Status validate() const;
};

/// Reads the optional `service:` section of `root` into `out` (errors collect in `root`).
void read_common(config::MapReader& root, CommonConfig& out);

/// Applies CELL_* environment overrides (see CommonConfig). Errors: kConfig for a malformed
/// value, naming the variable.
Status apply_environment(CommonConfig& config);

}  // namespace cell::service
