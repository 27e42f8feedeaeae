#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <variant>

namespace cell {

/// Error categories (STYLE.md §4). Every failure a user or the world can cause travels as an
/// `Error` inside a `Result`; exceptions are for setup failures only.
enum class Errc : std::uint8_t {
  kInvalidArgument,  ///< malformed input: wrong size, NaN, unknown id
  kOutOfRange,       ///< well-formed but outside limits: workspace, joint range
  kConfig,           ///< config problem; message starts with file:line:col
  kBus,              ///< DDS call failed; message carries dds_strretcode()
  kProtocol,         ///< controller or transport misbehaved
  kNotReady,         ///< call made in the wrong lifecycle state
  kTimeout,          ///< a deadline passed before an answer came
  kIo,               ///< file or device I/O failed
};

/// Short lower-case name of an error code, e.g. "out_of_range" (used in logs and replies).
std::string_view to_string(Errc code) noexcept;

/// A failure: category plus a full sentence saying what, where, expected vs got.
struct Error {
  Errc code = Errc::kInvalidArgument;
  std::string message;
};

/// Marker value for `Status` (a `Result` that carries no value).
struct Ok {};

/// Tag wrapper, as std::unexpected, for returning an error from a function returning Result<T>
/// when T is itself constructible from Error (rare). Normally just `return Error{...};`.
template <typename E>
struct Unexpected {
  E error;
};

/// std::expected<T, Error> with the same member names (has_value, value, error, operator*,
/// operator->), so it becomes an alias when we move to C++23. Not thread-safe; cheap to move.
/// Accessing value() of an error result (or error() of a value) is a programmer error: it aborts.
template <typename T>
class [[nodiscard]] Result {
 public:
  using value_type = T;

  Result()
    requires std::is_default_constructible_v<T>
      : storage_(std::in_place_index<0>) {}
  Result(const T& value) : storage_(std::in_place_index<0>, value) {}  // NOLINT: implicit
  Result(T&& value) : storage_(std::in_place_index<0>, std::move(value)) {}  // NOLINT
  Result(Error error) : storage_(std::in_place_index<1>, std::move(error)) {}  // NOLINT
  Result(Unexpected<Error> error)  // NOLINT
      : storage_(std::in_place_index<1>, std::move(error.error)) {}
  template <typename U>
    requires(std::is_constructible_v<T, U&&> && !std::is_same_v<std::decay_t<U>, T> &&
             !std::is_same_v<std::decay_t<U>, Error> &&
             !std::is_same_v<std::decay_t<U>, Result<T>>)
  Result(U&& value) : storage_(std::in_place_index<0>, T(std::forward<U>(value))) {}  // NOLINT

  bool has_value() const noexcept { return storage_.index() == 0; }
  explicit operator bool() const noexcept { return has_value(); }

  T& value() & {
    check_value();
    return std::get<0>(storage_);
  }
  const T& value() const& {
    check_value();
    return std::get<0>(storage_);
  }
  // Rvalue access returns by value (std::expected returns T&&): `for (x : *make_result())`
  // then iterates a live object instead of one inside a destroyed temporary.
  T value() && {
    check_value();
    return std::get<0>(std::move(storage_));
  }
  const Error& error() const& {
    check_error();
    return std::get<1>(storage_);
  }
  Error&& error() && {
    check_error();
    return std::get<1>(std::move(storage_));
  }

  T& operator*() & { return value(); }
  const T& operator*() const& { return value(); }
  T operator*() && { return std::move(*this).value(); }
  T* operator->() { return &value(); }
  const T* operator->() const { return &value(); }

  /// The value, or `fallback` when this holds an error.
  template <typename U>
  T value_or(U&& fallback) const& {
    return has_value() ? std::get<0>(storage_) : static_cast<T>(std::forward<U>(fallback));
  }

 private:
  void check_value() const;
  void check_error() const;
  std::variant<T, Error> storage_;
};

using Status = Result<Ok>;

/// The success value of a Status.
inline Status ok_status() { return Status(Ok{}); }

namespace detail {
[[noreturn]] void bad_result_access(bool wanted_value, const Error* error) noexcept;
}  // namespace detail

template <typename T>
void Result<T>::check_value() const {
  if (!has_value()) {
    detail::bad_result_access(true, &std::get<1>(storage_));
  }
}

template <typename T>
void Result<T>::check_error() const {
  if (has_value()) {
    detail::bad_result_access(false, nullptr);
  }
}

/// Prefixes an error message with context ("loading robot 'ibm7545': ...").
inline Error with_context(Error error, std::string_view context) {
  error.message = std::string(context) + ": " + error.message;
  return error;
}

}  // namespace cell

/// Evaluates `expr` (a Result or Status); on error returns that error from the enclosing
/// function, which must return a Result of any type.
#define CELL_TRY(expr)                                   \
  do {                                                   \
    auto cell_try_result_ = (expr);                      \
    if (!cell_try_result_) {                             \
      return std::move(cell_try_result_).error();        \
    }                                                    \
  } while (false)
