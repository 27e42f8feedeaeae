#pragma once

#include <string_view>

#include "cell/rapt/ast.hpp"
#include "cell/rapt/source.hpp"

/// The RAPT parser: recursive descent over the statements of digest 003 §1-§2 (thesis ch. 3, 5
/// and the forms used by Appendices V and VI). See core/rapt/README.md for the grammar.
namespace cell::rapt {

/// Parses `source` (lexing it first). Every syntax error is reported to `diags` with its
/// position and what was expected ("expected ',' after the line name, got ';'"); the parser
/// then skips to the next ';' and goes on, so one run reports every error of the file. The
/// returned program holds the statements that parsed. Never throws; allocation is the token
/// vector plus the AST.
ast::Program parse(std::string_view source, Diagnostics& diags);

}  // namespace cell::rapt
