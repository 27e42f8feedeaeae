#include "cell/rapt/sema.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <set>

namespace cell::rapt {

// ---------------------------------------------------------------------------------------------
// Model helpers

bool Feature::cylindrical() const noexcept {
  return type == FeatureType::kShaft || type == FeatureType::kHole || type == FeatureType::kEdge;
}

bool Feature::spherical() const noexcept {
  return type == FeatureType::kSphface || type == FeatureType::kVertex;
}

std::pair<Eigen::Vector3d, Eigen::Vector3d> Feature::edge_end_points() const {
  // Digest 003 §2.2 [verified]: second end point = origin + length * X, not the line's end.
  return {origin(), origin() + length * axis()};
}

std::string Program::feature_name(FeatureId id) const {
  if (!id.valid()) {
    return "<invalid feature>";
  }
  return feature(id).name + " of " + body(id.body).name;
}

int Program::find_body(std::string_view name) const {
  for (const Body& b : bodies) {
    if (b.name == name) {
      return b.number;
    }
  }
  return 0;
}

bool Program::is_moved(int body_number, int s) const {
  if (s < 1 || s > situation_count()) {
    return false;
  }
  const auto& m = moved[static_cast<std::size_t>(s - 1)];
  return std::find(m.begin(), m.end(), body_number) != m.end();
}

std::vector<int> Program::unmoved(int s) const {
  std::vector<int> out;
  for (const Body& b : bodies) {
    if (b.number != kWorld && !is_moved(b.number, s)) {
      out.push_back(b.number);
    }
  }
  return out;
}

namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;
constexpr double kMaxMagnitude = 1e9;

/// Which body axis a direction keyword names (0, 1, 2) and its sign.
std::pair<int, double> axis_of(Direction d) {
  switch (d) {
    case Direction::kXLarge:
      return {0, 1.0};
    case Direction::kXSmall:
      return {0, -1.0};
    case Direction::kYLarge:
      return {1, 1.0};
    case Direction::kYSmall:
      return {1, -1.0};
    case Direction::kZLarge:
      return {2, 1.0};
    case Direction::kZSmall:
      return {2, -1.0};
  }
  return {0, 1.0};
}

bool is_face(const Feature& f) { return f.type == FeatureType::kFace; }

/// Table 3.1: is (a, b) a valid feature pair for `kind` (either order)?
bool valid_pair(RelKeyword kind, const Feature& a, const Feature& b) {
  auto pair_is = [&](FeatureType x, FeatureType y) {
    return (a.type == x && b.type == y) || (a.type == y && b.type == x);
  };
  switch (kind) {
    case RelKeyword::kAgainst:
      return pair_is(FeatureType::kFace, FeatureType::kFace) ||
             pair_is(FeatureType::kFace, FeatureType::kShaft) ||
             pair_is(FeatureType::kFace, FeatureType::kEdge) ||
             pair_is(FeatureType::kFace, FeatureType::kVertex) ||
             pair_is(FeatureType::kFace, FeatureType::kSphface) ||
             pair_is(FeatureType::kVertex, FeatureType::kVertex) ||
             pair_is(FeatureType::kSphface, FeatureType::kSphface) ||
             pair_is(FeatureType::kSphface, FeatureType::kVertex);
    case RelKeyword::kCoplanar:
      return is_face(a) && is_face(b);
    case RelKeyword::kFits:
    case RelKeyword::kAligned:
      return a.cylindrical() && b.cylindrical();
    case RelKeyword::kParax:
    case RelKeyword::kParallel:
      return (a.cylindrical() && b.cylindrical()) || (is_face(a) && is_face(b));
  }
  return false;
}

const char* allowed_pairs(RelKeyword kind) {
  switch (kind) {
    case RelKeyword::kAgainst:
      return "face-face, face-shaft, face-edge, face-vertex, face-sphface, vertex-vertex, "
             "sphface-sphface, sphface-vertex";
    case RelKeyword::kCoplanar:
      return "face-face";
    case RelKeyword::kFits:
    case RelKeyword::kAligned:
      return "shaft-hole, shaft-edge, shaft-shaft, hole-edge, hole-hole, edge-edge";
    case RelKeyword::kParax:
    case RelKeyword::kParallel:
      return "shaft-hole, shaft-edge, shaft-shaft, hole-edge, hole-hole, edge-edge, face-face";
  }
  return "";
}

class Analyzer {
 public:
  Analyzer(const std::string& file, Diagnostics& diags) : d_(diags) {
    p_.file = file;
    Body world;
    world.name = "world";
    world.number = kWorld;
    p_.bodies.push_back(std::move(world));
    Situation first;
    first.number = 1;
    p_.situations.push_back(std::move(first));
  }

  Program run(const ast::Program& program) {
    for (const ast::Statement& st : program.statements) {
      std::visit([&](const auto& node) { visit(st.loc, node); }, st.body);
    }
    if (in_body_) {
      d_.error(body_loc_,
               fmt::format("BODY/{} is not terminated: expected TERBOD", p_.body(scope_).name));
    }
    if (package_ >= 0) {
      d_.error(package_loc_, "COMBINE is not terminated: expected TERCOM");
    }
    if (subass_ >= 0) {
      d_.error(p_.subassemblies[static_cast<std::size_t>(subass_)].loc,
               "SUBASS is not terminated: expected TERSUB");
    }
    build_tables();
    return std::move(p_);
  }

