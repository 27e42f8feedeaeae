#include "cell/rapt/mf_array.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <functional>
#include <map>
#include <set>

#include "cell/common/check.hpp"

namespace cell::rapt {

MfEntry MfEntry::verified(int package) {
  MfEntry e;
  e.kind = Kind::kVerified;
  e.package = package;
  return e;
}

MfEntry MfEntry::points_to(int body, int situation) {
  MfEntry e;
  e.kind = Kind::kPointer;
  e.pointer = MfRef{body, situation};
  return e;
}

MfEntry MfEntry::triple_of(int body, int situation, int via_body) {
  MfEntry e;
  e.kind = Kind::kTriple;
  e.triple = {MfRef{body, situation - 1}, MfRef{via_body, situation - 1},
              MfRef{via_body, situation}};
  return e;
}

MfArray::MfArray(int bodies, int situations)
    : bodies_(bodies),
      situations_(situations),
      entries_(static_cast<std::size_t>(bodies) * static_cast<std::size_t>(situations)) {}

MfEntry& MfArray::at(int body, int situation) {
  CELL_CHECK(body >= 1 && body <= bodies_ && situation >= 1 && situation <= situations_);
  return entries_[static_cast<std::size_t>(body - 1) * static_cast<std::size_t>(situations_) +
                  static_cast<std::size_t>(situation - 1)];
}

const MfEntry& MfArray::at(int body, int situation) const {
  CELL_CHECK(body >= 1 && body <= bodies_ && situation >= 1 && situation <= situations_);
  return entries_[static_cast<std::size_t>(body - 1) * static_cast<std::size_t>(situations_) +
                  static_cast<std::size_t>(situation - 1)];
}

namespace {

std::string format_entry(const MfEntry& e,
                         int body,
                         int situation,
                         const std::function<std::string(int)>& name) {
  switch (e.kind) {
    case MfEntry::Kind::kIdentity:
      return "I";
    case MfEntry::Kind::kVerified:
      return "P";
    case MfEntry::Kind::kPointer:
      return fmt::format("{},{}", name(e.pointer.body), e.pointer.situation);
    case MfEntry::Kind::kTriple: {
      const auto& t = e.triple;
      if (t[0] == MfRef{body, situation - 1} && t[1].body == t[2].body &&
          t[1].situation == situation - 1 && t[2].situation == situation) {
        return fmt::format("[{},{}]", name(t[2].body), situation);
      }
      return fmt::format("[({},{}),({},{}),({},{})]", name(t[0].body), t[0].situation,
                         name(t[1].body), t[1].situation, name(t[2].body), t[2].situation);
    }
  }
  return "?";
}

}  // namespace

std::string MfArray::notation(int body, int situation) const {
  return format_entry(at(body, situation), body, situation,
                      [](int b) { return std::to_string(b); });
}

std::string MfArray::named(int body, int situation, const std::vector<std::string>& names) const {
  return format_entry(at(body, situation), body, situation, [&](int b) {
    return b >= 1 && b <= static_cast<int>(names.size()) ? names[static_cast<std::size_t>(b - 1)]
                                                         : std::to_string(b);
  });
}

// --- resolution to I -----------------------------------------------------------------------------

namespace {

bool valid(const MfArray& a, MfRef r) {
  return r.body >= 1 && r.body <= a.bodies() && r.situation >= 1 && r.situation <= a.situations();
}

bool resolves(const MfArray& a, MfRef ref, int depth) {
  if (!valid(a, ref) || depth > 4 * (a.bodies() * a.situations() + 1)) {
    return false;
  }
  const MfEntry& e = a.at(ref.body, ref.situation);
  switch (e.kind) {
    case MfEntry::Kind::kIdentity:
      return true;
    case MfEntry::Kind::kVerified:
      return false;
    case MfEntry::Kind::kPointer:
      return resolves(a, e.pointer, depth + 1);  // rule 1
    case MfEntry::Kind::kTriple: {
      const bool i1 = resolves(a, e.triple[0], depth + 1);
      const bool i2 = resolves(a, e.triple[1], depth + 1);
      const bool i3 = resolves(a, e.triple[2], depth + 1);
      if (i1 && i2) {
        return i3;  // rule 2: the triple is p3
      }
      const MfEntry& p3 = a.at(e.triple[2].body, e.triple[2].situation);
      const bool p3_to_p2 = p3.kind == MfEntry::Kind::kPointer && p3.pointer == e.triple[1];
      if ((i2 && i3) || p3_to_p2) {
        return i1;  // rule 3: the triple is p1
      }
      return false;
    }
  }
  return false;
}

}  // namespace

bool resolves_to_identity(const MfArray& array, MfRef ref) { return resolves(array, ref, 0); }

MfArray simplify(const MfArray& array) {
  MfArray out = array;
  bool changed = true;
  while (changed) {
    changed = false;
    for (int b = 1; b <= out.bodies(); ++b) {
      for (int s = 1; s <= out.situations(); ++s) {
        MfEntry& e = out.at(b, s);
        if (e.kind == MfEntry::Kind::kPointer && resolves_to_identity(out, e.pointer)) {
          e = MfEntry::identity();  // rule 1
          changed = true;
        } else if (e.kind == MfEntry::Kind::kTriple) {
          const auto t = e.triple;
          const bool i1 = resolves_to_identity(out, t[0]);
          const bool i2 = resolves_to_identity(out, t[1]);
          const bool i3 = resolves_to_identity(out, t[2]);
          const bool p3_to_p2 = valid(out, t[2]) &&
                                out.at(t[2].body, t[2].situation).kind == MfEntry::Kind::kPointer &&
                                out.at(t[2].body, t[2].situation).pointer == t[1];
          if (i1 && i2) {
            e = MfEntry::points_to(t[2].body, t[2].situation);  // rule 2
            changed = true;
          } else if ((i2 && i3) || p3_to_p2) {
            e = MfEntry::points_to(t[0].body, t[0].situation);  // rule 3
            changed = true;
          }
        }
      }
    }
  }
  return out;
}

// --- linking rules -------------------------------------------------------------------------------

namespace {

using Edge = std::pair<int, int>;

Edge edge(int a, int b) { return {std::min(a, b), std::max(a, b)}; }

class Linker {
 public:
  Linker(const LinkInput& in, const std::vector<std::string>& names)
      : in_(in), names_(names), out_{MfArray(in.bodies, in.situations), {}, {}, {}} {}

