#include "echo_service.hpp"

#include <chrono>
#include <cstdlib>
#include <thread>

#include <fmt/format.h>

namespace cell::echo {

Result<EchoConfig> load_config(const config::Document& doc) {
  EchoConfig config;
  config::MapReader root(doc, doc.root, "");
  service::read_common(root, config.common);
  root.optional("crash_after_s", config.crash_after_s);
  root.optional("stall_after_s", config.stall_after_s);
  if (config.crash_after_s < 0) {
    root.fail("crash_after_s", fmt::format("must be >= 0, got {}", config.crash_after_s));
  }
  if (config.stall_after_s < 0) {
    root.fail("stall_after_s", fmt::format("must be >= 0, got {}", config.stall_after_s));
  }
  CELL_TRY(root.finish());
  return config;
}

EchoService::EchoService(service::Context& /*ctx*/, const EchoConfig& config) : config_(config) {}

void EchoService::run(service::Context& ctx) const {
  constexpr dds_attach_t kStop = 1;
  bus::WaitSet waitset(ctx.participant());
  waitset.attach(ctx.stop_guard().get(), kStop);
  ctx.health().set(cell_health_HEALTH_SERVING);
  const auto started = std::chrono::steady_clock::now();
  const auto period = std::chrono::milliseconds(200);
  for (;;) {
    const bus::Fired fired = waitset.wait(period);
    if (fired.contains(kStop)) {
      break;
    }
    const double age_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
    if (config_.crash_after_s > 0 && age_s >= config_.crash_after_s) {
      log::error("fault_injection", "crashing on purpose (crash_after_s)");
      std::abort();
    }
    if (config_.stall_after_s > 0 && age_s >= config_.stall_after_s) {
      continue;  // alive but not ticking: the heartbeat must say degraded
    }
    ctx.health().tick();
  }
}

}  // namespace cell::echo