 private:
  // --- context checks ------------------------------------------------------------------------

  bool top_level(SourceLoc loc, const char* what) {
    if (in_body_) {
      d_.error(loc, fmt::format("{} is not allowed inside BODY/{} (missing TERBOD?)", what,
                                p_.body(scope_).name));
      return false;
    }
    if (package_ >= 0) {
      d_.error(loc, fmt::format("{} is not allowed inside COMBINE: only LOOK, INVIOLATE and "
                                "TOLERANCE/TRAN may appear before TERCOM",
                                what));
      return false;
    }
    if (subass_ >= 0) {
      d_.error(loc, fmt::format("{} is not allowed inside SUBASS (missing TERSUB?)", what));
      return false;
    }
    return true;
  }

  bool definition_context(SourceLoc loc, const char* what) {
    if (package_ >= 0 || subass_ >= 0) {
      d_.error(loc, fmt::format("{} definitions are not allowed inside {}", what,
                                package_ >= 0 ? "COMBINE" : "SUBASS"));
      return false;
    }
    return true;
  }

  Body& scope() { return p_.bodies[static_cast<std::size_t>(scope_ - 1)]; }
  Situation& current() { return p_.situations.back(); }

  bool name_free(const Name& name) {
    const Body& b = scope();
    if (b.points.count(name.text) != 0 || b.lines.count(name.text) != 0 ||
        b.circles.count(name.text) != 0 || b.feature_index.count(name.text) != 0) {
      d_.error(name.loc, fmt::format("'{}' is already defined in body '{}'", name.text, b.name));
      return false;
    }
    return true;
  }

  const Point* point(const Name& name) {
    const Body& b = scope();
    const auto it = b.points.find(name.text);
    if (it == b.points.end()) {
      d_.error(name.loc, fmt::format("unknown point '{}' in body '{}'", name.text, b.name));
      return nullptr;
    }
    return &it->second;
  }
  const Line* line(const Name& name) {
    const Body& b = scope();
    const auto it = b.lines.find(name.text);
    if (it == b.lines.end()) {
      d_.error(name.loc, fmt::format("unknown line '{}' in body '{}'", name.text, b.name));
      return nullptr;
    }
    return &it->second;
  }
  const Circle* circle(const Name& name) {
    const Body& b = scope();
    const auto it = b.circles.find(name.text);
    if (it == b.circles.end()) {
      d_.error(name.loc, fmt::format("unknown circle '{}' in body '{}'", name.text, b.name));
      return nullptr;
    }
    return &it->second;
  }

  int body_ref(const Name& name) {
    if (name.text == "world") {
      return kWorld;
    }
    const int n = p_.find_body(name.text);
    if (n == 0) {
      d_.error(name.loc, fmt::format("unknown body '{}'", name.text));
    }
    return n;
  }

  FeatureId feature_ref(const FeatureRef& ref) {
    if (ref.body) {
      const int n = body_ref(*ref.body);
      if (n == 0) {
        return {};
      }
      const Body& b = p_.body(n);
      const auto it = b.feature_index.find(ref.feature.text);
      if (it == b.feature_index.end()) {
        const bool primitive = b.points.count(ref.feature.text) != 0 ||
                               b.lines.count(ref.feature.text) != 0 ||
                               b.circles.count(ref.feature.text) != 0;
        d_.error(ref.feature.loc,
                 fmt::format("unknown feature '{}' of body '{}'{}", ref.feature.text, b.name,
                             primitive ? " (it is a point, line or circle, not a feature)" : ""));
        return {};
      }
      return FeatureId{n, it->second};
    }
    std::vector<FeatureId> found;
    for (const Body& b : p_.bodies) {
      const auto it = b.feature_index.find(ref.feature.text);
      if (it != b.feature_index.end()) {
        found.push_back(FeatureId{b.number, it->second});
      }
    }
    if (found.empty()) {
      d_.error(ref.feature.loc, fmt::format("unknown feature '{}'", ref.feature.text));
      return {};
    }
    if (found.size() > 1) {
      std::string owners;
      for (const FeatureId& f : found) {
        owners += (owners.empty() ? "" : ", ") + p_.body(f.body).name;
      }
      d_.error(ref.feature.loc,
               fmt::format("feature '{}' is ambiguous: it is defined in {}; write '{} of <body>'",
                           ref.feature.text, owners, ref.feature.text));
      return {};
    }
    return found.front();
  }

  /// Applies the x/y/z large/small rule to a unit direction.
  std::optional<Eigen::Vector3d> directed(const Eigen::Vector3d& v,
                                          Direction dir,
                                          SourceLoc loc,
                                          const char* what) {
    const auto [axis, sign] = axis_of(dir);
    const double comp = v[axis];
    if (std::abs(comp) < 1e-9) {
      d_.error(loc, fmt::format("{} has no {} component, so {} cannot choose its sign", what,
                                "xyz"[axis], to_string(dir)));
      return std::nullopt;
    }
    return comp * sign > 0.0 ? v : Eigen::Vector3d(-v);
  }

