#include "cell/rapt/nominal.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

#include "cell/rapt/rule_tables.hpp"

namespace cell::rapt {

const std::optional<Pose>& NominalSolution::pose(int body, int situation) const {
  static const std::optional<Pose> kNone;
  if (body < 1 || body > bodies || situation < 1 || situation > situations) {
    return kNone;
  }
  return poses[static_cast<std::size_t>(body - 1) * static_cast<std::size_t>(situations) +
               static_cast<std::size_t>(situation - 1)];
}

bool NominalSolution::complete() const {
  return std::all_of(poses.begin(), poses.end(), [](const auto& p) { return p.has_value(); });
}

namespace {

struct Arc {
  Relation rel;
  bool alive = true;
  int id = 0;
};

/// A TIE: after the action, `to_b` keeps the pose relative to `to_a` that `from_b` had
/// relative to `from_a` (digest §1.3: tied bodies keep their relative position).
struct TieLink {
  int from_a = 0;
  int from_b = 0;
  int to_a = 0;
  int to_b = 0;
  SourceLoc loc;  ///< the action
  bool done = false;
};

std::string situations_text(const std::vector<int>& s) {
  if (s.size() == 1) {
    return fmt::format("situation {}", s.front());
  }
  bool contiguous = true;
  for (std::size_t i = 1; i < s.size(); ++i) {
    contiguous = contiguous && s[i] == s[i - 1] + 1;
  }
  if (contiguous) {
    return fmt::format("situations {}-{}", s.front(), s.back());
  }
  std::string out = "situations ";
  for (std::size_t i = 0; i < s.size(); ++i) {
    out += (i > 0 ? ", " : "") + std::to_string(s[i]);
  }
  return out;
}

class Engine {
 public:
  Engine(const Program& program, Diagnostics& diags, const NominalOptions& options)
      : p_(program), d_(diags), o_(options), s_(program.situation_count()) {
    const std::size_t n = static_cast<std::size_t>(p_.body_count()) * static_cast<std::size_t>(s_);
    parent_.resize(n);
    parent_T_.assign(n, Pose::Identity());
    for (std::size_t i = 0; i < n; ++i) {
      parent_[i] = static_cast<int>(i);
    }
  }

  NominalSolution run() {
    build();
    int rounds = 0;
    for (; rounds < o_.max_rounds; ++rounds) {
      if (links_pass() || combine_pass()) {
        continue;
      }
      if (!creation_pass()) {
        break;
      }
    }
    NominalSolution out;
    out.bodies = p_.body_count();
    out.situations = s_;
    out.poses.resize(parent_.size());
    out.combinations = combinations_;
    out.creations = creations_;
    out.merges = merges_;
    for (std::size_t i = 0; i < parent_.size(); ++i) {
      const auto [root, root_T_node] = find(static_cast<int>(i));
      if (root == 0) {
        out.poses[i] = root_T_node;
      }
    }
    report_undetermined();
    return out;
  }

 private:
  // --- network -------------------------------------------------------------------------------

  int node(int body, int situation) const { return (body - 1) * s_ + (situation - 1); }
  int body_of(int n) const { return n / s_ + 1; }
  int situation_of(int n) const { return n % s_ + 1; }
  std::string node_name(int n) const {
    return fmt::format("{}@{}", p_.body(body_of(n)).name, situation_of(n));
  }

  std::pair<int, Pose> find(int x) {
    std::vector<int> path;
    int r = x;
    while (parent_[static_cast<std::size_t>(r)] != r) {
      path.push_back(r);
      r = parent_[static_cast<std::size_t>(r)];
    }
    for (auto it = path.rbegin(); it != path.rend(); ++it) {
      const auto n = static_cast<std::size_t>(*it);
      const int p = parent_[n];
      if (p != r) {
        parent_T_[n] = parent_T_[static_cast<std::size_t>(p)] * parent_T_[n];
      }
      parent_[n] = r;
    }
    return {r, x == r ? Pose::Identity() : parent_T_[static_cast<std::size_t>(x)]};
  }