  LinkResult run() {
    out_.rules.assign(static_cast<std::size_t>(in_.situations),
                      std::vector<std::string>(static_cast<std::size_t>(in_.bodies), "I"));
    // Initiation: situation 1 and the world are I (the default entry).
    if (in_.situations >= 1) {
      apply_changes(1);
    }
    for (int s = 2; s <= in_.situations; ++s) {
      for (int b = 2; b <= in_.bodies; ++b) {
        set(b, s, MfEntry::points_to(b, s - 1), "A1");
      }
      const LinkEvent& ev = in_.events[static_cast<std::size_t>(s - 1)];
      if (ev.kind == LinkEvent::Kind::kMove) {
        move(s, ev);
      } else if (ev.kind == LinkEvent::Kind::kVision) {
        vision(s, ev);
      }
      apply_changes(s);
    }
    return std::move(out_);
  }

 private:
  std::string name(int b) const {
    return b >= 1 && b <= static_cast<int>(names_.size()) ? names_[static_cast<std::size_t>(b - 1)]
                                                          : std::to_string(b);
  }

  void set(int b, int s, MfEntry e, const std::string& rule) {
    out_.array.at(b, s) = e;
    out_.rules[static_cast<std::size_t>(s - 1)][static_cast<std::size_t>(b - 1)] = rule;
  }

  /// Bodies reachable from `b` over active (and, if `lingering`, revoked-but-effective) links.
  std::set<int> component(int b, bool lingering) const {
    std::set<int> seen{b};
    std::vector<int> stack{b};
    while (!stack.empty()) {
      const int x = stack.back();
      stack.pop_back();
      auto visit = [&](const Edge& e) {
        const int other = e.first == x ? e.second : (e.second == x ? e.first : 0);
        if (other != 0 && seen.insert(other).second) {
          stack.push_back(other);
        }
      };
      for (const auto& [e, permanent] : active_) {
        visit(e);
      }
      if (lingering) {
        for (const Edge& e : lingering_) {
          visit(e);
        }
      }
    }
    return seen;
  }

  /// Ends the influence of revoked links touching `piece` (T6, T8).
  void terminate(const std::set<int>& piece) {
    for (auto it = lingering_.begin(); it != lingering_.end();) {
      if (piece.count(it->first) != 0 || piece.count(it->second) != 0) {
        it = lingering_.erase(it);
      } else {
        ++it;
      }
    }
  }