  void add_feature(const Name& name, Feature f) {
    f.name = name.text;
    f.body = scope_;
    f.loc = name.loc;
    Body& b = scope();
    b.feature_index[name.text] = static_cast<int>(b.features.size());
    b.features.push_back(std::move(f));
  }

  // --- statements ----------------------------------------------------------------------------

  void visit(SourceLoc loc, const ast::BodyBegin& st) {
    if (in_body_) {
      d_.error(loc, fmt::format("BODY/{} inside BODY/{}: expected TERBOD first", st.name.text,
                                p_.body(scope_).name));
      return;
    }
    if (!top_level(loc, "BODY")) {
      return;
    }
    if (st.name.text == "world") {
      d_.error(st.name.loc, "'world' is reserved: the world body exists already");
      return;
    }
    if (const int n = p_.find_body(st.name.text); n != 0) {
      d_.error(st.name.loc, fmt::format("body '{}' is already defined at {}", st.name.text,
                                        to_string(p_.body(n).loc)));
      return;
    }
    Body b;
    b.name = st.name.text;
    b.number = p_.body_count() + 1;
    b.loc = st.name.loc;
    p_.bodies.push_back(std::move(b));
    scope_ = p_.body_count();
    in_body_ = true;
    body_loc_ = loc;
  }

  void visit(SourceLoc loc, const ast::BodyEnd&) {
    if (!in_body_) {
      d_.error(loc, "TERBOD without BODY");
      return;
    }
    in_body_ = false;
    scope_ = kWorld;
  }

  /// Numbers beyond +-1e9 (mm, degrees) are rejected: they are typos, and their products
  /// would overflow the geometry.
  bool in_range(double value, SourceLoc loc, const char* what) {
    if (std::abs(value) > kMaxMagnitude) {
      d_.error(loc, fmt::format("{} must be within +-{:g}, got {:g}", what, kMaxMagnitude, value));
      return false;
    }
    return true;
  }

  void visit(SourceLoc loc, const ast::PointDef& st) {
    if (!definition_context(loc, "POINT") || !name_free(st.name)) {
      return;
    }
    for (const double v : st.xyz) {
      if (!in_range(v, st.name.loc, "a POINT coordinate [mm]")) {
        return;
      }
    }
    scope().points[st.name.text] =
        Point{Eigen::Vector3d(st.xyz[0], st.xyz[1], st.xyz[2]), st.name.loc};
  }

  void visit(SourceLoc loc, const ast::LineDef& st) {
    if (!definition_context(loc, "LINE") || !name_free(st.name)) {
      return;
    }
    const Point* a = point(st.from);
    const Point* b = point(st.to);
    if (a == nullptr || b == nullptr) {
      return;
    }
    if ((b->xyz - a->xyz).norm() < 1e-9) {
      d_.error(st.to.loc, fmt::format("LINE {} has zero length: '{}' and '{}' coincide",
                                      st.name.text, st.from.text, st.to.text));
      return;
    }
    scope().lines[st.name.text] = Line{a->xyz, b->xyz, st.name.loc};
  }

  void visit(SourceLoc loc, const ast::CircleDef& st) {
    if (!definition_context(loc, "CIRCLE") || !name_free(st.name)) {
      return;
    }
    const Point* c = point(st.centre);
    if (c == nullptr) {
      return;
    }
    if (!(st.radius > 0.0) || !in_range(st.radius, st.name.loc, "a RADIUS [mm]")) {
      d_.error(st.name.loc,
               fmt::format("CIRCLE {}: RADIUS must be > 0, got {}", st.name.text, st.radius));
      return;
    }
    scope().circles[st.name.text] = Circle{c->xyz, st.radius, st.name.loc};
  }

  void visit(SourceLoc loc, const ast::FaceDef& st) {
    if (!definition_context(loc, "FACE") || !name_free(st.name)) {
      return;
    }
    Feature f;
    f.type = FeatureType::kFace;
    if (st.form == ast::FaceDef::Form::kHoriz) {
      if (!in_range(st.height, st.name.loc, "the height of FACE/HORIZ [mm]")) {
        return;
      }
      const auto [axis, sign] = axis_of(st.dir);
      if (axis != 2) {
        d_.error(st.dir_loc, fmt::format("FACE/HORIZ has a vertical normal: the direction must "
                                         "be ZLARGE or ZSMALL, got {}",
                                         to_string(st.dir)));
        return;
      }
      f.body_T_feature = frame_from_x(Eigen::Vector3d(0, 0, st.height), Eigen::Vector3d(0, 0, sign),
                                      Eigen::Vector3d::UnitX());
    } else {
      const Point* p[3];
      for (int i = 0; i < 3; ++i) {
        p[i] = point(st.points[static_cast<std::size_t>(i)]);
      }
      if (p[0] == nullptr || p[1] == nullptr || p[2] == nullptr) {
        return;
      }
      const Eigen::Vector3d u = p[1]->xyz - p[0]->xyz;
      const Eigen::Vector3d n = u.cross(p[2]->xyz - p[0]->xyz);
      if (n.norm() < 1e-9 * std::max(1.0, u.squaredNorm())) {
        d_.error(st.name.loc,
                 fmt::format("FACE {}: points '{}', '{}', '{}' are collinear", st.name.text,
                             st.points[0].text, st.points[1].text, st.points[2].text));
        return;
      }
      const auto x = directed(n.normalized(), st.dir, st.dir_loc, "the FACE normal");
      if (!x) {
        return;
      }
      f.body_T_feature = frame_from_x(p[0]->xyz, *x, u);
    }
    add_feature(st.name, std::move(f));
  }

