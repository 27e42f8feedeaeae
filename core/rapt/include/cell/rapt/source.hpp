#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "cell/common/result.hpp"

/// Source positions and the diagnostics list shared by every stage of the RAPT compiler
/// (lexer, parser, semantic analysis, inference, vision packages, MF linking).
namespace cell::rapt {

/// A position in a RAPT source file: 1-based line and column (columns count bytes).
/// {0, 0} means "no position" (only for diagnostics about the whole file).
struct SourceLoc {
  std::uint32_t line = 0;    ///< 1-based line
  std::uint32_t column = 0;  ///< 1-based column (bytes)

  /// True when this is a real position in the file.
  bool known() const noexcept { return line > 0 && column > 0; }
  friend bool operator==(const SourceLoc&, const SourceLoc&) = default;
};

/// How bad a diagnostic is. Errors make compilation fail; warnings (e.g. a vision package that
/// cannot fix its body, a multi-reference MOVE whose references disagree) do not.
enum class Severity : std::uint8_t { kError, kWarning };

/// One message about the program, always with the position it concerns.
struct Diagnostic {
  Severity severity = Severity::kError;
  SourceLoc loc;
  std::string message;  ///< a full sentence: what is wrong and what was expected
};

/// Collects the diagnostics of one compilation, in the order found. Bounded: after
/// `kMaxDiagnostics` errors further ones are dropped and a final note says so, so that a
/// pathological input cannot make the list grow without bound. Not thread-safe.
class Diagnostics {
 public:
  /// Upper bound on stored diagnostics.
  static constexpr std::size_t kMaxDiagnostics = 200;

  /// `file` names the source in formatted messages ("config/rapt/appendix_v.rapt").
  explicit Diagnostics(std::string file = "<input>") : file_(std::move(file)) {}

  /// Records an error at `loc`.
  void error(SourceLoc loc, std::string message);
  /// Records a warning at `loc`.
  void warning(SourceLoc loc, std::string message);

  /// True when at least one error was recorded.
  bool has_errors() const noexcept { return errors_ > 0; }
  /// Number of errors recorded (including dropped ones).
  std::size_t error_count() const noexcept { return errors_; }
  /// Every stored diagnostic, in order.
  const std::vector<Diagnostic>& items() const noexcept { return items_; }
  /// The file name used in formatted messages.
  const std::string& file() const noexcept { return file_; }

  /// "file:line:col: error: message" (or "warning:") for one diagnostic.
  std::string format(const Diagnostic& d) const;
  /// Every diagnostic formatted, one per line (errors and warnings).
  std::string format_all() const;
  /// kConfig Error whose message is every error (not warnings), one per line; call only when
  /// has_errors().
  Error to_error() const;

 private:
  void add(Severity severity, SourceLoc loc, std::string message);

  std::string file_;
  std::vector<Diagnostic> items_;
  std::size_t errors_ = 0;
  bool truncated_ = false;
};

/// "12:5" for messages that point at another statement ("the relation at 12:5").
std::string to_string(SourceLoc loc);

}  // namespace cell::rapt
