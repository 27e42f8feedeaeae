#include "cell/service/common_config.hpp"

#include <cstdlib>

#include <fmt/format.h>

namespace cell::service {

Status CommonConfig::validate() const {
  if (service_id.empty()) {
    return Error{Errc::kConfig, "service.id must not be empty"};
  }
  if (domain_id > 230) {
    return Error{Errc::kConfig, fmt::format("service.domain_id must be 0..230, got {}", domain_id)};
  }
  if (partition.empty()) {
    return Error{Errc::kConfig, "service.partition must not be empty"};
  }
  if (!(heartbeat_period_s >= 0.05 && heartbeat_period_s <= 1.0)) {
    return Error{Errc::kConfig,
                 fmt::format("service.heartbeat_period_s must be in [0.05, 1.0] (the liveliness "
                             "lease is 3 s), got {}",
                             heartbeat_period_s)};
  }
  if (!(stall_timeout_s > heartbeat_period_s)) {
    return Error{Errc::kConfig,
                 fmt::format("service.stall_timeout_s must exceed heartbeat_period_s, got {}",
                             stall_timeout_s)};
  }
  return ok_status();
}

void read_common(config::MapReader& root, CommonConfig& out) {
  config::MapReader section = root.child("service", false);
  section.optional("id", out.service_id);
  section.optional("domain_id", out.domain_id);
  section.optional("partition", out.partition);
  section.optional("heartbeat_period_s", out.heartbeat_period_s);
  section.optional("stall_timeout_s", out.stall_timeout_s);
  std::string level;
  section.optional("log_level", level);
  if (!level.empty() && !log::parse_level(level, out.log_level)) {
    section.fail("log_level", "expected debug, info, warn or error, got '" + level + "'");
  }
  root.absorb(section);
}

Status apply_environment(CommonConfig& config) {
  if (const char* id = std::getenv("CELL_SERVICE_ID"); id != nullptr && *id != '\0') {
    config.service_id = id;
  }
  if (const char* domain = std::getenv("CELL_DOMAIN_ID"); domain != nullptr && *domain != '\0') {
    char* end = nullptr;
    const unsigned long value = std::strtoul(domain, &end, 10);
    if (*end != '\0' || value > 230) {
      return Error{Errc::kConfig,
                   fmt::format("environment CELL_DOMAIN_ID must be 0..230, got '{}'", domain)};
    }
    config.domain_id = static_cast<std::uint32_t>(value);
  }
  if (const char* partition = std::getenv("CELL_PARTITION");
      partition != nullptr && *partition != '\0') {
    config.partition = partition;
  }
  if (const char* level = std::getenv("CELL_LOG_LEVEL"); level != nullptr && *level != '\0') {
    if (!log::parse_level(level, config.log_level)) {
      return Error{Errc::kConfig,
                   fmt::format("environment CELL_LOG_LEVEL must be debug, info, warn or error, "
                               "got '{}'",
                               level)};
    }
  }
  return ok_status();
}

}  // namespace cell::service
