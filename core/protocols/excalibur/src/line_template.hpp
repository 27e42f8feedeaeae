#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "cell/common/result.hpp"
#include "cell/protocols/excalibur/dialect.hpp"

namespace cell::protocols::excalibur::detail {

/// Named placeholders a template may use.
enum class Field : std::uint8_t {
  kQ1,
  kQ2,
  kQ3,
  kQ4,
  kQ5,
  kQ6,
  kMode,
  kTolerance,
  kTimeout,
  kCode,
};
inline constexpr std::size_t kFields = 10;

/// Bit of a field in a field mask.
constexpr std::uint32_t bit(Field f) noexcept { return 1U << static_cast<unsigned>(f); }
/// q1..q6.
inline constexpr std::uint32_t kAngleFields = 0x3FU;

/// "q1", ..., "mode", "tolerance", "timeout", "code".
std::string_view to_string(Field field) noexcept;

/// The values a template renders or a match extracts.
struct Values {
  ControllerAngles q{};
  std::size_t mode_index = 0;  ///< index into the dialect's mode words
  double tolerance = 0.0;
  double timeout = 0.0;
  int code = 0;
};

/// One line template: literal text and {placeholders}. A space in the literal text is written as
/// one space and matches one or more blanks (space or tab) when parsing. A template starts
/// with a literal mnemonic (its `head`). Immutable after compile.
class LineTemplate {
 public:
  /// Compiles `text`. `allowed` and `required` are field masks. Errors (kConfig, message without
  /// location): unknown or unclosed placeholder, a placeholder not allowed here or used twice,
  /// a required one missing, no leading mnemonic, a non-printable character.
  static Result<LineTemplate> compile(std::string_view text,
                                      std::uint32_t allowed,
                                      std::uint32_t required);

  /// Appends the rendered line to `out`. Errors: kInvalidArgument for a non-finite number or
  /// one that does not fit (|angle| > max_abs_angle_deg).
  Status render(const Values& values,
                const NumberFormat& numbers,
                const std::array<std::string, kModes>& mode_words,
                std::string& out) const;

  /// Matches a whole body (checksum already removed). Errors: kProtocol, "expected ... at column
  /// N, got '...'" (column 1-based in the body).
  Result<Values> match(std::string_view body,
                       const NumberFormat& numbers,
                       const std::array<std::string, kModes>& mode_words) const;

  /// True when `body` starts with this template's mnemonic.
  bool head_matches(std::string_view body) const noexcept;
  const std::string& head() const noexcept { return head_; }
  const std::string& text() const noexcept { return text_; }
  std::uint32_t fields() const noexcept { return fields_; }

 private:
  struct Token {
    bool literal = true;
    std::string text;
    Field field = Field::kQ1;
  };
  std::vector<Token> tokens_;
  std::string head_;
  std::string text_;
  std::uint32_t fields_ = 0;
};

}  // namespace cell::protocols::excalibur::detail
