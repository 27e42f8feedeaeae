#include "session.hpp"

#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdlib>
#include <exception>

#include <fmt/format.h>
#include <CLI/CLI.hpp>

#include "cell/bus/entity.hpp"
#include "cell/common/version.hpp"
#include "cell/service/paths.hpp"
#include "commands.hpp"

namespace cell::cellctl {
namespace {

constexpr std::uint32_t kMaxDomainId = 230;

/// Every command group, in --help order.
constexpr Registrar kCommandGroups[] = {
    &add_ping_commands,
    &add_kin_commands,
    &add_move_commands,
    &add_robot_commands,
    &add_world_commands,
    &add_camera_commands,
    &add_locate_commands,
    &add_calibrate_commands,
    &add_rapt_commands,
    &add_job_commands,
    &add_task_commands,
    &add_completion_commands,
};

}  // namespace

Session::Session(const GlobalOptions& options, std::ostream& out, std::ostream& err)
    : options_(options), out_(out), err_(err) {}

Status Session::resolve() {
  if (options_.domain_id) {
    domain_id_ = *options_.domain_id;
    if (domain_id_ > kMaxDomainId) {
      return Error{Errc::kConfig,
                   fmt::format("--domain must be 0..{}, got {}", kMaxDomainId, domain_id_)};
    }
  } else if (const char* env = std::getenv("CELL_DOMAIN_ID"); env != nullptr && *env != '\0') {
    char* end = nullptr;
    const unsigned long value = std::strtoul(env, &end, 10);
    if (*end != '\0' || value > kMaxDomainId) {
      return Error{Errc::kConfig, fmt::format("environment CELL_DOMAIN_ID must be 0..{}, got '{}'",
                                              kMaxDomainId, env)};
    }
    domain_id_ = static_cast<std::uint32_t>(value);
  }
  if (options_.partition) {
    partition_ = *options_.partition;
    if (partition_.empty()) {
      return Error{Errc::kConfig, "--partition must not be empty"};
    }
  } else if (const char* env = std::getenv("CELL_PARTITION"); env != nullptr && *env != '\0') {
    partition_ = env;
  }
  if (!(options_.timeout_s > 0.0 && options_.timeout_s <= 3600.0)) {
    return Error{Errc::kConfig,
                 fmt::format("--timeout must be in (0, 3600] s, got {}", options_.timeout_s)};
  }
  if (const char* uri = std::getenv("CYCLONEDDS_URI"); uri == nullptr || *uri == '\0') {
    const std::string loopback = service::cell_home() + "/config/dds/loopback.xml";
    if (access(loopback.c_str(), R_OK) == 0) {
      setenv("CYCLONEDDS_URI", ("file://" + loopback).c_str(), 1);
    }
  }
  return ok_status();
}

std::chrono::milliseconds Session::timeout() const noexcept {
  return std::chrono::milliseconds(std::lround(options_.timeout_s * 1000.0));
}

std::string Session::describe_bus() const {
  return fmt::format("domain {}, partition '{}'", domain_id_, partition_);
}

const bus::Participant& Session::participant() {
  if (!participant_) {
    participant_ = std::make_unique<bus::Participant>(domain_id_, partition_);
  }
  return *participant_;
}

int Session::fail(std::string_view message, int code) {
  err_ << "cellctl: " << message << "\n";
  return code;
}

void Commands::add(const CLI::App* subcommand, Action action) {
  actions_.emplace_back(subcommand, std::move(action));
}

const Action* Commands::chosen(const CLI::App& app) const {
  for (const CLI::App* sub : app.get_subcommands()) {  // the parsed ones
    if (const Action* deeper = chosen(*sub)) {
      return deeper;
    }
    for (const auto& [owner, action] : actions_) {
      if (owner == sub) {
        return &action;
      }
    }
  }
  return nullptr;
}

int run(int argc, const char* const* argv, std::ostream& out, std::ostream& err) {
  try {
    GlobalOptions options;
    Commands commands;
    CLI::App app("cellctl: operate a cell from the command line", "cellctl");
    app.set_version_flag("--version",
                         fmt::format("cellctl {} (Cyclone DDS {})", version(), dds_version()));
    app.add_flag("--json", options.json, "machine-readable JSON on stdout");
    // Given twice (a script's defaults, then the user's), the last one wins.
    const auto last = CLI::MultiOptionPolicy::TakeLast;
    app.add_option("--domain", options.domain_id, "DDS domain (default $CELL_DOMAIN_ID or 0)")
        ->multi_option_policy(last);
    app.add_option("--partition", options.partition,
                   "DDS partition (default $CELL_PARTITION or 'cell')")
        ->multi_option_policy(last);
    app.add_option("--timeout", options.timeout_s, "seconds to wait for the bus, default 2")
        ->multi_option_policy(last);
    // Global options are accepted after the subcommand too (`cellctl ping --json`):
    // subcommands made after this inherit it.
    app.fallthrough();
    app.footer(
        "Environment: CELL_DOMAIN_ID, CELL_PARTITION select the cell; CYCLONEDDS_URI the DDS\n"
        "configuration (default: $CELL_HOME/config/dds/loopback.xml, the single-machine cell).\n"
        "Exit codes: 0 ok, 1 failure, 2 usage error.");
    for (const Registrar add : kCommandGroups) {
      add(app, commands);
    }
    try {
      app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
      const int rc = app.exit(e, out, err);
      return rc == 0 ? kExitOk : kExitUsage;
    }
    const Action* action = commands.chosen(app);
    if (action == nullptr) {
      err << app.help() << "cellctl: choose a command (ping, ...)\n";
      return kExitUsage;
    }
    Session session(options, out, err);
    if (auto s = session.resolve(); !s) {
      return session.fail(s.error().message, kExitUsage);
    }
    return (*action)(session);
  } catch (const bus::BusError& e) {
    err << "cellctl: cannot join the bus: " << e.what()
        << " (check CYCLONEDDS_URI and the domain id)\n";
    return kExitFailure;
  } catch (const std::exception& e) {
    err << "cellctl: " << e.what() << "\n";
    return kExitFailure;
  }
}

}  // namespace cell::cellctl
