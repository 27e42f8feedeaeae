#include "cell/service/runtime.hpp"

#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <iostream>

#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include "cell/common/version.hpp"
#include "cell/service/paths.hpp"

#ifndef CELL_SOURCE_DIR
#define CELL_SOURCE_DIR "."
#endif

namespace cell::service {

std::string cell_home() {
  if (const char* home = std::getenv("CELL_HOME"); home != nullptr && *home != '\0') {
    return home;
  }
  return CELL_SOURCE_DIR;
}

std::string resolve_path(const std::string& path) {
  namespace fs = std::filesystem;
  if (path.empty() || fs::path(path).is_absolute() || fs::exists(path)) {
    return path;
  }
  const fs::path candidate = fs::path(cell_home()) / path;
  return fs::exists(candidate) ? candidate.string() : path;
}

CommandLine parse_command_line(int argc, char** argv, const ServiceInfo& info) {
  CommandLine cli;
  cli.config_path = std::string(info.default_config);
  CLI::App app(std::string(info.summary), fmt::format("cell-{}", info.kind));
  app.set_version_flag("--version", fmt::format("cell-{} {} (Cyclone DDS {})", info.kind,
                                                version(), dds_version()));
  app.add_option("-c,--config", cli.config_path, "YAML configuration file")
      ->capture_default_str();
  app.add_option("--id", cli.service_id, "service id on the bus (overrides service.id)");
  app.add_option("--domain", cli.domain_id, "DDS domain (overrides service.domain_id)");
  app.add_option("--partition", cli.partition, "DDS partition (overrides service.partition)");
  app.add_option("--log-level", cli.log_level, "debug, info, warn or error");
  app.footer(
      "Environment: CELL_SERVICE_ID, CELL_DOMAIN_ID, CELL_PARTITION, CELL_LOG_LEVEL override "
      "the file;\nCYCLONEDDS_URI selects the DDS configuration; CELL_HOME the root for "
      "relative paths.\nExit codes: 0 stopped cleanly, 1 failure, 2 usage or config error, "
      "3 DDS setup error.");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = app.exit(e);
    cli.exit_code = rc == 0 ? kExitOk : kExitConfig;
  }
  return cli;
}

Status apply_command_line(const CommandLine& cli, CommonConfig& config) {
  if (cli.service_id) {
    config.service_id = *cli.service_id;
  }
  if (cli.domain_id) {
    config.domain_id = *cli.domain_id;
  }
  if (cli.partition) {
    config.partition = *cli.partition;
  }
  if (cli.log_level && !log::parse_level(*cli.log_level, config.log_level)) {
    return Error{Errc::kConfig, fmt::format("--log-level must be debug, info, warn or error, "
                                            "got '{}'",
                                            *cli.log_level)};
  }
  return ok_status();
}

Context::Context(const bus::Participant& participant, const CommonConfig& config,
                 const ServiceInfo& info, ShutdownSignal& shutdown)
    : participant_(participant),
      config_(config),
      shutdown_(shutdown),
      stop_guard_(participant),
      health_(participant, config, std::string(info.kind)),
      events_(participant, config.service_id) {
  stop_callback_ = shutdown_.on_stop([this] { stop_guard_.trigger(); });
}

Context::~Context() { shutdown_.remove(stop_callback_); }

namespace detail {

int report_exception(const std::exception& e, bool bus_error) noexcept {
  try {
    if (bus_error) {
      log::error("bus", e.what(),
                 {{"hint", "check CYCLONEDDS_URI and the domain id; is the network interface up?"}});
    } else {
      log::error("fatal", e.what());
    }
  } catch (...) {  // the log itself failed (out of memory): the exit code still says it
    (void)std::fputs(e.what(), stderr);
  }
  return bus_error ? kExitBus : kExitFailure;
}

int report_unknown_exception() noexcept {
  try {
    log::error("fatal", "an exception not derived from std::exception");
  } catch (...) {
    (void)std::fputs("fatal: an exception not derived from std::exception\n", stderr);
  }
  return kExitFailure;
}

int report_config_error(const Error& error) {
  std::string_view rest = error.message;
  while (!rest.empty()) {
    const auto nl = rest.find('\n');
    log::error("config", rest.substr(0, nl));
    if (nl == std::string_view::npos) {
      break;
    }
    rest.remove_prefix(nl + 1);
  }
  return kExitConfig;
}

Result<config::Document> load_document(const CommandLine& cli) {
  return config::load_file(resolve_path(cli.config_path));
}

}  // namespace detail
}  // namespace cell::service
