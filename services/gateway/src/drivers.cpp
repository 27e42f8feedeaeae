#include "drivers.hpp"

#include <array>

#include "dpr7545_driver.hpp"
#include "excalibur_driver.hpp"
#include "ideal_driver.hpp"

namespace cell::gateway {
namespace {

constexpr std::array kDrivers = {
    DriverKind{"ideal", &parse_ideal_driver},
    DriverKind{"dpr7545", &parse_dpr7545_driver},
    DriverKind{"excalibur", &parse_excalibur_driver},
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
