#pragma once

#include <string_view>

namespace cell {

/// Version of the cell software, e.g. "0.1.0" (from the top-level CMake project()).
std::string_view version() noexcept;

/// The Cyclone DDS version this build links, e.g. "0.10.2".
std::string_view dds_version() noexcept;

}  // namespace cell
