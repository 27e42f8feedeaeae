#include "cell/rapt/lexer.hpp"

#include <fmt/format.h>

#include <cctype>
#include <charconv>
#include <cmath>
#include <string>

namespace cell::rapt {
namespace {

bool is_ident_start(char c) noexcept {
  return std::isalpha(static_cast<unsigned char>(c)) != 0 || c == '_';
}
bool is_ident_char(char c) noexcept {
  return std::isalnum(static_cast<unsigned char>(c)) != 0 || c == '_';
}
bool is_digit(char c) noexcept { return c >= '0' && c <= '9'; }

char lower(char c) noexcept {
  return static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
}

/// Walks the source keeping line and column.
class Cursor {
 public:
  explicit Cursor(std::string_view src) : src_(src) {}
  bool done() const noexcept { return pos_ >= src_.size(); }
  char peek(std::size_t ahead = 0) const noexcept {
    return pos_ + ahead < src_.size() ? src_[pos_ + ahead] : '\0';
  }
  void advance() noexcept {
    if (src_[pos_] == '\n') {
      ++line_;
      column_ = 1;
    } else {
      ++column_;
    }
    ++pos_;
  }
  std::size_t pos() const noexcept { return pos_; }
  SourceLoc loc() const noexcept { return SourceLoc{line_, column_}; }
  std::string_view slice(std::size_t from) const noexcept { return src_.substr(from, pos_ - from); }

 private:
  std::string_view src_;
  std::size_t pos_ = 0;
  std::uint32_t line_ = 1;
  std::uint32_t column_ = 1;
};

}  // namespace

std::string describe(const Token& token) {
  switch (token.kind) {
    case TokenKind::kIdent:
      return fmt::format("'{}'", token.text);
    case TokenKind::kNumber:
      return fmt::format("number {}", token.text);
    case TokenKind::kSlash:
      return "'/'";
    case TokenKind::kComma:
      return "','";
    case TokenKind::kSemicolon:
      return "';'";
    case TokenKind::kEquals:
      return "'='";
    case TokenKind::kEnd:
      return "end of file";
  }
  return "token";
}

bool keyword_is(const Token& token, std::string_view lower_keyword) noexcept {
  if (token.kind != TokenKind::kIdent || token.text.size() != lower_keyword.size()) {
    return false;
  }
  for (std::size_t i = 0; i < lower_keyword.size(); ++i) {
    if (lower(token.text[i]) != lower_keyword[i]) {
      return false;
    }
  }
  return true;
}

std::vector<Token> lex(std::string_view source, Diagnostics& diags) {
  std::vector<Token> tokens;
  tokens.reserve(source.size() / 3 + 1);
  Cursor cur(source);
  while (!cur.done()) {
    const char c = cur.peek();
    if (std::isspace(static_cast<unsigned char>(c)) != 0) {
      cur.advance();
      continue;
    }
    const SourceLoc loc = cur.loc();
    const std::size_t start = cur.pos();
    if (is_ident_start(c)) {
      while (!cur.done() && is_ident_char(cur.peek())) {
        cur.advance();
      }
      Token tok{TokenKind::kIdent, cur.slice(start), 0.0, loc};
      if (keyword_is(tok, "remark")) {
        // A remark runs to the next ';' (it may span lines) and vanishes with it.
        while (!cur.done() && cur.peek() != ';') {
          cur.advance();
        }
        if (cur.done()) {
          diags.error(loc, "REMARK is not terminated: expected ';' before the end of the file");
        } else {
          cur.advance();
        }
        continue;
      }
      tokens.push_back(tok);
      continue;
    }
    const bool signed_number =
        (c == '-' || c == '+') &&
        (is_digit(cur.peek(1)) || (cur.peek(1) == '.' && is_digit(cur.peek(2))));
    if (is_digit(c) || signed_number || (c == '.' && is_digit(cur.peek(1)))) {
      if (signed_number) {
        cur.advance();
      }
      while (!cur.done() && is_digit(cur.peek())) {
        cur.advance();
      }
      if (cur.peek() == '.') {
        cur.advance();
        while (!cur.done() && is_digit(cur.peek())) {
          cur.advance();
        }
      }
      if ((cur.peek() == 'e' || cur.peek() == 'E') &&
          (is_digit(cur.peek(1)) ||
           ((cur.peek(1) == '-' || cur.peek(1) == '+') && is_digit(cur.peek(2))))) {
        cur.advance();
        if (cur.peek() == '-' || cur.peek() == '+') {
          cur.advance();
        }
        while (!cur.done() && is_digit(cur.peek())) {
          cur.advance();
        }
      }
      const std::string_view text = cur.slice(start);
      // from_chars does not accept a leading '+'.
      const std::string_view digits = text.front() == '+' ? text.substr(1) : text;
      double value = 0.0;
      const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), value);
      if (ec != std::errc() || ptr != digits.data() + digits.size() || !std::isfinite(value)) {
        diags.error(loc, fmt::format("number '{}' is out of range", text));
        value = 0.0;
      }
      tokens.push_back(Token{TokenKind::kNumber, text, value, loc});
      continue;
    }
    TokenKind kind = TokenKind::kEnd;
    switch (c) {
      case '/':
        kind = TokenKind::kSlash;
        break;
      case ',':
        kind = TokenKind::kComma;
        break;
      case ';':
        kind = TokenKind::kSemicolon;
        break;
      case '=':
        kind = TokenKind::kEquals;
        break;
      default:
        break;
    }
    cur.advance();
    if (kind == TokenKind::kEnd) {
      const unsigned char uc = static_cast<unsigned char>(c);
      if (std::isprint(uc) != 0) {
        diags.error(loc, fmt::format("unexpected character '{}'", c));
      } else {
        diags.error(loc, fmt::format("unexpected byte 0x{:02x}", static_cast<unsigned>(uc)));
      }
      continue;
    }
    tokens.push_back(Token{kind, cur.slice(start), 0.0, loc});
  }
  tokens.push_back(Token{TokenKind::kEnd, {}, 0.0, cur.loc()});
  return tokens;
}

}  // namespace cell::rapt