  /// Merges y into x's group (or the reverse, keeping the lower node as root) with the known
  /// x_T_y; if they are already one group, checks that x_T_y agrees.
  void unite(int x, int y, const Pose& x_T_y, const std::vector<SourceLoc>& sources) {
    const auto [rx, rx_T_x] = find(x);
    const auto [ry, ry_T_y] = find(y);
    if (rx == ry) {
      const Pose diff = (rx_T_x * x_T_y).inverse() * ry_T_y;
      const double mm = diff.translation().norm();
      const double rad = Eigen::AngleAxisd(diff.linear()).angle();
      if (mm > o_.tolerances.linear_mm || rad > o_.tolerances.angular_rad) {
        report_incompatible(sources, mm, rad, "");
      }
      return;
    }
    const Pose rx_T_ry = rx_T_x * x_T_y * ry_T_y.inverse();
    ++merges_;
    if (rx < ry) {
      attach(ry, rx, rx_T_ry);
    } else {
      attach(rx, ry, rx_T_ry.inverse());
    }
  }

  /// Makes `child` (a root) a child of `root` with root_T_child, and moves its arcs.
  void attach(int child, int root, const Pose& root_T_child) {
    parent_[static_cast<std::size_t>(child)] = root;
    parent_T_[static_cast<std::size_t>(child)] = root_T_child;
    for (Arc& arc : arcs_) {
      if (!arc.alive) {
        continue;
      }
      if (arc.rel.a == child) {
        arc.rel.a = root;
        arc.rel.a_T_fa = root_T_child * arc.rel.a_T_fa;
      }
      if (arc.rel.b == child) {
        arc.rel.b = root;
        arc.rel.b_T_fb = root_T_child * arc.rel.b_T_fb;
      }
      if (arc.rel.a == arc.rel.b) {
        check_closed(arc);
      }
    }
  }

  /// An arc whose two ends are merged: it must hold at the known relative pose.
  void check_closed(Arc& arc) {
    arc.alive = false;
    const auto [rad, mm] = residual(arc.rel, Pose::Identity());
    if (mm > o_.tolerances.linear_mm || rad > o_.tolerances.angular_rad) {
      report_incompatible(arc.rel.sources, mm, rad, to_string(arc.rel.type));
    }
  }

  void add_arc(Relation r) {
    const auto [ra, ra_T_a] = find(r.a);
    const auto [rb, rb_T_b] = find(r.b);
    r.a = ra;
    r.b = rb;
    r.a_T_fa = ra_T_a * r.a_T_fa;
    r.b_T_fb = rb_T_b * r.b_T_fb;
    Arc arc{std::move(r), true, next_id_++};
    if (arc.rel.a == arc.rel.b) {
      check_closed(arc);
      return;
    }
    arcs_.push_back(std::move(arc));
  }

  // --- building the network ------------------------------------------------------------------

  void note_source(SourceLoc loc, std::string text) {
    source_text_.emplace(std::pair{loc.line, loc.column}, std::move(text));
  }

  std::string source_text(SourceLoc loc) const {
    const auto it = source_text_.find({loc.line, loc.column});
    return it == source_text_.end() ? to_string(loc)
                                    : fmt::format("{} (at {})", it->second, to_string(loc));
  }

  Relation from_decl(const RelationDecl& decl, int s) {
    Relation r = relation_of(p_, decl);
    r.a = node(decl.a.body, s);
    r.b = node(decl.b.body, s);
    note_source(decl.loc, fmt::format("{}/{}, {} in situation {}", to_string(decl.kind),
                                      p_.feature_name(decl.a), p_.feature_name(decl.b), s));
    return r;
  }

  void build() {
    for (int s = 2; s <= s_; ++s) {
      unite(node(kWorld, 1), node(kWorld, s), Pose::Identity(), {});
    }
    for (int s = 1; s <= s_; ++s) {
      const Situation& sit = p_.situation(s);
      if (s > 1) {
        build_action(sit);
      }
      for (const RelationDecl& decl : sit.relations) {
        add_arc(from_decl(decl, s));
      }
      for (const int k : p_.subass_after[static_cast<std::size_t>(s - 1)]) {
        for (const RelationDecl& decl : p_.subassemblies[static_cast<std::size_t>(k)].relations) {
          add_arc(from_decl(decl, s));
        }
      }
    }
  }

