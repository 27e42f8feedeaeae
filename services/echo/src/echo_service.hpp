#pragma once

#include "cell/service/runtime.hpp"

namespace cell::echo {

/// config/echo.yaml: only the common `service:` section, plus an optional fault injection
/// used by the launcher tests.
struct EchoConfig {
  service::CommonConfig common;
  double crash_after_s = 0.0;  ///< > 0: abort after this long (tests of restart with back-off)
  double stall_after_s = 0.0;  ///< > 0: stop ticking after this long (tests of stall detection)
};

/// Parses and validates an echo config document.
Result<EchoConfig> load_config(const config::Document& doc);

/// The minimal service: heartbeats and pings (from the framework) and nothing else. It proves
/// the launcher, the health machinery and cellctl before the real services exist.
class EchoService {
 public:
  EchoService(service::Context& ctx, const EchoConfig& config);
  void run(service::Context& ctx) const;

 private:
  EchoConfig config_;
};

}  // namespace cell::echo
