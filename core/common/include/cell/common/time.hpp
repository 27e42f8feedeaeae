#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace cell {

/// Monotonic clock for deadlines, loop timing and latency (never jumps).
using SteadyClock = std::chrono::steady_clock;

/// Wall-clock time in nanoseconds since the Unix epoch: the stamp carried in IDL headers
/// (`stamp_ns`) and logs. Comparable across processes and, with NTP/PTP, across hosts.
std::int64_t wall_time_ns() noexcept;

/// Monotonic time in nanoseconds (CLOCK_MONOTONIC): comparable across processes of one host.
std::int64_t monotonic_ns() noexcept;

/// ISO 8601 UTC with milliseconds, e.g. "2026-11-22T02:08:08.123Z".
std::string format_iso8601(std::int64_t wall_ns);

/// A duration for people, unit included: "12.3 s", "4.5 min", "2.0 h".
std::string format_duration(double seconds);

}  // namespace cell
