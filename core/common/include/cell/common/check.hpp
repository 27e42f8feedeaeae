#pragma once

/// CELL_CHECK(cond): a broken invariant, i.e. a programmer error (STYLE.md §4, channel 3).
/// Logs file:line and the condition, then aborts. Never use it for anything input can trigger.
#define CELL_CHECK(cond)                                            \
  do {                                                              \
    if (!(cond)) {                                                  \
      ::cell::detail::check_failed(#cond, __FILE__, __LINE__);      \
    }                                                               \
  } while (false)

namespace cell::detail {
[[noreturn]] void check_failed(const char* condition, const char* file, int line) noexcept;
}  // namespace cell::detail
