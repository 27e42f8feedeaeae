#include "cell/common/time.hpp"

#include <ctime>

#include <fmt/format.h>

namespace cell {

std::int64_t wall_time_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_REALTIME, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::int64_t monotonic_ns() noexcept {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000 + ts.tv_nsec;
}

std::string format_iso8601(std::int64_t wall_ns) {
  const std::time_t secs = static_cast<std::time_t>(wall_ns / 1'000'000'000);
  const int millis = static_cast<int>((wall_ns % 1'000'000'000) / 1'000'000);
  std::tm utc{};
  gmtime_r(&secs, &utc);
  return fmt::format("{:04d}-{:02d}-{:02d}T{:02d}:{:02d}:{:02d}.{:03d}Z", utc.tm_year + 1900,
                     utc.tm_mon + 1, utc.tm_mday, utc.tm_hour, utc.tm_min, utc.tm_sec, millis);
}

std::string format_duration(double seconds) {
  if (seconds < 120.0) {
    return fmt::format("{:.1f} s", seconds);
  }
  if (seconds < 7200.0) {
    return fmt::format("{:.1f} min", seconds / 60.0);
  }
  return fmt::format("{:.1f} h", seconds / 3600.0);
}

}  // namespace cell