  void visit(SourceLoc loc, const ast::CylinderDef& st) {
    const char* kw = to_string(st.type);
    if (!definition_context(loc, kw) || !name_free(st.name)) {
      return;
    }
    Feature f;
    f.type = st.type;
    if (st.form == ast::CylinderDef::Form::kCircle) {
      const Circle* c = circle(st.primitive);
      if (c == nullptr) {
        return;
      }
      const auto [axis, sign] = axis_of(st.dir);
      if (axis != 2) {
        d_.error(st.dir_loc, fmt::format("a {} made from a circle has a vertical axis (circles "
                                         "are parallel to the body's X-Y plane): the direction "
                                         "must be ZLARGE or ZSMALL, got {}",
                                         kw, to_string(st.dir)));
        return;
      }
      f.body_T_feature = frame_from_x(c->centre, Eigen::Vector3d(0, 0, sign));
      f.radius = c->radius;
    } else {
      const Line* l = line(st.primitive);
      if (l == nullptr) {
        return;
      }
      const Eigen::Vector3d dvec = l->to - l->from;
      const auto x = directed(dvec.normalized(), st.dir, st.dir_loc, "the axis line");
      if (!x) {
        return;
      }
      f.body_T_feature = frame_from_x(l->from, *x);
      f.length = dvec.norm();
      if (st.form == ast::CylinderDef::Form::kAxis) {
        if (!(st.radius > 0.0) || !in_range(st.radius, st.name.loc, "a RADIUS [mm]")) {
          d_.error(st.name.loc,
                   fmt::format("{} {}: RADIUS must be > 0, got {}", kw, st.name.text, st.radius));
          return;
        }
        f.radius = st.radius;
      }
    }
    add_feature(st.name, std::move(f));
  }

  void visit(SourceLoc loc, const ast::SphereDef& st) {
    if (!definition_context(loc, to_string(st.type)) || !name_free(st.name)) {
      return;
    }
    const Point* c = point(st.centre);
    if (c == nullptr) {
      return;
    }
    if (st.type == FeatureType::kSphface &&
        (!(st.radius > 0.0) || !in_range(st.radius, st.name.loc, "a radius [mm]"))) {
      d_.error(st.name.loc,
               fmt::format("SPHFACE {}: the radius must be > 0, got {}", st.name.text, st.radius));
      return;
    }
    Feature f;
    f.type = st.type;
    f.radius = st.radius;
    f.body_T_feature = frame_from_x(c->xyz, Eigen::Vector3d::UnitX());
    add_feature(st.name, std::move(f));
  }

  std::optional<RelationDecl> relation(SourceLoc loc,
                                       RelKeyword kind,
                                       const FeatureRef& ra,
                                       const FeatureRef& rb) {
    const FeatureId a = feature_ref(ra);
    const FeatureId b = feature_ref(rb);
    if (!a.valid() || !b.valid()) {
      return std::nullopt;
    }
    const Feature& fa = p_.feature(a);
    const Feature& fb = p_.feature(b);
    if (!valid_pair(kind, fa, fb)) {
      d_.error(loc,
               fmt::format("{} between a {} ('{}') and a {} ('{}') is not allowed: {} takes "
                           "{} (thesis Table 3.1)",
                           to_string(kind), to_string(fa.type), ra.display(), to_string(fb.type),
                           rb.display(), to_string(kind), allowed_pairs(kind)));
      return std::nullopt;
    }
    if (a.body == b.body) {
      d_.error(loc, fmt::format("{} relates two features of the same body '{}'", to_string(kind),
                                p_.body(a.body).name));
      return std::nullopt;
    }
    return RelationDecl{kind, a, b, loc};
  }

  void visit(SourceLoc loc, const ast::RelationStmt& st) {
    if (in_body_ || package_ >= 0) {
      top_level(loc, to_string(st.kind));
      return;
    }
    auto rel = relation(loc, st.kind, st.a, st.b);
    if (!rel) {
      return;
    }
    if (subass_ >= 0) {
      Subassembly& sa = p_.subassemblies[static_cast<std::size_t>(subass_)];
      sa.relations.push_back(*rel);
      for (const int body : {rel->a.body, rel->b.body}) {
        if (std::find(sa.bodies.begin(), sa.bodies.end(), body) == sa.bodies.end()) {
          sa.bodies.push_back(body);
        }
      }
      return;
    }
    current().relations.push_back(*rel);
  }

