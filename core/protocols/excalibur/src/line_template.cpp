#include "line_template.hpp"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <iterator>

namespace cell::protocols::excalibur::detail {
namespace {

constexpr std::array<std::string_view, kFields> kFieldNames = {
    "q1", "q2", "q3", "q4", "q5", "q6", "mode", "tolerance", "timeout", "code"};

bool is_blank(char c) noexcept { return c == ' ' || c == '\t'; }
bool is_digit(char c) noexcept { return c >= '0' && c <= '9'; }
bool is_alnum(char c) noexcept {
  return is_digit(c) || (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z');
}

bool is_number_field(Field f) noexcept { return f != Field::kMode && f != Field::kCode; }

int decimals_of(Field f, const NumberFormat& n) noexcept {
  switch (f) {
    case Field::kTolerance:
      return n.tolerance_decimals;
    case Field::kTimeout:
      return n.timeout_decimals;
    default:
      return n.angle_decimals;
  }
}

/// The run of non-blank characters at `pos`, for "got '...'" in messages.
std::string word_at(std::string_view body, std::size_t pos) {
  std::size_t end = pos;
  while (end < body.size() && !is_blank(body[end])) {
    ++end;
  }
  if (end == pos) {
    return pos >= body.size() ? std::string("end of line") : quote_line(body.substr(pos, 1));
  }
  return quote_line(body.substr(pos, end - pos));
}

}  // namespace

std::string_view to_string(Field field) noexcept {
  return kFieldNames[static_cast<std::size_t>(field)];
}

Result<LineTemplate> LineTemplate::compile(std::string_view text,
                                           std::uint32_t allowed,
                                           std::uint32_t required) {
  LineTemplate t;
  t.text_ = std::string(text);
  const auto fail = [&](const std::string& what) -> Error {
    return Error{Errc::kConfig, fmt::format("template {}: {}", quote_line(text), what)};
  };
  for (char c : text) {
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7E) {
      return fail("only printable ASCII is allowed (terminators are set in `framing`)");
    }
  }
  if (text.empty() || text.front() == ' ' || text.front() == '{') {
    return fail("must begin with a literal mnemonic (e.g. \"MJ {q1} ...\")");
  }
  std::size_t i = 0;
  std::string literal;
  while (i < text.size()) {
    const char c = text[i];
    if (c == '}') {
      return fail(fmt::format("unmatched '}}' at column {}", i + 1));
    }
    if (c != '{') {
      // Runs of spaces collapse to one: a space means "one or more blanks".
      if (!(c == ' ' && !literal.empty() && literal.back() == ' ')) {
        literal.push_back(c);
      }
      ++i;
      continue;
    }
    const std::size_t close = text.find('}', i);
    if (close == std::string_view::npos) {
      return fail(fmt::format("unclosed '{{' at column {}", i + 1));
    }
    const std::string_view name = text.substr(i + 1, close - i - 1);
    std::size_t index = kFields;
    for (std::size_t f = 0; f < kFields; ++f) {
      if (kFieldNames[f] == name) {
        index = f;
      }
    }
    if (index == kFields) {
      return fail(
          fmt::format("unknown placeholder {{{}}} (known: q1..q6, mode, tolerance, "
                      "timeout, code)",
                      name));
    }
    const auto field = static_cast<Field>(index);
    if ((allowed & bit(field)) == 0) {
      return fail(fmt::format("placeholder {{{}}} is not used by this line", name));
    }
    if ((t.fields_ & bit(field)) != 0) {
      return fail(fmt::format("placeholder {{{}}} appears twice", name));
    }
    if (!t.tokens_.empty() && !t.tokens_.back().literal && literal.empty()) {
      return fail(fmt::format("placeholders {{{}}} and {{{}}} need a separator between them",
                              to_string(t.tokens_.back().field), name));
    }
    if (!literal.empty()) {
      t.tokens_.push_back(Token{true, literal, Field::kQ1});
      literal.clear();
    }
    t.tokens_.push_back(Token{false, {}, field});
    t.fields_ |= bit(field);
    i = close + 1;
  }
  if (!literal.empty()) {
    t.tokens_.push_back(Token{true, literal, Field::kQ1});
  }
  if ((t.fields_ & required) != required) {
    std::string missing;
    for (std::size_t f = 0; f < kFields; ++f) {
      if ((required & (1U << f)) != 0 && (t.fields_ & (1U << f)) == 0) {
        missing += fmt::format("{}{{{}}}", missing.empty() ? "" : ", ", kFieldNames[f]);
      }
    }
    return fail("missing placeholder " + missing);
  }
  const std::string& first = t.tokens_.front().text;
  t.head_ = first.substr(0, first.find(' '));
  return t;
}

Status LineTemplate::render(const Values& values,
                            const NumberFormat& numbers,
                            const std::array<std::string, kModes>& mode_words,
                            std::string& out) const {
  for (const Token& token : tokens_) {
    if (token.literal) {
      out += token.text;
      continue;
    }
    switch (token.field) {
      case Field::kMode:
        out += mode_words[values.mode_index];
        break;
      case Field::kCode:
        fmt::format_to(std::back_inserter(out), "{}", values.code);
        break;
      default: {
        double v = 0.0;
        if (token.field == Field::kTolerance) {
          v = values.tolerance;
        } else if (token.field == Field::kTimeout) {
          v = values.timeout;
        } else {
          v = values.q[static_cast<std::size_t>(token.field)];
        }
        const int decimals = decimals_of(token.field, numbers);
        const double limit = token.field == Field::kTimeout || token.field == Field::kTolerance
                                 ? 9999.0
                                 : numbers.max_abs_angle_deg;
        if (!std::isfinite(v) || std::abs(v) > limit) {
          return Error{Errc::kInvalidArgument,
                       fmt::format("{} = {} does not fit the wire format (|value| <= {})",
                                   to_string(token.field), v, limit)};
        }
        if (numbers.plus_sign) {
          fmt::format_to(std::back_inserter(out), "{:+.{}f}", v, decimals);
        } else {
          fmt::format_to(std::back_inserter(out), "{:.{}f}", v, decimals);
        }
        break;
      }
    }
  }
  return ok_status();
}

bool LineTemplate::head_matches(std::string_view body) const noexcept {
  return body.substr(0, head_.size()) == head_;
}

Result<Values> LineTemplate::match(std::string_view body,
                                   const NumberFormat& numbers,
                                   const std::array<std::string, kModes>& mode_words) const {
  Values values;
  std::size_t pos = 0;
  const auto fail = [&](std::string what) -> Error {
    return Error{Errc::kProtocol, std::move(what)};
  };
  for (const Token& token : tokens_) {
    if (token.literal) {
      for (char c : token.text) {
        if (c == ' ') {
          if (pos >= body.size() || !is_blank(body[pos])) {
            return fail(fmt::format("expected a blank at column {} (template {}), got {}", pos + 1,
                                    quote_line(text_), word_at(body, pos)));
          }
          while (pos < body.size() && is_blank(body[pos])) {
            ++pos;
          }
        } else if (pos >= body.size() || body[pos] != c) {
          return fail(fmt::format("expected {} at column {} (template {}), got {}",
                                  quote_line(std::string_view(&c, 1)), pos + 1, quote_line(text_),
                                  word_at(body, pos)));
        } else {
          ++pos;
        }
      }
      continue;
    }
    const std::size_t start = pos;
    if (token.field == Field::kMode) {
      while (pos < body.size() && is_alnum(body[pos])) {
        ++pos;
      }
      const std::string_view word = body.substr(start, pos - start);
      bool found = false;
      for (std::size_t m = 0; m < kModes; ++m) {
        if (mode_words[m] == word) {
          values.mode_index = m;
          found = true;
        }
      }
      if (!found) {
        std::string known;
        for (std::size_t m = 0; m < kModes; ++m) {
          known += fmt::format("{}{}", m == 0 ? "" : ", ", mode_words[m]);
        }
        return fail(fmt::format("expected a mode word ({}) at column {}, got {}", known, start + 1,
                                word_at(body, start)));
      }
      continue;
    }
    if (pos < body.size() && (body[pos] == '+' || body[pos] == '-')) {
      ++pos;
    }
    const std::size_t digits = pos;
    while (pos < body.size() && is_digit(body[pos])) {
      ++pos;
    }
    const bool has_int = pos > digits;
    int decimals = 0;
    if (token.field != Field::kCode && pos < body.size() && body[pos] == '.') {
      ++pos;
      const std::size_t frac = pos;
      while (pos < body.size() && is_digit(body[pos])) {
        ++pos;
      }
      decimals = static_cast<int>(pos - frac);
      if (decimals == 0) {
        pos = frac - 1;  // "12." is malformed: report below
        decimals = -1;
      }
    }
    const bool ends_clean =
        pos >= body.size() || is_blank(body[pos]) || (!is_alnum(body[pos]) && body[pos] != '.');
    const std::size_t sign_skip = start < body.size() && body[start] == '+' ? 1 : 0;
    if (token.field == Field::kCode) {
      int code = 0;
      const auto [ptr, ec] =
          std::from_chars(body.data() + start + sign_skip, body.data() + pos, code);
      if (!has_int || ec != std::errc() || ptr != body.data() + pos || !ends_clean) {
        return fail(fmt::format("expected an integer for {{code}} at column {}, got {}", start + 1,
                                word_at(body, start)));
      }
      values.code = code;
      continue;
    }
    const int wanted = decimals_of(token.field, numbers);
    const bool decimals_ok = decimals >= 0 && (!numbers.strict_decimals || decimals == wanted);
    double v = 0.0;
    const char* first = body.data() + start + sign_skip;
    const auto [ptr, ec] = std::from_chars(first, body.data() + pos, v);
    if (!has_int || !decimals_ok || ec != std::errc() || ptr != body.data() + pos || !ends_clean) {
      return fail(fmt::format("expected a number with {} decimal{} for {{{}}} at column {}, got {}",
                              wanted, wanted == 1 ? "" : "s", to_string(token.field), start + 1,
                              word_at(body, start)));
    }
    if (is_number_field(token.field) && token.field != Field::kTolerance &&
        token.field != Field::kTimeout) {
      values.q[static_cast<std::size_t>(token.field)] = v;
    } else if (token.field == Field::kTolerance) {
      values.tolerance = v;
    } else {
      values.timeout = v;
    }
  }
  if (pos != body.size()) {
    while (pos + 1 < body.size() && is_blank(body[pos])) {
      ++pos;
    }
    return fail(fmt::format("unexpected {} at column {} after a complete {} line",
                            word_at(body, pos), pos + 1, quote_line(head_)));
  }
  return values;
}

}  // namespace cell::protocols::excalibur::detail
