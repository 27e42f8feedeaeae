#pragma once

#include <cstdint>
#include <string_view>
#include <vector>

#include "cell/rapt/source.hpp"

/// The RAPT lexer: turns source text into tokens with positions.
///
/// The language (digest 003 §1, thesis ch. 3 and 5) is case-insensitive and made of statements
/// ended by ';'. Tokens: identifiers ([A-Za-z_][A-Za-z0-9_]*), numbers (an optional sign, digits,
/// an optional fraction and exponent: "-20", "0.5", "1e3"), and the punctuation '/' ',' ';' '='.
/// `REMARK <any text> ;` is a comment: the lexer drops it, text and ';' included (a remark may
/// span lines, as in Appendix V). Keywords are ordinary identifiers; the parser recognises them
/// with `keyword_is` (case-insensitive).
namespace cell::rapt {

/// What a token is.
enum class TokenKind : std::uint8_t {
  kIdent,      ///< a name or keyword
  kNumber,     ///< a finite number (value in Token::number)
  kSlash,      ///< '/'
  kComma,      ///< ','
  kSemicolon,  ///< ';'
  kEquals,     ///< '='
  kEnd,        ///< end of input (always the last token)
};

/// One token. `text` points into the source passed to `lex`, which must outlive the tokens.
struct Token {
  TokenKind kind = TokenKind::kEnd;  ///< what the token is
  std::string_view text;             ///< the characters of the token as written
  double number = 0.0;               ///< value of a kNumber token
  SourceLoc loc;                     ///< position of the first character
};

/// Human-readable name of a token for "expected X, got Y" messages: "';'", "number 20",
/// "name 'b1'", "end of file".
std::string describe(const Token& token);

/// Case-insensitive comparison of an identifier token with a lower-case keyword.
bool keyword_is(const Token& token, std::string_view lower_keyword) noexcept;

/// Tokenises `source`. Never fails: malformed characters, numbers that are out of range and
/// unterminated remarks are reported to `diags` (with their position) and skipped, so the parser
/// still sees the rest of the file. The result always ends with one kEnd token.
/// Allocation: one vector of tokens; token text is not copied.
std::vector<Token> lex(std::string_view source, Diagnostics& diags);

}  // namespace cell::rapt