  void visit(SourceLoc loc, const ast::ActionStmt& st) {
    const char* kw = st.verb == ast::ActionVerb::kMove ? "MOVE" : "TURN";
    if (!top_level(loc, kw)) {
      return;
    }
    Action action;
    action.kind = st.verb == ast::ActionVerb::kMove ? ActionKind::kMove : ActionKind::kTurn;
    action.mode = st.mode;
    action.loc = loc;
    action.body = body_ref(st.body);
    bool ok = action.body != 0;
    if (action.body == kWorld) {
      d_.error(st.body.loc, fmt::format("{}/world: the world cannot be moved", kw));
      ok = false;
    }
    if (st.verb == ast::ActionVerb::kTurn && st.mode != ast::ActionMode::kAbout) {
      d_.error(loc, "TURN needs ABOUT: TURN/<body>, ABOUT, <feature> [, degrees]");
      ok = false;
    }
    if (st.verb == ast::ActionVerb::kMove && st.mode == ast::ActionMode::kAbout) {
      d_.error(loc, "MOVE takes PERPTO or PARLEL; ABOUT belongs to TURN");
      ok = false;
    }
    if (st.feature && ok) {
      const FeatureId f = feature_ref(*st.feature);
      if (!f.valid()) {
        ok = false;
      } else if (f.body != action.body) {
        d_.error(st.feature->loc,
                 fmt::format("the feature of {} must belong to the moved body '{}', got '{}'", kw,
                             p_.body(action.body).name, st.feature->display()));
        ok = false;
      } else {
        const Feature& feat = p_.feature(f);
        if (st.mode == ast::ActionMode::kPerpto && feat.type != FeatureType::kFace) {
          d_.error(st.feature->loc, fmt::format("MOVE PERPTO needs a face (its normal gives the "
                                                "direction), '{}' is a {}",
                                                st.feature->display(), to_string(feat.type)));
          ok = false;
        } else if (feat.spherical()) {
          d_.error(st.feature->loc, fmt::format("{} cannot refer to a {} ('{}'): it has no "
                                                "axis",
                                                kw, to_string(feat.type), st.feature->display()));
          ok = false;
        }
        action.feature = f;
        if (st.amount && !in_range(*st.amount, st.amount_loc, "the amount of an action")) {
          ok = false;
        } else if (st.amount) {
          action.amount = st.verb == ast::ActionVerb::kTurn ? *st.amount * kDegToRad : *st.amount;
          if (st.mode == ast::ActionMode::kParlel && feat.type == FeatureType::kFace) {
            d_.warning(st.amount_loc,
                       "the amount is not used: MOVE PARLEL to a face is not an "
                       "explicit action (the direction within the face is not "
                       "given, thesis §3.2.3)");
            action.amount.reset();
          }
        }
      }
    }
    Situation s;
    s.number = p_.situation_count() + 1;
    s.action =
        ok ? action : Action{ActionKind::kMove, 0, ast::ActionMode::kGeneral, {}, {}, -1, loc};
    p_.situations.push_back(std::move(s));
  }

  void visit(SourceLoc loc, const ast::AgentStmt& st) {
    if (!top_level(loc, "AGENT")) {
      return;
    }
    const int b = body_ref(st.body);
    if (b == kWorld) {
      d_.error(st.body.loc, "AGENT/world: the world cannot be an agent");
    } else if (b != 0) {
      p_.agents.push_back(b);
    }
  }

  void visit(SourceLoc loc, const ast::TieStmt& st) {
    if (!top_level(loc, st.tied ? "TIED" : "UNTIED")) {
      return;
    }
    const int a = body_ref(st.a);
    const int b = body_ref(st.b);
    if (a == 0 || b == 0) {
      return;
    }
    if (a == b) {
      d_.error(st.b.loc, fmt::format("{} needs two different bodies, got '{}' twice",
                                     st.tied ? "TIED" : "UNTIED", st.a.text));
      return;
    }
    current().tie_changes.push_back(TieChange{st.tied, std::min(a, b), std::max(a, b), loc});
  }

  void visit(SourceLoc loc, const ast::SubassBegin& st) {
    if (!top_level(loc, "SUBASS")) {
      return;
    }
    for (const Subassembly& sa : p_.subassemblies) {
      if (sa.name == st.name.text) {
        d_.error(st.name.loc, fmt::format("subassembly '{}' is already defined at {}", st.name.text,
                                          to_string(sa.loc)));
        return;
      }
    }
    Subassembly sa;
    sa.name = st.name.text;
    sa.permanent = st.permanent;
    sa.loc = loc;
    p_.subassemblies.push_back(std::move(sa));
    subass_ = static_cast<int>(p_.subassemblies.size()) - 1;
  }

  void visit(SourceLoc loc, const ast::SubassEnd&) {
    if (subass_ < 0) {
      d_.error(loc, "TERSUB without SUBASS");
      return;
    }
    const Subassembly& sa = p_.subassemblies[static_cast<std::size_t>(subass_)];
    if (sa.relations.empty()) {
      d_.error(sa.loc, fmt::format("subassembly '{}' has no relations", sa.name));
    }
    subass_ = -1;
  }

