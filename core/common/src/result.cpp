#include "cell/common/result.hpp"

#include <cstdio>
#include <cstdlib>

#include "cell/common/check.hpp"

namespace cell {

std::string_view to_string(Errc code) noexcept {
  switch (code) {
    case Errc::kInvalidArgument:
      return "invalid_argument";
    case Errc::kOutOfRange:
      return "out_of_range";
    case Errc::kConfig:
      return "config";
    case Errc::kBus:
      return "bus";
    case Errc::kProtocol:
      return "protocol";
    case Errc::kNotReady:
      return "not_ready";
    case Errc::kTimeout:
      return "timeout";
    case Errc::kIo:
      return "io";
  }
  return "unknown";
}

namespace detail {

void bad_result_access(bool wanted_value, const Error* error) noexcept {
  if (wanted_value) {
    std::fprintf(stderr, "cell: Result::value() called on an error result: %s\n",
                 error != nullptr ? error->message.c_str() : "?");
  } else {
    std::fprintf(stderr, "cell: Result::error() called on a value result\n");
  }
  std::abort();
}

void check_failed(const char* condition, const char* file, int line) noexcept {
  std::fprintf(stderr, "cell: CELL_CHECK(%s) failed at %s:%d\n", condition, file, line);
  std::fflush(stderr);
  std::abort();
}

}  // namespace detail
}  // namespace cell
