#include "drivers.hpp"

#include <array>

#include "ideal_driver.hpp"

namespace cell::gateway {
namespace {

constexpr std::array kDrivers = {
    DriverKind{"ideal", &parse_ideal_driver},
};

}  // namespace

std::span<const DriverKind> driver_kinds() noexcept { return kDrivers; }

DriverParser find_driver(std::string_view kind) noexcept {
  for (const auto& d : kDrivers) {
    if (d.name == kind) {
      return d.parse;
    }
  }
  return nullptr;
}

}  // namespace cell::gateway