  void visit(SourceLoc loc, const ast::SubassSwitch& st) {
    if (!top_level(loc, st.on ? "ISSUB" : "NOSUB")) {
      return;
    }
    for (std::size_t i = 0; i < p_.subassemblies.size(); ++i) {
      if (p_.subassemblies[i].name == st.name.text) {
        if (p_.subassemblies[i].permanent) {
          d_.error(st.name.loc, fmt::format("subassembly '{}' is permanent: ISSUB/NOSUB apply "
                                            "to temporary ones",
                                            st.name.text));
          return;
        }
        current().subass_changes.push_back(SubassChange{st.on, static_cast<int>(i), loc});
        return;
      }
    }
    d_.error(st.name.loc, fmt::format("unknown subassembly '{}'", st.name.text));
  }

  void visit(SourceLoc loc, const ast::CameraDef& st) {
    if (!top_level(loc, "CAMERA")) {
      return;
    }
    for (const Camera& c : p_.cameras) {
      if (c.name == st.name.text) {
        d_.error(st.name.loc, fmt::format("camera '{}' is already defined at {}", st.name.text,
                                          to_string(c.loc)));
        return;
      }
    }
    Camera cam;
    cam.name = st.name.text;
    cam.physical = st.physical ? st.physical->text : "";
    cam.general = st.general;
    cam.focus = st.focus;
    cam.loc = loc;
    if (!(st.focus > 0.0) || !in_range(st.focus, st.focus_loc, "the focal length")) {
      d_.error(st.focus_loc, fmt::format("camera '{}': the focal length must be > 0, got {}",
                                         st.name.text, st.focus));
      return;
    }
    if (st.general) {
      cam.body = body_ref(st.place);
      if (cam.body == 0) {
        return;
      }
    } else {
      for (const double angle : {st.theta_deg, st.phi_deg, st.psi_deg}) {
        if (!in_range(angle, st.name.loc, "a camera angle [deg]")) {
          return;
        }
      }
      const Point* centre = point(st.place);  // world scope (top level)
      if (centre == nullptr) {
        return;
      }
      // Digest 003 §2.2 [verified]: reference axes X_c = (0,0,1), Y_c = (0,1,0), Z_c = (-1,0,0)
      // in the world; rotate about the current Z_c by +THETA, about the current Y_c by -PHI,
      // about X_c by PSI (the sign of PSI is untested: every thesis camera has PSI = 0).
      Eigen::Matrix3d ref;
      ref << 0, 0, -1,  //
          0, 1, 0,      //
          1, 0, 0;
      const Eigen::Matrix3d r =
          ref * Eigen::AngleAxisd(st.theta_deg * kDegToRad, Eigen::Vector3d::UnitZ()) *
          Eigen::AngleAxisd(-st.phi_deg * kDegToRad, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(st.psi_deg * kDegToRad, Eigen::Vector3d::UnitX());
      cam.world_T_camera = Pose::Identity();
      cam.world_T_camera.linear() = r;
      cam.world_T_camera.translation() = centre->xyz;
    }
    p_.cameras.push_back(std::move(cam));
  }

  int camera_ref(const Name& name) {
    for (std::size_t i = 0; i < p_.cameras.size(); ++i) {
      if (p_.cameras[i].name == name.text) {
        return static_cast<int>(i);
      }
    }
    d_.error(name.loc, fmt::format("unknown camera '{}'", name.text));
    return -1;
  }

  void visit(SourceLoc loc, const ast::SetCamera& st) {
    if (!top_level(loc, "SETCAMERA")) {
      return;
    }
    const int c = camera_ref(st.camera);
    if (c >= 0) {
      default_camera_ = c;
    }
  }

  void visit(SourceLoc loc, const ast::Tolerance& st) {
    if (!(st.value > 0.0) || !in_range(st.value, st.value_loc, "a TOLERANCE [mm]")) {
      d_.error(st.value_loc, fmt::format("TOLERANCE must be > 0 mm, got {}", st.value));
      return;
    }
    if (st.body) {
      if (package_ >= 0) {
        d_.error(loc,
                 "a global TOLERANCE/<body>,TRAN,d is not allowed inside COMBINE: use the "
                 "local form TOLERANCE/TRAN,d");
        return;
      }
      if (!top_level(loc, "TOLERANCE")) {
        return;
      }
      const int b = body_ref(*st.body);
      if (b != 0) {
        p_.global_tolerance[b] = st.value;
      }
      return;
    }
    if (package_ < 0) {
      d_.error(loc,
               "TOLERANCE/TRAN,d without a body is the local form and is only allowed "
               "inside COMBINE; outside write TOLERANCE/<body>,TRAN,d");
      return;
    }
    Package& pk = p_.packages[static_cast<std::size_t>(package_)];
    if (pk.local_tolerance) {
      d_.error(loc, "a second local TOLERANCE in the same COMBINE package");
      return;
    }
    pk.local_tolerance = st.value;
  }

  void visit(SourceLoc loc, const ast::Combine&) {
    if (package_ >= 0) {
      d_.error(loc, fmt::format("COMBINE inside COMBINE (opened at {}): expected TERCOM first",
                                to_string(package_loc_)));
      return;
    }
    if (!top_level(loc, "COMBINE")) {
      return;
    }
    Package pk;
    pk.loc = loc;
    Situation s;
    s.number = p_.situation_count() + 1;
    pk.situation = s.number;
    s.action.kind = ActionKind::kVision;
    s.action.loc = loc;
    s.action.package = static_cast<int>(p_.packages.size());
    p_.situations.push_back(std::move(s));
    p_.packages.push_back(std::move(pk));
    package_ = static_cast<int>(p_.packages.size()) - 1;
    package_loc_ = loc;
  }

  void visit(SourceLoc loc, const ast::TerCom&) {
    if (package_ < 0) {
      d_.error(loc, "TERCOM without COMBINE");
      return;
    }
    finish_package(loc);
    package_ = -1;
  }

  void visit(SourceLoc loc, const ast::Inviolate& st) {
    if (package_ < 0) {
      d_.error(loc, "INVIOLATE is only allowed inside a COMBINE ... TERCOM package");
      return;
    }
    if (st.kind != RelKeyword::kAgainst) {
      d_.error(st.kind_loc, fmt::format("INVIOLATE supports only AGAINST between two faces "
                                        "(AGPP, thesis §5.3.1), got {}",
                                        to_string(st.kind)));
      return;
    }
    const FeatureId a = feature_ref(st.a);
    const FeatureId b = feature_ref(st.b);
    if (!a.valid() || !b.valid()) {
      return;
    }
    for (const auto& [id, ref] : {std::pair{a, &st.a}, std::pair{b, &st.b}}) {
      if (p_.feature(id).type != FeatureType::kFace) {
        d_.error(ref->loc, fmt::format("INVIOLATE/AGAINST relates two faces (AGPP); '{}' is a {}",
                                       ref->display(), to_string(p_.feature(id).type)));
        return;
      }
    }
    // Which one belongs to the verified body is settled at TERCOM.
    p_.packages[static_cast<std::size_t>(package_)].inviolates.push_back(InviolateDecl{a, b, loc});
  }

  void visit(SourceLoc loc, const ast::Look& st) {
    if (package_ < 0) {
      d_.error(loc, "LOOK is only allowed inside a COMBINE ... TERCOM package");
      return;
    }
    const FeatureId f = feature_ref(st.edge);
    int cam = -1;
    if (st.camera) {
      cam = camera_ref(*st.camera);
    } else if (default_camera_ >= 0) {
      cam = default_camera_;
    } else {
      d_.error(loc,
               "LOOK has no camera: name one (LOOK/<edge>, <camera>) or set a default with "
               "SETCAMERA");
    }
    if (!f.valid()) {
      return;
    }
    const Feature& feat = p_.feature(f);
    if (feat.type != FeatureType::kEdge) {
      d_.error(st.edge.loc, fmt::format("LOOK needs an edge: '{}' is a {} (only finite edges can "
                                        "be verified, thesis §5.2)",
                                        st.edge.display(), to_string(feat.type)));
      return;
    }
    if (!(feat.length > 0.0)) {
      d_.error(st.edge.loc,
               fmt::format("LOOK needs a finite edge: '{}' has no length", st.edge.display()));
      return;
    }
    if (cam < 0) {
      return;
    }
    p_.packages[static_cast<std::size_t>(package_)].looks.push_back(LookDecl{f, cam, loc});
  }

  void visit(SourceLoc loc, const ast::TerApt&) {
    if (in_body_) {
      d_.error(loc,
               fmt::format("TERAPT inside BODY/{}: expected TERBOD first", p_.body(scope_).name));
    }
    if (subass_ >= 0) {
      d_.error(loc, "TERAPT inside SUBASS: expected TERSUB first");
    }
  }

  // --- package and table checks --------------------------------------------------------------

  void finish_package(SourceLoc loc) {
    Package& pk = p_.packages[static_cast<std::size_t>(package_)];
    if (pk.looks.empty()) {
      d_.error(loc, fmt::format("the COMBINE package at {} has no LOOK: there is nothing to "
                                "verify",
                                to_string(pk.loc)));
      return;
    }
    pk.body = pk.looks.front().edge.body;
    p_.situations[static_cast<std::size_t>(pk.situation - 1)].action.body = pk.body;
    const std::string bv = p_.body(pk.body).name;
    if (pk.body == kWorld) {
      d_.error(pk.looks.front().loc, "COMBINE cannot verify the world");
    }
    for (const LookDecl& look : pk.looks) {
      if (look.edge.body != pk.body) {
        d_.error(look.loc,
                 fmt::format("every LOOK and INVIOLATE of a COMBINE package must concern "
                             "one body: this LOOK is of '{}', the package verifies '{}' "
                             "(its first LOOK at {})",
                             p_.body(look.edge.body).name, bv, to_string(pk.looks.front().loc)));
      }
    }
    for (InviolateDecl& inv : pk.inviolates) {
      const bool a_is_bv = inv.reference.body == pk.body;
      const bool b_is_bv = inv.verified.body == pk.body;
      if (a_is_bv && b_is_bv) {
        d_.error(inv.loc, fmt::format("INVIOLATE relates two faces of the verified body '{}'; "
                                      "the reference must belong to the world or a body fixed in "
                                      "the world",
                                      bv));
      } else if (a_is_bv) {
        // The §5.5.3 example writes the reference second; accept both orders.
        std::swap(inv.reference, inv.verified);
      } else if (!b_is_bv) {
        d_.error(inv.loc,
                 fmt::format("every LOOK and INVIOLATE of a COMBINE package must concern "
                             "one body: this INVIOLATE relates '{}' and '{}', the "
                             "package verifies '{}'",
                             p_.feature_name(inv.reference), p_.feature_name(inv.verified), bv));
      }
    }
  }

  void build_tables() {
    const std::size_t n = p_.situations.size();
    p_.ties_after.assign(n, {});
    p_.subass_after.assign(n, {});
    p_.moved.assign(n, {});
    std::set<std::pair<int, int>> ties;
    std::set<int> subs;
    for (std::size_t i = 0; i < p_.subassemblies.size(); ++i) {
      if (p_.subassemblies[i].permanent) {
        subs.insert(static_cast<int>(i));
      }
    }
    for (std::size_t i = 0; i < n; ++i) {
      Situation& s = p_.situations[i];
      if (i > 0 && (s.action.kind == ActionKind::kMove || s.action.kind == ActionKind::kTurn) &&
          s.action.body != 0) {
        p_.moved[i] = moved_group(s.action, p_.ties_after[i - 1], p_.subass_after[i - 1]);
      }
      for (const TieChange& c : s.tie_changes) {
        const std::pair<int, int> key{c.a, c.b};
        if (c.tied) {
          if (!ties.insert(key).second) {
            d_.warning(c.loc, fmt::format("'{}' and '{}' are already TIED", p_.body(c.a).name,
                                          p_.body(c.b).name));
          }
        } else if (ties.erase(key) == 0) {
          d_.error(c.loc, fmt::format("UNTIED/{},{}: they are not TIED", p_.body(c.a).name,
                                      p_.body(c.b).name));
        }
      }
      for (const SubassChange& c : s.subass_changes) {
        if (c.on) {
          subs.insert(c.subassembly);
        } else {
          subs.erase(c.subassembly);
        }
      }
      p_.ties_after[i].assign(ties.begin(), ties.end());
      p_.subass_after[i].assign(subs.begin(), subs.end());
    }
  }

  /// The bodies an action moves: the mover plus everything TIED to it or in an active
  /// subassembly with it (transitively). Checks the agent and world rules.
  std::vector<int> moved_group(const Action& action,
                               const std::vector<std::pair<int, int>>& ties,
                               const std::vector<int>& subs) {
    std::vector<int> group{action.body};
    for (std::size_t k = 0; k < group.size(); ++k) {
      const int b = group[k];
      auto add = [&](int other) {
        if (std::find(group.begin(), group.end(), other) == group.end()) {
          group.push_back(other);
        }
      };
      for (const auto& [x, y] : ties) {
        if (x == b) {
          add(y);
        } else if (y == b) {
          add(x);
        }
      }
      for (const int si : subs) {
        const auto& members = p_.subassemblies[static_cast<std::size_t>(si)].bodies;
        if (std::find(members.begin(), members.end(), b) != members.end()) {
          for (const int m : members) {
            add(m);
          }
        }
      }
    }
    const char* kw = action.kind == ActionKind::kTurn ? "TURN" : "MOVE";
    const std::string mover = p_.body(action.body).name;
    if (std::find(group.begin(), group.end(), kWorld) != group.end()) {
      d_.error(action.loc, fmt::format("{}/{} would move the world: '{}' is TIED to the world "
                                       "(directly or through other bodies)",
                                       kw, mover, mover));
      group.erase(std::remove(group.begin(), group.end(), kWorld), group.end());
    }
    const bool has_agent = std::any_of(group.begin(), group.end(), [&](int b) {
      return std::find(p_.agents.begin(), p_.agents.end(), b) != p_.agents.end();
    });
    if (!has_agent) {
      d_.error(action.loc, fmt::format("'{}' cannot be moved: it is neither an AGENT nor TIED or "
                                       "in a subassembly with one (thesis §3.2.3)",
                                       mover));
    }
    std::sort(group.begin(), group.end());
    return group;
  }

  Program p_;
  Diagnostics& d_;
  int scope_ = kWorld;
  bool in_body_ = false;
  SourceLoc body_loc_;
  int package_ = -1;
  SourceLoc package_loc_;
  int subass_ = -1;
  int default_camera_ = -1;
};

}  // namespace

Program analyze(const ast::Program& ast, const std::string& file, Diagnostics& diags) {
  Analyzer analyzer(file, diags);
  return analyzer.run(ast);
}

}  // namespace cell::rapt