  /// "Both I, or one's entry points to the other" (A2's multi-reference condition), judged on
  /// the entries built so far: equality pointers are followed back to where a body was placed.
  bool same_factor(int x, int y, int s) const {
    const MfArray& a = out_.array;
    if (resolves_to_identity(a, {x, s}) && resolves_to_identity(a, {y, s})) {
      return true;
    }
    auto points_to = [&](int from, int to) {
      MfRef r{from, s};
      while (valid(a, r)) {
        const MfEntry& e = a.at(r.body, r.situation);
        if (e.kind != MfEntry::Kind::kPointer) {
          return false;
        }
        if (e.pointer.body == to) {
          // `to` must not have moved since (its entries back to there are equalities).
          MfRef t{to, s};
          while (t.situation > e.pointer.situation) {
            const MfEntry& te = a.at(t.body, t.situation);
            if (te.kind != MfEntry::Kind::kPointer || te.pointer != MfRef{to, t.situation - 1}) {
              return false;
            }
            --t.situation;
          }
          return true;
        }
        if (e.pointer.body != from) {
          return false;
        }
        r = e.pointer;
      }
      return false;
    };
    return points_to(x, y) || points_to(y, x);
  }

  void move(int s, const LinkEvent& ev) {
    const std::set<int> super = component(ev.body, false);
    const bool group = super.size() > 1;
    if (super.count(1) != 0) {
      // S2 (or a TIE to the world): every member keeps its factor.
      if (ev.specified) {
        out_.warnings.emplace_back(
            ev.loc, fmt::format("rule S2: '{}' belongs to a group TIED to the world, so the "
                                "specified relations of this action may not hold with the "
                                "actual positions",
                                name(ev.body)));
      }
      mark_rule(super, s, "S2");
      return;
    }
    std::vector<int> refs;
    for (const int r : ev.references) {
      if (super.count(r) == 0 && std::find(refs.begin(), refs.end(), r) == refs.end()) {
        refs.push_back(r);
      }
    }
    if (!ev.specified || refs.empty()) {
      mark_rule(super, s, group ? "T4" : "A1");
      return;
    }
    int c = refs.front();
    if (refs.size() > 1) {
      bool ok = true;
      for (std::size_t i = 1; i < refs.size(); ++i) {
        ok = ok && same_factor(refs.front(), refs[i], s);
      }
      if (!ok) {
        // Digest §6.1: the printed Appendix V array uses the world in situation 13 although
        // the first relation names b3; we follow the printed array (the world when it is one
        // of the references, otherwise the first relation's reference, as §8.1.2 writes).
        if (std::find(refs.begin(), refs.end(), 1) != refs.end()) {
          c = 1;
        }
        std::string list;
        for (const int r : refs) {
          list += (list.empty() ? "" : ", ") + name(r);
        }
        out_.warnings.emplace_back(
            ev.loc, fmt::format("rule A2: the destination of '{}' refers to several bodies ({}) "
                                "whose modifying factors are not known to agree (FM*PN ratios may "
                                "differ from the nominal ones); using '{}'",
                                name(ev.body), list, name(c)));
      }
    }
    const int bj = super.count(ev.referenced_member) != 0 ? ev.referenced_member : ev.body;
    set(bj, s, MfEntry::points_to(c, s), group ? "T1" : "A2");
    for (const int x : super) {
      if (x != bj) {
        set(x, s, MfEntry::triple_of(x, s, bj), "T1");
      }
    }
    // T6: the pieces of a broken super TIE linked to this one only by revoked TIEs keep their
    // factors (already A1) and stop influencing it.
    const std::set<int> linked = component(ev.body, true);
    for (const int x : linked) {
      if (super.count(x) == 0) {
        out_.rules[static_cast<std::size_t>(s - 1)][static_cast<std::size_t>(x - 1)] = "T6/T4";
      }
    }
    terminate(super);
  }

