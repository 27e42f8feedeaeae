#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <optional>
#include <ostream>
#include <string>
#include <string_view>

#include "cell/bus/participant.hpp"
#include "cell/common/result.hpp"

/// cellctl: the operator's command line. main.cpp only calls run(); each command group lives
/// in its own source file and registers its CLI11 subcommands through a Registrar (see
/// commands.hpp), so later issues add `kin`, `move`, `world`, `job` without touching the rest.
namespace cell::cellctl {

/// Exit codes of cellctl.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;  ///< the command ran and failed (nobody answered, ...)
inline constexpr int kExitUsage = 2;    ///< bad command line or environment

/// Options every command sees (set before the subcommand on the command line).
struct GlobalOptions {
  bool json = false;                       ///< machine-readable output on stdout
  std::optional<std::uint32_t> domain_id;  ///< --domain; else CELL_DOMAIN_ID; else 0
  std::optional<std::string> partition;    ///< --partition; else CELL_PARTITION; else "cell"
  double timeout_s = 2.0;                  ///< --timeout: discovery and reply budget
};

/// What a command runs with: the resolved bus, the output streams, and the participant (made
/// on first use). One per cellctl invocation; single-threaded.
class Session {
 public:
  /// Keeps references to `options`, `out` and `err`: they must outlive the session.
  Session(const GlobalOptions& options, std::ostream& out, std::ostream& err);

  /// Resolves the domain and partition (command line over environment over defaults) and the
  /// Cyclone configuration: when CYCLONEDDS_URI is unset, $CELL_HOME/config/dds/loopback.xml
  /// (the single-machine cell's) is used if it exists. Errors: kConfig naming the option or
  /// variable and its value. Call once, after parsing, before any command runs.
  Status resolve();

  /// The resolved DDS domain (valid after resolve()).
  std::uint32_t domain_id() const noexcept { return domain_id_; }
  /// The resolved DDS partition (valid after resolve()).
  const std::string& partition() const noexcept { return partition_; }
  /// True when --json asked for machine-readable output.
  bool json() const noexcept { return options_.json; }
  /// --timeout as a duration.
  std::chrono::milliseconds timeout() const noexcept;

  /// "domain 0, partition 'cell'": names the bus in messages.
  std::string describe_bus() const;

  /// The participant on the resolved bus, created on first use. Throws bus::BusError
  /// (caught by run(), which reports it and exits 1).
  const bus::Participant& participant();

  /// Where results go (stdout in the executable).
  std::ostream& out() noexcept { return out_; }
  /// Where diagnostics go (stderr in the executable).
  std::ostream& err() noexcept { return err_; }

  /// Prints "cellctl: <message>" on stderr and returns kExitFailure (or `code`).
  int fail(std::string_view message, int code = kExitFailure);

 private:
  const GlobalOptions& options_;
  std::ostream& out_;
  std::ostream& err_;
  std::uint32_t domain_id_ = 0;
  std::string partition_ = "cell";
  std::unique_ptr<bus::Participant> participant_;
};

/// Runs cellctl on `argv` (argv[0] is the program name), writing to `out` and `err`; returns
/// the exit code. Never throws.
int run(int argc, const char* const* argv, std::ostream& out, std::ostream& err);

}  // namespace cell::cellctl
