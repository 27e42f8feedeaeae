#include "cell/rapt/rule_tables.hpp"

namespace cell::rapt {
namespace {

using R = RelType;
constexpr RuleOutcome O(R t) { return RuleOutcome{t, false}; }
constexpr RuleOutcome L(R t) { return RuleOutcome{t, true}; }  // '*'
constexpr std::optional<RuleOutcome> kNone = std::nullopt;

// Appendix I, Table 1 (combination rules), row by row as printed.
constexpr RuleEntry kCombination[] = {
    {R::kLin, R::kLin, O(R::kFix), false, {O(R::kLin)}},
    {R::kLinlin, R::kLinlin, O(R::kLin), false, {O(R::kLinlin)}},
    {R::kLinlin, R::kLin, O(R::kFix), false, {O(R::kLin)}},
    {R::kRot, R::kRot, O(R::kFix), false, {O(R::kRot)}},
    {R::kRot, R::kLinlin, O(R::kFix), false, {}},
    {R::kRot, R::kLin, O(R::kFix), false, {}},
    {R::kFits, R::kFits, O(R::kFix), false, {O(R::kFits), O(R::kLin)}},
    {R::kFits, R::kRot, O(R::kFix), false, {O(R::kRot)}},
    {R::kFits, R::kLinlin, O(R::kFix), false, {O(R::kLin)}},
    {R::kFits, R::kLin, O(R::kFix), false, {O(R::kLin)}},
    {R::kAgpp, R::kAgpp, O(R::kLin), false, {O(R::kAgpp)}},
    {R::kAgpp, R::kFits, O(R::kFix), false, {O(R::kLin), O(R::kRot)}},
    {R::kAgpp, R::kRot, O(R::kFix), false, {O(R::kRot)}},
    {R::kAgpp, R::kLinlin, O(R::kLin), false, {O(R::kLinlin)}},
    {R::kAgpp, R::kLin, O(R::kFix), false, {O(R::kLin)}},
    {R::kAgpp, R::kAgpc, O(R::kLin), true, {O(R::kAgpp)}, true},
    {R::kParax, R::kParax, kNone, false, {O(R::kParax)}},
    {R::kParax, R::kAgpp, O(R::kLinlin), false, {O(R::kAgpp)}},
    {R::kParax, R::kFits, O(R::kLin), false, {O(R::kFits)}},
    {R::kParax, R::kRot, O(R::kFix), false, {O(R::kRot)}},
    {R::kParax, R::kLinlin, O(R::kLinlin), false, {}},
    {R::kParax, R::kLin, O(R::kLin), false, {}},
    {R::kAgss, R::kAgss, kNone, false, {O(R::kRot), O(R::kAgss)}},
    {R::kAgss, R::kParax, kNone, false, {O(R::kRot)}},
    {R::kAgss, R::kAgpp, kNone, false, {O(R::kRot)}},
    {R::kAgss, R::kFits, kNone, false, {O(R::kRot), O(R::kFix)}},
    {R::kAgss, R::kRot, O(R::kFix), true, {O(R::kRot), O(R::kFix)}},
    {R::kAgss, R::kLinlin, kNone, false, {O(R::kFix)}},
    {R::kAgss, R::kLin, O(R::kFix), true, {O(R::kFix)}},
    {R::kAgps, R::kAgps, kNone, false, {}},
    {R::kAgps, R::kAgss, kNone, false, {O(R::kRot)}},
    {R::kAgps, R::kParax, kNone, false, {O(R::kAgpp)}},
    {R::kAgps, R::kAgpp, kNone, false, {O(R::kAgpp)}},
    {R::kAgps, R::kFits, kNone, false, {O(R::kRot), O(R::kLin)}},
    {R::kAgps, R::kRot, O(R::kFix), true, {O(R::kRot), O(R::kFix)}},
    {R::kAgps, R::kLinlin, O(R::kLin), true, {O(R::kLinlin)}},
    {R::kAgps, R::kLin, O(R::kFix), false, {O(R::kLin)}},
    {R::kAgpc, R::kAgpc, kNone, false, {O(R::kAgpp)}},
    {R::kAgpc, R::kAgps, kNone, false, {O(R::kAgpp)}},
    {R::kAgpc, R::kAgss, kNone, false, {O(R::kRot)}},
    {R::kAgpc, R::kParax, O(R::kLinlin), true, {O(R::kRot), O(R::kFix)}},
    {R::kAgpc, R::kFits, O(R::kFix), true, {O(R::kFits), O(R::kRot), O(R::kLin)}},
    {R::kAgpc, R::kRot, O(R::kFix), true, {O(R::kRot), O(R::kFix)}},
    {R::kAgpc, R::kLinlin, O(R::kLin), false, {O(R::kLinlin)}},
    {R::kAgpc, R::kLin, O(R::kFix), false, {O(R::kLin)}},
};

// Appendix I, Table 2 (creation rules).
constexpr RuleEntry kCreation[] = {
    {R::kLin, R::kLin, O(R::kLinlin), false, {O(R::kLin)}},
    {R::kLinlin, R::kLinlin, L(R::kParax), false, {O(R::kLinlin)}},
    {R::kLinlin, R::kLin, L(R::kParax), false, {O(R::kLinlin)}},
    {R::kRot, R::kRot, kNone, false, {O(R::kRot)}},
    {R::kRot, R::kLinlin, L(R::kParax), false, {O(R::kAgpp)}},
    {R::kRot, R::kLin, L(R::kParax), false, {O(R::kFits)}},
    {R::kFits, R::kFits, kNone, false, {O(R::kFits), L(R::kParax)}},
    {R::kFits, R::kRot, kNone, false, {O(R::kFits), O(R::kAgpc), L(R::kParax)}},
    {R::kFits, R::kLinlin, kNone, false, {O(R::kParax)}},
    {R::kFits, R::kLin, kNone, false, {O(R::kFits), L(R::kParax)}},
    {R::kAgpp, R::kAgpp, kNone, false, {O(R::kAgpp)}},
    {R::kAgpp, R::kFits, kNone, false, {O(R::kParax), O(R::kAgpc)}},
    {R::kAgpp, R::kRot, kNone, false, {O(R::kAgpp)}},
    {R::kAgpp, R::kLinlin, O(R::kParax), false, {O(R::kAgpp)}},
    {R::kAgpp, R::kLin, O(R::kParax), false, {O(R::kAgpp)}},
    {R::kParax, R::kParax, kNone, false, {O(R::kParax)}},
    {R::kParax, R::kFits, kNone, false, {O(R::kParax)}},
    {R::kParax, R::kRot, kNone, false, {O(R::kParax)}},
    {R::kParax, R::kLinlin, O(R::kParax), false, {}},
    {R::kParax, R::kLin, O(R::kParax), false, {}},
    {R::kAgss, R::kAgss, kNone, false, {O(R::kAgss)}},
    {R::kAgss, R::kAgpp, kNone, false, {O(R::kAgps)}},
    {R::kAgss, R::kRot, kNone, false, {O(R::kAgss)}},
    {R::kAgps, R::kAgss, kNone, false, {O(R::kAgps)}},
    {R::kAgps, R::kAgpp, kNone, false, {O(R::kAgps)}},
    {R::kAgps, R::kRot, kNone, false, {O(R::kAgps)}},
    {R::kAgps, R::kLinlin, kNone, false, {O(R::kAgps)}},
    {R::kAgps, R::kLin, kNone, false, {O(R::kAgps)}},
    {R::kAgpc, R::kAgss, kNone, false, {O(R::kAgps)}},
    {R::kAgpc, R::kAgpp, kNone, false, {O(R::kAgpc)}},
    {R::kAgpc, R::kFits, kNone, false, {O(R::kAgpc)}},
    {R::kAgpc, R::kRot, kNone, false, {O(R::kAgpc)}},
    {R::kAgpc, R::kLin, kNone, false, {O(R::kAgpc)}},
};

// Table 6.2 (symbolic reasoning rules), plus LIN+AGPP for a third INVIOLATE (Table 1's
// AGPP+LIN -> FIX, non-symbolic).
constexpr SymbolicRule kSymbolic[] = {
    {R::kAgpp, SymbolicInput::kAgpp, R::kAgpp, SymbolicFunction::kAgppAgppParallel, false,
     "x_a_parallel"},
    {R::kAgpp, SymbolicInput::kAgpp, R::kLin, SymbolicFunction::kAgppAgppLin, false, "general"},
    {R::kAgpp, SymbolicInput::kAgpe, R::kLin, SymbolicFunction::kAgppAgpeLin, true,
     "x_b_perpendicular / general"},
    {R::kLin, SymbolicInput::kAgpe, R::kFix, SymbolicFunction::kLinAgpeFix, true,
     "x_a_parallel, merged with the general case"},
    {R::kLin, SymbolicInput::kAgpp, R::kFix, SymbolicFunction::kLinAgppFix, false, "general"},
};

const RuleEntry* find(std::span<const RuleEntry> table, RelType a, RelType b) noexcept {
  for (const RuleEntry& e : table) {
    if ((e.first == a && e.second == b) || (e.first == b && e.second == a)) {
      return &e;
    }
  }
  return nullptr;
}

}  // namespace

bool RuleEntry::admits(RelType type) const noexcept {
  if (general && general->type == type) {
    return true;
  }
  for (const auto& s : special) {
    if (s && s->type == type) {
      return true;
    }
  }
  return false;
}

const RuleEntry* combination_rule(RelType a, RelType b) noexcept {
  return find(kCombination, a, b);
}

const RuleEntry* creation_rule(RelType a, RelType b) noexcept { return find(kCreation, a, b); }

std::span<const RuleEntry> combination_table() noexcept { return kCombination; }
std::span<const RuleEntry> creation_table() noexcept { return kCreation; }
std::span<const SymbolicRule> symbolic_table() noexcept { return kSymbolic; }

const SymbolicRule* symbolic_rule(RelType first, SymbolicInput second, bool parallel) noexcept {
  for (const SymbolicRule& r : kSymbolic) {
    if (r.first != first || r.second != second) {
      continue;
    }
    if (r.function == SymbolicFunction::kAgppAgppParallel && !parallel) {
      continue;
    }
    if (r.function == SymbolicFunction::kAgppAgppLin && parallel) {
      continue;
    }
    return &r;
  }
  return nullptr;
}

const char* to_string(SymbolicFunction f) noexcept {
  switch (f) {
    case SymbolicFunction::kAgppAgppParallel:
      return "agpp_agpp_parallel";
    case SymbolicFunction::kAgppAgppLin:
      return "agpp_agpp_lin";
    case SymbolicFunction::kAgppAgpeLin:
      return "agpp_agpe_lin";
    case SymbolicFunction::kLinAgpeFix:
      return "lin_agpe_fix";
    case SymbolicFunction::kLinAgppFix:
      return "lin_agpp_fix";
  }
  return "?";
}

}  // namespace cell::rapt