  void vision(int s, const LinkEvent& ev) {
    PackageScope scope{ev.package, false, "global"};
    if (!ev.fixable) {
      scope.reason = "cannot fix: ignored at run time";
      out_.scopes.push_back(scope);
      out_.rules[static_cast<std::size_t>(s - 1)][static_cast<std::size_t>(ev.body - 1)] =
          "A1 (cannot fix)";
      return;
    }
    const std::set<int> super = component(ev.body, false);
    const std::set<int> linked = component(ev.body, true);
    for (const int r : ev.inviolate_references) {
      if (r != 1 && linked.count(r) != 0) {
        scope.local = true;
        scope.reason = fmt::format(
            "local: the INVIOLATE reference '{}' is TIED or in a "
            "subassembly with '{}' (thesis §5.3.2, T3)",
            name(r), name(ev.body));
      }
    }
    if (!scope.local && super.count(1) != 0) {
      scope.local = true;
      scope.reason =
          fmt::format("local: '{}' belongs to a super TIE TIED to the world (T9)", name(ev.body));
    }
    // T8: another piece of the broken super TIE was verified since the break -> this piece only.
    std::set<int> affected = linked;
    bool t8 = false;
    for (const int x : linked) {
      if (super.count(x) == 0 && marks_.count(x) != 0) {
        t8 = true;
      }
    }
    if (t8) {
      affected = super;
    }
    for (const int cam : ev.camera_bodies) {
      if (!scope.local && cam != ev.body && affected.count(cam) != 0) {
        scope.local = true;
        scope.reason = fmt::format(
            "local: as a global package it would move its own camera "
            "body '{}' (rule R1)",
            name(cam));
      }
    }
    out_.scopes.push_back(scope);
    if (scope.local) {
      set(ev.body, s, MfEntry::verified(ev.package), "T3");
      return;
    }
    const std::string rule = t8 ? "T8" : (linked.size() > super.size() ? "T7" : "T2");
    set(ev.body, s, MfEntry::verified(ev.package), linked.size() > 1 ? rule : "P");
    for (const int x : affected) {
      if (x != ev.body) {
        set(x, s, MfEntry::triple_of(x, s, ev.body), rule);
      }
    }
    if (t8) {
      for (const int x : linked) {
        if (super.count(x) == 0) {
          out_.rules[static_cast<std::size_t>(s - 1)][static_cast<std::size_t>(x - 1)] = "T8/T4";
        }
      }
      terminate(super);
    }
    marks_.insert(ev.body);
  }

  void mark_rule(const std::set<int>& bodies, int s, const std::string& rule) {
    for (const int x : bodies) {
      if (x != 1) {
        out_.rules[static_cast<std::size_t>(s - 1)][static_cast<std::size_t>(x - 1)] = rule;
      }
    }
  }

  void apply_changes(int s) {
    for (const LinkChange& c : in_.changes[static_cast<std::size_t>(s - 1)]) {
      const Edge e = edge(c.a, c.b);
      if (c.tied) {
        lingering_.erase(e);
        active_[e] = active_[e] || c.permanent;
      } else {
        const auto it = active_.find(e);
        if (it == active_.end() || it->second) {
          continue;  // not tied, or a permanent link
        }
        // A break: the group's verification record starts again (T7, T8 count "since").
        for (const int x : component(c.a, true)) {
          marks_.erase(x);
        }
        active_.erase(it);
        lingering_.insert(e);
      }
    }
  }

  const LinkInput& in_;
  const std::vector<std::string>& names_;
  LinkResult out_;
  std::map<Edge, bool> active_;  ///< links in force -> permanent?
  std::set<Edge> lingering_;     ///< revoked links whose influence has not terminated
  std::set<int> marks_;          ///< bodies verified by global packages since the last break
};

}  // namespace

LinkResult link(const LinkInput& input, const std::vector<std::string>& body_names) {
  LinkInput in = input;
  in.events.resize(static_cast<std::size_t>(in.situations));
  in.changes.resize(static_cast<std::size_t>(in.situations));
  Linker linker(in, body_names);
  return linker.run();
}

namespace mf_equations {

Pose from_verified(const Pose& world_T_nominal, const Pose& world_T_verified) {
  return world_T_nominal.inverse() * world_T_verified;
}

Pose specified(const Pose& pn_a, const Pose& pn_b, const Pose& fm_b) {
  return pn_a.inverse() * pn_b * fm_b * pn_b.inverse() * pn_a;
}

Pose triple(const Pose& fm_b_i,
            const Pose& pn_b_i,
            const Pose& fm_a_i,
            const Pose& pn_a_i,
            const Pose& fm_a_j,
            const Pose& pn_a_j,
            const Pose& pn_b_j) {
  const Pose pv_b_i = pn_b_i * fm_b_i;
  const Pose pv_a_i = pn_a_i * fm_a_i;
  const Pose pv_a_j = pn_a_j * fm_a_j;
  return pn_b_j.inverse() * pv_a_j * pv_a_i.inverse() * pv_b_i;
}

}  // namespace mf_equations

}  // namespace cell::rapt