  void build_action(const Situation& sit) {
    const int s = sit.number;
    const Action& act = sit.action;
    const auto& moved = p_.moved[static_cast<std::size_t>(s - 1)];
    for (const Body& b : p_.bodies) {
      if (b.number != kWorld && std::find(moved.begin(), moved.end(), b.number) == moved.end()) {
        unite(node(b.number, s - 1), node(b.number, s), Pose::Identity(), {act.loc});
      }
    }
    if (moved.empty()) {
      return;  // vision package (or an action with errors)
    }
    const char* verb = act.kind == ActionKind::kTurn ? "TURN" : "MOVE";
    note_source(act.loc, fmt::format("{}/{} (situation {})", verb, p_.body(act.body).name, s));
    const int m0 = node(act.body, s - 1);
    const int m1 = node(act.body, s);
    if (act.feature) {
      const Feature& f = p_.feature(*act.feature);
      const Pose& bf = f.body_T_feature;
      if (act.amount) {
        // Explicit: the instance after is fixed to the one before (thesis (3.4)).
        const Pose motion = act.kind == ActionKind::kTurn
                                ? Pose(bf * rot_x(*act.amount) * bf.inverse())
                                : translation(*act.amount * f.axis());
        unite(m0, m1, motion, {act.loc});
      } else {
        Relation r;
        r.a = m0;
        r.b = m1;
        r.a_T_fa = bf;
        r.b_T_fb = bf;
        r.sources = {act.loc};
        if (act.kind == ActionKind::kTurn) {
          r.type = RelType::kRot;
        } else if (act.mode == ast::ActionMode::kParlel && f.type == FeatureType::kFace) {
          r.type = RelType::kLinlin;
        } else {
          r.type = RelType::kLin;
        }
        add_arc(std::move(r));
      }
    }
    // Bodies TIED to the mover follow it: link each to the body it was reached from.
    const auto& ties = p_.ties_after[static_cast<std::size_t>(s - 2)];
    std::vector<int> reached{act.body};
    for (std::size_t k = 0; k < reached.size(); ++k) {
      for (const auto& [x, y] : ties) {
        const int from = reached[k];
        const int other = x == from ? y : (y == from ? x : 0);
        if (other == 0 || other == kWorld ||
            std::find(reached.begin(), reached.end(), other) != reached.end()) {
          continue;
        }
        reached.push_back(other);
        links_.push_back(
            TieLink{node(from, s - 1), node(other, s - 1), node(from, s), node(other, s), act.loc});
        note_source(act.loc, fmt::format("{}/{} with {} TIED to {} (situation {})", verb,
                                         p_.body(act.body).name, p_.body(other).name,
                                         p_.body(from).name, s));
      }
    }
  }

  // --- passes --------------------------------------------------------------------------------

  bool links_pass() {
    bool progress = false;
    for (TieLink& link : links_) {
      if (link.done) {
        continue;
      }
      const auto [ra, ra_T_a] = find(link.from_a);
      const auto [rb, rb_T_b] = find(link.from_b);
      if (ra != rb) {
        continue;
      }
      link.done = true;
      unite(link.to_a, link.to_b, ra_T_a.inverse() * rb_T_b, {link.loc});
      progress = true;
    }
    return progress;
  }

  void block(int a, int b, std::string note) {
    auto& notes = blocked_[{std::min(a, b), std::max(a, b)}];
    if (std::find(notes.begin(), notes.end(), note) == notes.end()) {
      notes.push_back(std::move(note));
    }
  }

