#pragma once

#include <initializer_list>
#include <string_view>
#include <utility>

namespace cell::log {

/// Severity of a log line.
enum class Level { kDebug, kInfo, kWarn, kError };

/// One structured field: key=value. Values with spaces or quotes are quoted and escaped.
using Field = std::pair<std::string_view, std::string_view>;

/// Sets the process's service name (the `svc=` field) and minimum level. Call once, first,
/// from main. Thread-safe afterwards; logging before init uses svc=<unset>.
void init(std::string_view service, Level min_level = Level::kInfo);

/// Parses "debug", "info", "warn", "error"; returns false on anything else.
bool parse_level(std::string_view text, Level& level) noexcept;

/// Writes one line to stderr:
///   ts=2026-11-22T02:08:08.123Z lvl=info svc=vision event=start msg="..." key=value ...
/// `event` is a short snake_case tag grep-able across services. Never throws; thread-safe.
void write(Level level, std::string_view event, std::string_view message,
           std::initializer_list<Field> fields = {}) noexcept;

inline void debug(std::string_view event, std::string_view message,
                  std::initializer_list<Field> fields = {}) noexcept {
  write(Level::kDebug, event, message, fields);
}
inline void info(std::string_view event, std::string_view message,
                 std::initializer_list<Field> fields = {}) noexcept {
  write(Level::kInfo, event, message, fields);
}
inline void warn(std::string_view event, std::string_view message,
                 std::initializer_list<Field> fields = {}) noexcept {
  write(Level::kWarn, event, message, fields);
}
inline void error(std::string_view event, std::string_view message,
                  std::initializer_list<Field> fields = {}) noexcept {
  write(Level::kError, event, message, fields);
}

/// Formats one structured line without writing it (used by write(); exposed for tests). A
/// message or value longer than 512 bytes is cut there and ends "...(N bytes)".
std::string format_line(Level level, std::string_view service, std::string_view event,
                        std::string_view message, std::initializer_list<Field> fields);

}  // namespace cell::log
