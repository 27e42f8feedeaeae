#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>

#include "cell/rapt/relation.hpp"

/// The cycle finder's rule tables as data (thesis Appendix I, digest 003 §1.5 and §3.3).
///
/// Table 1 (combination rules) and Table 2 (creation rules) say, for each unordered pair of
/// relation types, the general result, whether it has two solutions ("(2)"), and the special
/// results that arise under particular geometry. The inference engine (nominal.hpp) consults
/// them to decide whether a pair may be combined at all and whether the result the geometric
/// solver (relation.hpp) found is admissible; a pair with no entry is never combined.
/// Table 6.2 is the symbolic rule table of the vision packages (vision.hpp).
namespace cell::rapt {

/// One possible result of a rule.
struct RuleOutcome {
  RelType type = RelType::kFix;
  bool looser = false;  ///< Table 2's '*': weaker than the true result
};

/// One row of Table 1 or Table 2.
struct RuleEntry {
  RelType first = RelType::kFix;
  RelType second = RelType::kFix;
  std::optional<RuleOutcome> general;  ///< nullopt: '-' (not one of the types)
  bool two_solutions = false;          ///< "(2)"
  std::array<std::optional<RuleOutcome>, 3> special{};
  bool special_rotylin = false;  ///< AGPP+AGPC's "ROT+LIN" (ROTYLIN)

  /// True when `type` is the general or a special result.
  bool admits(RelType type) const noexcept;
};

/// Table 1: the combination rule for a 2-cycle of types (a, b) in either order, or nullptr.
const RuleEntry* combination_rule(RelType a, RelType b) noexcept;

/// Table 2: the creation rule for a chain of types (a, b) in either order, or nullptr.
const RuleEntry* creation_rule(RelType a, RelType b) noexcept;

/// All of Table 1 / Table 2 (for printing and tests).
std::span<const RuleEntry> combination_table() noexcept;
std::span<const RuleEntry> creation_table() noexcept;

/// Inputs of the symbolic reasoner: the instantiated types plus AGPE, the restricted AGPC a
/// LOOK creates between a symbolic world face and an edge (thesis §5.2.1).
enum class SymbolicInput : std::uint8_t { kAgpp, kAgpe };

/// The top-level rule functions of the symbolic reasoner; at compile time a symbolic
/// argument makes a call deferred (an expression node), at run time it is evaluated.
enum class SymbolicFunction : std::uint8_t {
  kAgppAgppParallel,  ///< AGPP+AGPP -> AGPP (x_a_parallel; checks the planes coincide)
  kAgppAgppLin,       ///< AGPP+AGPP -> LIN
  kAgppAgpeLin,       ///< AGPP+AGPE -> LIN (two solutions, the one nearer the nominal kept)
  kLinAgpeFix,        ///< LIN+AGPE -> FIX (slide along the LIN until the edge origin is in
                      ///< the symbolic face)
  kLinAgppFix,        ///< LIN+AGPP -> FIX (a third INVIOLATE)
};

/// One row of Table 6.2 (plus LIN+AGPP, which the thesis handles with the ordinary Table 1).
struct SymbolicRule {
  RelType first;
  SymbolicInput second;
  RelType result;
  SymbolicFunction function;
  bool symbolic;          ///< false: '*' in Table 6.2, evaluated at compile time when possible
  const char* condition;  ///< as printed: "general", "x_a_parallel", ...
};

/// Table 6.2 rows.
std::span<const SymbolicRule> symbolic_table() noexcept;

/// The symbolic rule for (current relation type, next input); `parallel` selects the
/// x_a_parallel row of AGPP+AGPP. nullptr when the table has no rule (the package cannot be
/// fixed that way).
const SymbolicRule* symbolic_rule(RelType first, SymbolicInput second, bool parallel) noexcept;

/// Name of a symbolic function as printed in routes ("agpp_agpe_lin").
const char* to_string(SymbolicFunction f) noexcept;

}  // namespace cell::rapt