  bool combine_pass() {
    std::map<std::pair<int, int>, std::vector<std::size_t>> groups;
    for (std::size_t i = 0; i < arcs_.size(); ++i) {
      const Arc& arc = arcs_[i];
      if (arc.alive) {
        groups[{std::min(arc.rel.a, arc.rel.b), std::max(arc.rel.a, arc.rel.b)}].push_back(i);
      }
    }
    for (auto& [key, members] : groups) {
      for (const std::size_t i : members) {
        if (arcs_[i].rel.type == RelType::kFix) {
          arcs_[i].alive = false;
          unite(arcs_[i].rel.a, arcs_[i].rel.b, fixed_pose(arcs_[i].rel), arcs_[i].rel.sources);
          return true;
        }
      }
      bool changed = true;
      bool progress = false;
      while (changed) {
        changed = false;
        for (std::size_t x = 0; x < members.size() && !changed; ++x) {
          for (std::size_t y = x + 1; y < members.size() && !changed; ++y) {
            Arc& ai = arcs_[members[x]];
            Arc& aj = arcs_[members[y]];
            if (!ai.alive || !aj.alive) {
              continue;
            }
            const std::string pair =
                fmt::format("{}+{}", to_string(ai.rel.type), to_string(aj.rel.type));
            const RuleEntry* rule = combination_rule(ai.rel.type, aj.rel.type);
            if (rule == nullptr) {
              block(key.first, key.second, pair + " has no combination rule (Table 1)");
              continue;
            }
            SolveResult res = intersect(ai.rel, aj.rel, o_.tolerances);
            switch (res.outcome) {
              case Outcome::kOk:
                if (!rule->admits(res.relation.type)) {
                  block(key.first, key.second,
                        fmt::format("{} gives {}, which Table 1 does not list", pair,
                                    to_string(res.relation.type)));
                  continue;
                }
                ai.rel = std::move(res.relation);
                aj.alive = false;
                ++combinations_;
                changed = progress = true;
                if (ai.rel.type == RelType::kFix) {
                  ai.alive = false;
                  unite(ai.rel.a, ai.rel.b, fixed_pose(ai.rel), ai.rel.sources);
                  return true;
                }
                break;
              case Outcome::kIncompatible: {
                std::vector<SourceLoc> sources = ai.rel.sources;
                sources.insert(sources.end(), aj.rel.sources.begin(), aj.rel.sources.end());
                report_incompatible(sources, res.residual_mm, res.residual_rad, res.detail);
                aj.alive = false;
                changed = progress = true;
                break;
              }
              case Outcome::kTwoSolutions:
                block(key.first, key.second,
                      fmt::format("{} has two solutions (Table 1 '(2)'): {}", pair, res.detail));
                break;
              case Outcome::kInexpressible:
                block(key.first, key.second, fmt::format("{}: {}", pair, res.detail));
                break;
            }
          }
        }
      }
      if (progress) {
        return true;
      }
    }
    return false;
  }

  bool connected_without(int from, int to, int excluded) const {
    std::vector<int> stack{from};
    std::set<int> seen{from, excluded};
    while (!stack.empty()) {
      const int n = stack.back();
      stack.pop_back();
      if (n == to) {
        return true;
      }
      for (const Arc& arc : arcs_) {
        if (!arc.alive) {
          continue;
        }
        const int other = arc.rel.a == n ? arc.rel.b : (arc.rel.b == n ? arc.rel.a : -1);
        if (other >= 0 && seen.insert(other).second) {
          stack.push_back(other);
        }
      }
    }
    return false;
  }

  bool creation_pass() {
    if (created_ >= o_.max_created) {
      return false;
    }
    for (std::size_t i = 0; i < arcs_.size(); ++i) {
      for (std::size_t j = 0; j < arcs_.size(); ++j) {
        if (i == j || !arcs_[i].alive || !arcs_[j].alive) {
          continue;
        }
        const Relation& r1 = arcs_[i].rel;
        const Relation& r2 = arcs_[j].rel;
        // Shared middle node m (not the world), distinct outer nodes.
        for (const int m : {r1.a, r1.b}) {
          if (m == 0 || (r2.a != m && r2.b != m)) {
            continue;
          }
          const int p = r1.a == m ? r1.b : r1.a;
          const int q = r2.a == m ? r2.b : r2.a;
          if (p == q || p == m || q == m) {
            continue;
          }
          const std::tuple<int, int, int> key{arcs_[i].id, arcs_[j].id, m};
          if (!tried_.insert(key).second) {
            continue;
          }
          const RuleEntry* rule = creation_rule(r1.type, r2.type);
          if (rule == nullptr || !connected_without(p, q, m)) {
            continue;
          }
          const Relation r12 = r1.b == m ? r1 : reversed(r1);
          const Relation r23 = r2.a == m ? r2 : reversed(r2);
          SolveResult res = compose(r12, r23, o_.tolerances);
          if (res.outcome != Outcome::kOk || !rule->admits(res.relation.type)) {
            continue;
          }
          ++creations_;
          ++created_;
          arcs_.push_back(Arc{std::move(res.relation), true, next_id_++});
          return true;
        }
      }
    }
    return false;
  }

