#include "cell/common/log.hpp"

#include <atomic>
#include <mutex>
#include <string>

#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>

#include "cell/common/time.hpp"

namespace cell::log {
namespace {

struct State {
  std::mutex mutex;
  std::string service = "<unset>";
  std::atomic<int> min_level{static_cast<int>(Level::kInfo)};
  std::shared_ptr<spdlog::logger> logger;
};

State& state() {
  static State instance;  // the process's one log sink; spdlog serialises writes
  return instance;
}

std::shared_ptr<spdlog::logger> logger_locked(State& s) {
  if (!s.logger) {
    s.logger = spdlog::stderr_logger_mt("cell");
    s.logger->set_pattern("%v");
    s.logger->set_level(spdlog::level::trace);
    s.logger->flush_on(spdlog::level::trace);
  }
  return s.logger;
}

std::string_view level_name(Level level) {
  switch (level) {
    case Level::kDebug:
      return "debug";
    case Level::kInfo:
      return "info";
    case Level::kWarn:
      return "warn";
    case Level::kError:
      return "error";
  }
  return "info";
}

bool needs_quotes(std::string_view value) {
  if (value.empty()) {
    return true;
  }
  for (const char c : value) {
    if (c == ' ' || c == '"' || c == '=' || c == '\\' || c == '\n' || c == '\t') {
      return true;
    }
  }
  return false;
}

constexpr std::size_t kMaxValueBytes = 512;

void append_value(std::string& out, std::string_view value, bool force_quotes) {
  // A value from the bus can be a megabyte of garbage: keep the head, say how long it was, so
  // a flood of bad samples cannot fill the disk through the log.
  std::string_view shown = value;
  if (value.size() > kMaxValueBytes) {
    std::size_t cut = kMaxValueBytes;
    while (cut > 0 && (static_cast<unsigned char>(value[cut]) & 0xC0U) == 0x80U) {
      --cut;  // never split a UTF-8 sequence
    }
    shown = value.substr(0, cut);
    force_quotes = true;
  }
  if (!force_quotes && !needs_quotes(shown)) {
    out += shown;
    return;
  }
  out += '"';
  for (const char c : shown) {
    switch (c) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\t':
        out += "\\t";
        break;
      default:
        out += c;
    }
  }
  if (shown.size() != value.size()) {
    out += "...(";
    out += std::to_string(value.size());
    out += " bytes)";
  }
  out += '"';
}

}  // namespace

void init(std::string_view service, Level min_level) {
  State& s = state();
  std::lock_guard lock(s.mutex);
  s.service = std::string(service);
  s.min_level = static_cast<int>(min_level);
  (void)logger_locked(s);
}

bool parse_level(std::string_view text, Level& level) noexcept {
  if (text == "debug") {
    level = Level::kDebug;
  } else if (text == "info") {
    level = Level::kInfo;
  } else if (text == "warn" || text == "warning") {
    level = Level::kWarn;
  } else if (text == "error") {
    level = Level::kError;
  } else {
    return false;
  }
  return true;
}

std::string format_line(Level level, std::string_view service, std::string_view event,
                        std::string_view message, std::initializer_list<Field> fields) {
  std::string line;
  line.reserve(96 + message.size());
  line += "ts=";
  line += format_iso8601(wall_time_ns());
  line += " lvl=";
  line += level_name(level);
  line += " svc=";
  append_value(line, service, false);
  line += " event=";
  append_value(line, event, false);
  line += " msg=";
  append_value(line, message, true);
  for (const auto& [key, value] : fields) {
    line += ' ';
    line += key;
    line += '=';
    append_value(line, value, false);
  }
  return line;
}

void write(Level level, std::string_view event, std::string_view message,
           std::initializer_list<Field> fields) noexcept {
  State& s = state();
  if (static_cast<int>(level) < s.min_level.load(std::memory_order_relaxed)) {
    return;
  }
  try {
    std::shared_ptr<spdlog::logger> logger;
    std::string service;
    {
      std::lock_guard lock(s.mutex);
      logger = logger_locked(s);
      service = s.service;
    }
    logger->info(format_line(level, service, event, message, fields));
  } catch (...) {
    // Logging must never take a service down (out of memory, closed stderr): drop the line.
  }
}

}  // namespace cell::log
