#include "cell/rapt/source.hpp"

#include <fmt/format.h>

namespace cell::rapt {

void Diagnostics::error(SourceLoc loc, std::string message) {
  add(Severity::kError, loc, std::move(message));
}

void Diagnostics::warning(SourceLoc loc, std::string message) {
  add(Severity::kWarning, loc, std::move(message));
}

void Diagnostics::add(Severity severity, SourceLoc loc, std::string message) {
  if (severity == Severity::kError) {
    ++errors_;
  }
  if (items_.size() >= kMaxDiagnostics) {
    if (!truncated_) {
      truncated_ = true;
      // Replace the last slot with the note so the bound holds exactly.
      items_.back() = Diagnostic{Severity::kError, items_.back().loc,
                                 "too many diagnostics; the rest are not shown"};
    }
    return;
  }
  items_.push_back(Diagnostic{severity, loc, std::move(message)});
}

std::string Diagnostics::format(const Diagnostic& d) const {
  const char* kind = d.severity == Severity::kError ? "error" : "warning";
  if (!d.loc.known()) {
    return fmt::format("{}: {}: {}", file_, kind, d.message);
  }
  return fmt::format("{}:{}:{}: {}: {}", file_, d.loc.line, d.loc.column, kind, d.message);
}

std::string Diagnostics::format_all() const {
  std::string out;
  for (const Diagnostic& d : items_) {
    out += format(d);
    out += '\n';
  }
  return out;
}

Error Diagnostics::to_error() const {
  std::string out;
  for (const Diagnostic& d : items_) {
    if (d.severity != Severity::kError) {
      continue;
    }
    if (!out.empty()) {
      out += '\n';
    }
    out += format(d);
  }
  return Error{Errc::kConfig, out};
}

std::string to_string(SourceLoc loc) { return fmt::format("{}:{}", loc.line, loc.column); }

}  // namespace cell::rapt