  // --- reports -------------------------------------------------------------------------------

  void report_incompatible(const std::vector<SourceLoc>& sources,
                           double mm,
                           double rad,
                           const std::string& detail) {
    std::vector<SourceLoc> unique;
    for (const SourceLoc& l : sources) {
      if (l.known() && std::find(unique.begin(), unique.end(), l) == unique.end()) {
        unique.push_back(l);
      }
    }
    std::sort(unique.begin(), unique.end(), [](const SourceLoc& x, const SourceLoc& y) {
      return std::tie(x.line, x.column) < std::tie(y.line, y.column);
    });
    std::vector<std::pair<std::uint32_t, std::uint32_t>> key;
    key.reserve(unique.size());
    for (const SourceLoc& l : unique) {
      key.emplace_back(l.line, l.column);
    }
    if (!reported_.insert(key).second) {
      return;
    }
    std::string list;
    for (const SourceLoc& l : unique) {
      list += (list.empty() ? "" : "; ") + source_text(l);
    }
    const SourceLoc at = unique.empty() ? SourceLoc{} : unique.back();
    const std::string off = fmt::format(
        "off by {:.4g} mm, {:.4g} deg; tolerance {:.3g} mm, {:.3g} deg", mm, rad * 180.0 / M_PI,
        o_.tolerances.linear_mm, o_.tolerances.angular_rad * 180.0 / M_PI);
    if (unique.size() <= 1) {
      d_.error(at, fmt::format("inconsistent program: the relation {} does not hold at the "
                               "positions fixed by the other relations ({}{})",
                               list.empty() ? std::string("here") : list,
                               detail.empty() ? "" : detail + ": ", off));
    } else {
      d_.error(at, fmt::format("inconsistent program: the relations {} are incompatible ({}{})",
                               list, detail.empty() ? "" : detail + ": ", off));
    }
  }

  void report_undetermined() {
    std::map<int, std::vector<int>> groups;  // root -> nodes
    for (int b = 2; b <= p_.body_count(); ++b) {
      for (int s = 1; s <= s_; ++s) {
        const int n = node(b, s);
        const int root = find(n).first;
        if (root != 0) {
          groups[root].push_back(n);
        }
      }
    }
    for (const auto& [root, nodes] : groups) {
      std::map<int, std::vector<int>> by_body;
      for (const int n : nodes) {
        by_body[body_of(n)].push_back(situation_of(n));
      }
      std::string who;
      for (const auto& [b, sits] : by_body) {
        who += (who.empty() ? "" : ", ") +
               fmt::format("{} in {}", p_.body(b).name, situations_text(sits));
      }
      std::string why;
      for (const Arc& arc : arcs_) {
        if (!arc.alive || (arc.rel.a != root && arc.rel.b != root)) {
          continue;
        }
        const int other = arc.rel.a == root ? arc.rel.b : arc.rel.a;
        std::string from;
        for (const SourceLoc& l : arc.rel.sources) {
          from += (from.empty() ? "" : ", ") + source_text(l);
        }
        why += fmt::format("; {} ({} translational, {} rotational freedoms) with {} from {}",
                           to_string(arc.rel.type), dof(arc.rel.type).translational,
                           dof(arc.rel.type).rotational,
                           other == 0 ? std::string("the world") : node_name(other),
                           from.empty() ? std::string("a TIE") : from);
      }
      for (const auto& [pair, notes] : blocked_) {
        if (pair.first == root || pair.second == root) {
          for (const std::string& note : notes) {
            why += "; " + note;
          }
        }
      }
      if (why.empty()) {
        why = "; no relation, explicit action or TIE connects it to the rest of the world";
      }
      // Report at the action that created the first undetermined instance, or the body.
      const int first = nodes.front();
      const int s = situation_of(first);
      const int b = body_of(first);
      SourceLoc at = p_.body(b).loc;
      if (s > 1 && p_.situation(s).action.loc.known()) {
        at = p_.situation(s).action.loc;
      }
      for (int k = s; k >= 2; --k) {  // the MOVE that last moved this body
        if (p_.is_moved(b, k)) {
          at = p_.situation(k).action.loc;
          break;
        }
      }
      d_.error(at, fmt::format("under-constrained program: the position of {} is not determined "
                               "relative to the world{}",
                               who, why));
    }
  }

