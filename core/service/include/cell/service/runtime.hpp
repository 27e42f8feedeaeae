#pragma once

#include <exception>
#include <optional>
#include <string>
#include <string_view>

#include "cell/bus/entity.hpp"
#include "cell/bus/participant.hpp"
#include "cell/bus/waitset.hpp"
#include "cell/common/log.hpp"
#include "cell/config/yaml.hpp"
#include "cell/service/common_config.hpp"
#include "cell/service/events.hpp"
#include "cell/service/health.hpp"
#include "cell/service/shutdown.hpp"

namespace cell::service {

/// Exit codes of every service executable.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;  ///< failed while running
inline constexpr int kExitConfig = 2;   ///< usage or configuration error
inline constexpr int kExitBus = 3;      ///< DDS setup failed (participant, topic, reader)

/// What a service executable is.
struct ServiceInfo {
  std::string_view kind;            ///< "vision": log svc=, default service id, cell-<kind>
  std::string_view summary;         ///< one line for --help
  std::string_view default_config;  ///< "config/vision.yaml", relative to the checkout
};

/// Command-line options common to every service.
struct CommandLine {
  std::string config_path;
  std::optional<std::string> service_id;
  std::optional<std::uint32_t> domain_id;
  std::optional<std::string> partition;
  std::optional<std::string> log_level;
  std::optional<int> exit_code;  ///< set when --help/--version/usage error ended parsing
};

/// Parses `cell-<kind> [--config FILE] [--id ID] [--domain N] [--partition P]
/// [--log-level L] [--help] [--version]`; prints help/version/usage errors itself.
CommandLine parse_command_line(int argc, char** argv, const ServiceInfo& info);

/// Applies the command line's overrides to `config`.
Status apply_command_line(const CommandLine& cli, CommonConfig& config);

/// What a running service gets from the framework. Lives for the whole service run.
class Context {
 public:
  Context(const bus::Participant& participant, const CommonConfig& config,
          const ServiceInfo& info, ShutdownSignal& shutdown);
  ~Context();
  Context(const Context&) = delete;
  Context& operator=(const Context&) = delete;

  const bus::Participant& participant() const noexcept { return participant_; }
  const CommonConfig& common() const noexcept { return config_; }
  HealthReporter& health() noexcept { return health_; }
  EventPublisher& events() noexcept { return events_; }
  /// Triggered when a stop is requested: attach it to the service's WaitSet.
  const bus::GuardCondition& stop_guard() const noexcept { return stop_guard_; }
  bool stopping() const noexcept { return shutdown_.requested(); }
  void request_stop() { shutdown_.request(); }

 private:
  const bus::Participant& participant_;
  CommonConfig config_;
  ShutdownSignal& shutdown_;
  bus::GuardCondition stop_guard_;
  HealthReporter health_;
  EventPublisher events_;
  int stop_callback_ = 0;
};

/// Loads the config file, applies env and command line, validates. Errors name file:line.
template <typename Config>
using ConfigLoader = Result<Config> (*)(const config::Document&);

namespace detail {
int report_exception(const std::exception& e, bool bus_error) noexcept;
/// An exception not derived from std::exception: logged as such; returns kExitFailure.
int report_unknown_exception() noexcept;
template <typename Config, typename Service>
int run_service(int argc, char** argv, const ServiceInfo& info, ConfigLoader<Config> load);
/// Logs a (possibly multi-line) config error, one line per problem; returns kExitConfig.
int report_config_error(const Error& error);
Result<config::Document> load_document(const CommandLine& cli);
}  // namespace detail

/// The fixed sequence of every service (STYLE.md §7): signals -> command line -> config ->
/// participant -> service (its readers/writers) -> service.run(ctx) until stop -> RAII
/// teardown. `Config` has a member `CommonConfig common`; `Service` is constructible from
/// (Context&, const Config&) and has `void run(Context&)`. Returns the exit code.
/// Nothing escapes it: an exception anywhere (the command line, a config loader that threw
/// instead of returning an Error, the service) is logged and gives a non-zero exit code.
template <typename Config, typename Service>
int run(int argc, char** argv, const ServiceInfo& info, ConfigLoader<Config> load) noexcept {
  try {
    return detail::run_service<Config, Service>(argc, argv, info, load);
  } catch (const bus::BusError& e) {
    return detail::report_exception(e, true);
  } catch (const std::exception& e) {
    return detail::report_exception(e, false);
  } catch (...) {
    return detail::report_unknown_exception();
  }
}

namespace detail {
template <typename Config, typename Service>
int run_service(int argc, char** argv, const ServiceInfo& info, ConfigLoader<Config> load) {
  ShutdownSignal shutdown;  // FIRST: blocks the signals before any thread exists
  const CommandLine cli = parse_command_line(argc, argv, info);
  if (cli.exit_code) {
    return *cli.exit_code;
  }
  log::init(info.kind);
  auto doc = detail::load_document(cli);
  if (!doc) {
    return detail::report_config_error(doc.error());
  }
  auto config = load(*doc);
  if (!config) {
    return detail::report_config_error(config.error());
  }
  CommonConfig& common = config->common;
  if (common.service_id.empty()) {
    common.service_id = std::string(info.kind);
  }
  if (auto s = apply_environment(common); !s) {
    return detail::report_config_error(s.error());
  }
  if (auto s = apply_command_line(cli, common); !s) {
    return detail::report_config_error(s.error());
  }
  if (auto s = common.validate(); !s) {
    return detail::report_config_error(with_context(s.error(), doc->path));
  }
  log::init(info.kind, common.log_level);
  bus::Participant participant(common.domain_id, common.partition);
  Context ctx(participant, common, info, shutdown);
  Service service(ctx, *config);
  log::info("start", "serving", {{"id", common.service_id}, {"config", doc->path}});
  service.run(ctx);
  ctx.health().set(cell_health_HEALTH_STOPPING);
  log::info("stop", "stopped cleanly", {{"id", common.service_id}});
  return kExitOk;
}
}  // namespace detail

}  // namespace cell::service
