#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "cell/config/yaml.hpp"
#include "cell/kinematics/robot_model.hpp"
#include "driver.hpp"

namespace cell::gateway {

/// Everything a driver may need when the gateway builds it (after the config was read).
struct DriverSetup {
  const kinematics::RobotModel& model;
  std::chrono::nanoseconds cycle;  ///< the servo period (1 / cycle_hz)
};

/// Builds a configured driver. Errors: kConfig or kIo naming what is wrong (a missing shared
/// memory segment, a serial port that will not open, initial joints outside the limits).
using DriverFactory = std::function<Result<std::unique_ptr<RobotDriver>>(const DriverSetup&)>;

/// Reads a driver's own keys from the config's `driver:` section (strictly: unknown keys and
/// bad values are recorded in `section` with file:line:col) and returns its factory.
using DriverParser = DriverFactory (*)(config::MapReader& section);

/// One kind of driver: its `driver.kind` name and its parser.
struct DriverKind {
  std::string_view name;
  DriverParser parse;
};

/// Every driver the gateway knows. To add one: write <name>_driver.{hpp,cpp} with a
/// DriverParser, add it to this table (drivers.cpp) and to the gateway's CMake sources.
std::span<const DriverKind> driver_kinds() noexcept;

/// The parser of `kind`, or nullptr.
DriverParser find_driver(std::string_view kind) noexcept;

}  // namespace cell::gateway