  const Program& p_;
  Diagnostics& d_;
  const NominalOptions& o_;
  int s_;
  std::vector<int> parent_;
  std::vector<Pose> parent_T_;  ///< parent_T_node
  std::vector<Arc> arcs_;
  std::vector<TieLink> links_;
  std::map<std::pair<int, int>, std::vector<std::string>> blocked_;
  std::map<std::pair<std::uint32_t, std::uint32_t>, std::string> source_text_;
  std::set<std::vector<std::pair<std::uint32_t, std::uint32_t>>> reported_;
  std::set<std::tuple<int, int, int>> tried_;
  int next_id_ = 0;
  int combinations_ = 0;
  int creations_ = 0;
  int created_ = 0;
  int merges_ = 0;
};

}  // namespace

Relation relation_of(const Program& program, const RelationDecl& decl) {
  const Feature& fa = program.feature(decl.a);
  const Feature& fb = program.feature(decl.b);
  Relation r;
  r.a = decl.a.body;
  r.b = decl.b.body;
  r.a_T_fa = fa.body_T_feature;
  r.b_T_fb = fb.body_T_feature;
  r.sources = {decl.loc};
  switch (decl.kind) {
    case RelKeyword::kAgainst:
      if (fa.type == FeatureType::kFace && fb.type == FeatureType::kFace) {
        r.type = RelType::kAgpp;
      } else if (fa.type == FeatureType::kFace || fb.type == FeatureType::kFace) {
        const Feature& other = fa.type == FeatureType::kFace ? fb : fa;
        r.type = other.cylindrical() ? RelType::kAgpc : RelType::kAgps;
        r.offset = other.radius;
        r.plane_on_b = fa.type != FeatureType::kFace;
      } else {
        r.type = RelType::kAgss;
        r.offset = fa.radius + fb.radius;
      }
      break;
    case RelKeyword::kCoplanar:  // AGPP with one normal flipped (digest §1.5)
      r.type = RelType::kAgpp;
      r.b_T_fb = r.b_T_fb * flip_x();
      break;
    case RelKeyword::kFits:
      r.type = RelType::kFits;
      break;
    case RelKeyword::kAligned:  // FITS after flipping a direction
      r.type = RelType::kFits;
      r.b_T_fb = r.b_T_fb * flip_x();
      break;
    case RelKeyword::kParax:
      r.type = RelType::kParax;
      break;
    case RelKeyword::kParallel:  // PARAX after flipping a direction
      r.type = RelType::kParax;
      r.b_T_fb = r.b_T_fb * flip_x();
      break;
  }
  return r;
}

std::pair<double, double> relation_residual(const Program& program,
                                            const RelationDecl& decl,
                                            const Pose& world_T_a,
                                            const Pose& world_T_b) {
  return residual(relation_of(program, decl), Pose(world_T_a.inverse() * world_T_b));
}

NominalSolution infer_nominal(const Program& program,
                              Diagnostics& diags,
                              const NominalOptions& options) {
  if (program.situation_count() == 0) {
    return {};
  }
  Engine engine(program, diags, options);
  return engine.run();
}

}  // namespace cell::rapt
