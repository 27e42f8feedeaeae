#include "cell/rapt/parser.hpp"

#include <fmt/format.h>

#include <cctype>
#include <initializer_list>
#include <string>

#include "cell/rapt/lexer.hpp"

namespace cell::rapt {

std::string FeatureRef::display() const {
  return body ? feature.text + " of " + body->text : feature.text;
}

const char* to_string(Direction d) noexcept {
  switch (d) {
    case Direction::kXLarge:
      return "xlarge";
    case Direction::kXSmall:
      return "xsmall";
    case Direction::kYLarge:
      return "ylarge";
    case Direction::kYSmall:
      return "ysmall";
    case Direction::kZLarge:
      return "zlarge";
    case Direction::kZSmall:
      return "zsmall";
  }
  return "?";
}

const char* to_string(FeatureType t) noexcept {
  switch (t) {
    case FeatureType::kFace:
      return "face";
    case FeatureType::kShaft:
      return "shaft";
    case FeatureType::kHole:
      return "hole";
    case FeatureType::kEdge:
      return "edge";
    case FeatureType::kSphface:
      return "sphface";
    case FeatureType::kVertex:
      return "vertex";
  }
  return "?";
}

const char* to_string(RelKeyword k) noexcept {
  switch (k) {
    case RelKeyword::kAgainst:
      return "AGAINST";
    case RelKeyword::kCoplanar:
      return "COPLANAR";
    case RelKeyword::kFits:
      return "FITS";
    case RelKeyword::kAligned:
      return "ALIGNED";
    case RelKeyword::kParax:
      return "PARAX";
    case RelKeyword::kParallel:
      return "PARALLEL";
  }
  return "?";
}

namespace {

std::string fold(std::string_view text) {
  std::string out(text);
  for (char& c : out) {
    c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  }
  return out;
}

class Parser {
 public:
  Parser(std::vector<Token> tokens, Diagnostics& diags)
      : tokens_(std::move(tokens)), diags_(diags) {}

  ast::Program run() {
    ast::Program program;
    bool ended = false;
    while (peek().kind != TokenKind::kEnd) {
      if (peek().kind == TokenKind::kSemicolon) {  // empty statement
        ++pos_;
        continue;
      }
      const Token& first = peek();
      if (ended) {
        diags_.error(first.loc, fmt::format("statement after TERAPT: TERAPT must end the "
                                            "program, got {}",
                                            describe(first)));
        sync();
        continue;
      }
      // Panic mode: after the first error of a statement every helper returns a default
      // without consuming input; the statement is then dropped and we resynchronise at ';'.
      failed_ = false;
      ast::Statement st{first.loc, statement()};
      expect(TokenKind::kSemicolon, "';' at the end of the statement");
      if (failed_) {
        sync();
        continue;
      }
      if (std::holds_alternative<ast::TerApt>(st.body)) {
        ended = true;
      }
      program.statements.push_back(std::move(st));
    }
    if (!ended) {
      diags_.error(peek().loc, "missing TERAPT: the program must end with 'TERAPT;'");
    }
    return program;
  }

 private:
  const Token& peek(std::size_t ahead = 0) const {
    const std::size_t i = pos_ + ahead;
    return i < tokens_.size() ? tokens_[i] : tokens_.back();
  }
  const Token& next() {
    const Token& t = peek();
    if (t.kind != TokenKind::kEnd) {
      ++pos_;
    }
    return t;
  }

  /// Skips past the next ';' (or to the end), the recovery point after an error.
  void sync() {
    while (peek().kind != TokenKind::kEnd) {
      if (next().kind == TokenKind::kSemicolon) {
        return;
      }
    }
  }

  /// Records "expected X, got Y" (once per statement) and enters panic mode.
  void fail(const Token& at, const std::string& expected) {
    if (!failed_) {
      diags_.error(at.loc, fmt::format("expected {}, got {}", expected, describe(at)));
    }
    failed_ = true;
  }

  /// Records a custom message (once per statement) and enters panic mode.
  void fail_with(SourceLoc loc, std::string message) {
    if (!failed_) {
      diags_.error(loc, std::move(message));
    }
    failed_ = true;
  }

  /// The next token if it has `kind` (consumed); otherwise records the error and returns a
  /// placeholder. In panic mode nothing is consumed.
  const Token& expect(TokenKind kind, const std::string& expected) {
    if (failed_) {
      return placeholder_;
    }
    if (peek().kind != kind) {
      fail(peek(), expected);
      return placeholder_;
    }
    return next();
  }

  void expect_keyword(std::string_view kw, const std::string& expected) {
    if (failed_) {
      return;
    }
    if (!keyword_is(peek(), kw)) {
      fail(peek(), expected);
      return;
    }
    next();
  }

  bool accept_keyword(std::string_view kw) {
    if (!failed_ && keyword_is(peek(), kw)) {
      next();
      return true;
    }
    return false;
  }

  Name name(const std::string& what) {
    const Token& t = expect(TokenKind::kIdent, what);
    return Name{fold(t.text), t.loc};
  }

  double number(const std::string& what, SourceLoc* loc = nullptr) {
    const Token& t = expect(TokenKind::kNumber, what);
    if (loc != nullptr) {
      *loc = t.loc;
    }
    return t.number;
  }

  void comma(const std::string& after) { expect(TokenKind::kComma, "',' after " + after); }

  FeatureRef feature_ref(const std::string& what) {
    FeatureRef ref;
    ref.loc = peek().loc;
    ref.feature = name(what);
    if (accept_keyword("of")) {
      ref.body = name("a body name after OF");
    }
    return ref;
  }

  Direction direction() {
    static constexpr std::pair<std::string_view, Direction> kDirs[] = {
        {"xlarge", Direction::kXLarge}, {"xsmall", Direction::kXSmall},
        {"ylarge", Direction::kYLarge}, {"ysmall", Direction::kYSmall},
        {"zlarge", Direction::kZLarge}, {"zsmall", Direction::kZSmall}};
    for (const auto& [kw, d] : kDirs) {
      if (accept_keyword(kw)) {
        return d;
      }
    }
    fail(peek(), "a direction (XLARGE, XSMALL, YLARGE, YSMALL, ZLARGE or ZSMALL)");
    return Direction::kXLarge;
  }

  std::optional<RelKeyword> relation_keyword(const Token& t) const {
    static constexpr std::pair<std::string_view, RelKeyword> kRels[] = {
        {"against", RelKeyword::kAgainst}, {"coplanar", RelKeyword::kCoplanar},
        {"fits", RelKeyword::kFits},       {"aligned", RelKeyword::kAligned},
        {"parax", RelKeyword::kParax},     {"parallel", RelKeyword::kParallel}};
    for (const auto& [kw, k] : kRels) {
      if (keyword_is(t, kw)) {
        return k;
      }
    }
    return std::nullopt;
  }

  ast::StatementBody statement() {
    const Token& first = peek();
    if (first.kind != TokenKind::kIdent) {
      fail(first, "a statement (a keyword such as BODY, AGAINST, MOVE, or '<name> =')");
      return ast::TerCom{};
    }
    if (peek(1).kind == TokenKind::kEquals) {
      return definition();
    }
    next();
    if (keyword_is(first, "body")) {
      expect(TokenKind::kSlash, "'/' after BODY");
      return ast::BodyBegin{name("a body name after BODY/")};
    }
    if (keyword_is(first, "terbod")) {
      return ast::BodyEnd{};
    }
    if (const auto rel = relation_keyword(first)) {
      const std::string kw = to_string(*rel);
      expect(TokenKind::kSlash, "'/' after " + kw);
      ast::RelationStmt st;
      st.kind = *rel;
      st.a = feature_ref("a feature after " + kw + "/");
      comma("the first feature of " + kw);
      st.b = feature_ref("the second feature of " + kw);
      return st;
    }
    if (keyword_is(first, "move") || keyword_is(first, "turn")) {
      return action(keyword_is(first, "move") ? ast::ActionVerb::kMove : ast::ActionVerb::kTurn);
    }
    if (keyword_is(first, "agent")) {
      expect(TokenKind::kSlash, "'/' after AGENT");
      return ast::AgentStmt{name("a body name after AGENT/")};
    }
    if (keyword_is(first, "tied") || keyword_is(first, "untied")) {
      const bool tied = keyword_is(first, "tied");
      const std::string kw = tied ? "TIED" : "UNTIED";
      expect(TokenKind::kSlash, "'/' after " + kw);
      ast::TieStmt st;
      st.tied = tied;
      st.a = name("a body name after " + kw + "/");
      comma("the first body of " + kw);
      st.b = name("the second body of " + kw);
      return st;
    }
    if (keyword_is(first, "issub") || keyword_is(first, "nosub") || keyword_is(first, "notsub")) {
      const bool on = keyword_is(first, "issub");
      expect(TokenKind::kSlash, on ? "'/' after ISSUB" : "'/' after NOSUB");
      return ast::SubassSwitch{on, name("a subassembly name")};
    }
    if (keyword_is(first, "tersub")) {
      return ast::SubassEnd{};
    }
    if (keyword_is(first, "setcamera")) {
      expect(TokenKind::kSlash, "'/' after SETCAMERA");
      return ast::SetCamera{name("a camera name after SETCAMERA/")};
    }
    if (keyword_is(first, "tolerance")) {
      return tolerance();
    }
    if (keyword_is(first, "combine")) {
      return ast::Combine{};
    }
    if (keyword_is(first, "tercom")) {
      return ast::TerCom{};
    }
    if (keyword_is(first, "inviolate")) {
      expect(TokenKind::kSlash, "'/' after INVIOLATE");
      ast::Inviolate st;
      st.kind_loc = peek().loc;
      const auto rel = failed_ ? std::nullopt : relation_keyword(peek());
      if (!rel) {
        fail(peek(), "a relation after INVIOLATE/ (AGAINST, COPLANAR, FITS, ...)");
      } else {
        next();
        st.kind = *rel;
      }
      comma("the INVIOLATE relation");
      st.a = feature_ref("the reference feature of INVIOLATE");
      comma("the reference feature of INVIOLATE");
      st.b = feature_ref("the feature of the verified body");
      return st;
    }
    if (keyword_is(first, "look")) {
      expect(TokenKind::kSlash, "'/' after LOOK");
      ast::Look st;
      st.edge = feature_ref("an edge after LOOK/");
      if (peek().kind == TokenKind::kComma) {
        next();
        st.camera = name("a camera name after the LOOK edge");
      }
      return st;
    }
    if (keyword_is(first, "terapt")) {
      return ast::TerApt{};
    }
    fail_with(first.loc,
              fmt::format("unknown statement '{}': expected BODY, TERBOD, a definition "
                          "'<name> = POINT|LINE|CIRCLE|FACE|SHAFT|HOLE|EDGE|SPHFACE|VERTEX|"
                          "SUBASS|CAMERA/...', a relation (AGAINST, COPLANAR, FITS, ALIGNED, "
                          "PARAX, PARALLEL), MOVE, TURN, AGENT, TIED, UNTIED, ISSUB, NOSUB, "
                          "TERSUB, SETCAMERA, TOLERANCE, COMBINE, INVIOLATE, LOOK, TERCOM or "
                          "TERAPT",
                          first.text));
    return ast::TerCom{};
  }

  ast::StatementBody definition() {
    const Name def = name("a name");
    next();  // '='
    const Token& kind = peek();
    if (kind.kind != TokenKind::kIdent) {
      fail(kind,
           "POINT, LINE, CIRCLE, FACE, SHAFT, HOLE, EDGE, SPHFACE, VERTEX, SUBASS or "
           "CAMERA after '='");
      return ast::TerCom{};
    }
    next();
    const std::string kw = fold(kind.text);
    if (kw == "point" || kw == "line" || kw == "circle" || kw == "face" || kw == "shaft" ||
        kw == "hole" || kw == "edge" || kw == "sphface" || kw == "vertex" || kw == "subass" ||
        kw == "camera") {
      expect(TokenKind::kSlash, "'/' after " + kw);
    } else {
      fail_with(kind.loc,
                fmt::format("unknown definition '{}': expected POINT, LINE, CIRCLE, FACE, "
                            "SHAFT, HOLE, EDGE, SPHFACE, VERTEX, SUBASS or CAMERA",
                            kind.text));
      return ast::TerCom{};
    }
    if (kw == "point") {
      ast::PointDef st{def, {}};
      st.xyz[0] = number("the x coordinate of POINT");
      comma("the x coordinate");
      st.xyz[1] = number("the y coordinate of POINT");
      comma("the y coordinate");
      st.xyz[2] = number("the z coordinate of POINT");
      return st;
    }
    if (kw == "line") {
      ast::LineDef st{def, {}, {}};
      st.from = name("the first point of LINE");
      comma("the first point of LINE");
      st.to = name("the second point of LINE");
      return st;
    }
    if (kw == "circle") {
      ast::CircleDef st{def, {}, 0.0};
      if (!accept_keyword("center") && !accept_keyword("centre")) {
        fail(peek(), "CENTER after CIRCLE/");
      }
      comma("CENTER");
      st.centre = name("the centre point of CIRCLE");
      comma("the centre point");
      expect_keyword("radius", "RADIUS");
      comma("RADIUS");
      st.radius = number("the radius of CIRCLE");
      return st;
    }
    if (kw == "face") {
      ast::FaceDef st;
      st.name = def;
      if (accept_keyword("horiz")) {
        st.form = ast::FaceDef::Form::kHoriz;
        comma("HORIZ");
        st.height = number("the height z of FACE/HORIZ");
        comma("the height");
      } else {
        st.form = ast::FaceDef::Form::kThreePoints;
        for (int i = 0; i < 3; ++i) {
          st.points[static_cast<std::size_t>(i)] =
              name(fmt::format("point {} of FACE (or HORIZ)", i + 1));
          comma(fmt::format("point {} of FACE", i + 1));
        }
      }
      st.dir_loc = peek().loc;
      st.dir = direction();
      return st;
    }
    if (kw == "shaft" || kw == "hole" || kw == "edge") {
      ast::CylinderDef st;
      st.name = def;
      st.type = kw == "shaft" ? FeatureType::kShaft
                              : (kw == "hole" ? FeatureType::kHole : FeatureType::kEdge);
      if (st.type != FeatureType::kEdge && accept_keyword("axis")) {
        st.form = ast::CylinderDef::Form::kAxis;
        comma("AXIS");
        st.primitive = name("the axis line");
        comma("the axis line");
        expect_keyword("radius", "RADIUS");
        comma("RADIUS");
        st.radius = number("the radius");
        comma("the radius");
      } else {
        st.form = st.type == FeatureType::kEdge ? ast::CylinderDef::Form::kLine
                                                : ast::CylinderDef::Form::kCircle;
        st.primitive =
            name(st.type == FeatureType::kEdge ? "the line of EDGE" : "AXIS or a circle name");
        comma(st.type == FeatureType::kEdge ? "the line" : "the circle");
      }
      st.dir_loc = peek().loc;
      st.dir = direction();
      return st;
    }
    if (kw == "sphface" || kw == "vertex") {
      ast::SphereDef st;
      st.name = def;
      st.type = kw == "sphface" ? FeatureType::kSphface : FeatureType::kVertex;
      st.centre = name("the centre point");
      if (st.type == FeatureType::kSphface) {
        comma("the centre point");
        st.radius = number("the radius of SPHFACE");
      }
      return st;
    }
    if (kw == "subass") {
      ast::SubassBegin st{def, true};
      if (accept_keyword("perm") || accept_keyword("permanent")) {
        st.permanent = true;
      } else if (accept_keyword("temp") || accept_keyword("temporary")) {
        st.permanent = false;
      } else {
        fail(peek(), "PERM or TEMP after SUBASS/");
      }
      return st;
    }
    return camera(def);
  }

  ast::StatementBody camera(const Name& def) {
    ast::CameraDef st;
    st.name = def;
    const Name first = name("POSITION or the physical camera name after CAMERA/");
    comma("the first CAMERA argument");
    st.place = name("the lens centre point or the camera body");
    comma("the lens centre point or the camera body");
    if (!failed_ && keyword_is(peek(), "theta")) {
      st.general = false;
      if (first.text != "position") {
        st.physical = first;
      }
      next();
      comma("THETA");
      st.theta_deg = number("the THETA angle [deg]");
      comma("the THETA angle");
      expect_keyword("phi", "PHI");
      comma("PHI");
      st.phi_deg = number("the PHI angle [deg]");
      comma("the PHI angle");
      expect_keyword("psi", "PSI");
      comma("PSI");
      st.psi_deg = number("the PSI angle [deg]");
      comma("the PSI angle");
    } else {
      st.general = true;
      st.physical = first;
    }
    if (accept_keyword("focus")) {
      comma("FOCUS");
    }
    st.focus = number("the focal length", &st.focus_loc);
    return st;
  }

  ast::StatementBody action(ast::ActionVerb verb) {
    const std::string kw = verb == ast::ActionVerb::kMove ? "MOVE" : "TURN";
    expect(TokenKind::kSlash, "'/' after " + kw);
    ast::ActionStmt st;
    st.verb = verb;
    st.body = name("the body to " +
                   (verb == ast::ActionVerb::kMove ? std::string("move") : std::string("turn")));
    if (peek().kind != TokenKind::kComma) {
      st.mode = ast::ActionMode::kGeneral;
      return st;
    }
    next();
    if (accept_keyword("perpto")) {
      st.mode = ast::ActionMode::kPerpto;
    } else if (accept_keyword("parlel") || accept_keyword("parallel")) {
      st.mode = ast::ActionMode::kParlel;
    } else if (accept_keyword("about")) {
      st.mode = ast::ActionMode::kAbout;
    } else {
      fail(peek(), verb == ast::ActionVerb::kMove ? "PERPTO or PARLEL after the moved body"
                                                  : "ABOUT after the turned body");
    }
    comma("the action mode");
    st.feature = feature_ref("the feature the action refers to");
    if (peek().kind == TokenKind::kComma) {
      next();
      st.amount = number(verb == ast::ActionVerb::kMove ? "the distance [mm]" : "the angle [deg]",
                         &st.amount_loc);
    }
    return st;
  }

  ast::StatementBody tolerance() {
    expect(TokenKind::kSlash, "'/' after TOLERANCE");
    ast::Tolerance st;
    const bool local = (keyword_is(peek(), "tran") || keyword_is(peek(), "trans")) &&
                       peek(1).kind == TokenKind::kComma && peek(2).kind == TokenKind::kNumber;
    if (!local) {
      st.body = name("TRAN or a body name after TOLERANCE/");
      comma("the body of TOLERANCE");
    }
    if (!accept_keyword("tran") && !accept_keyword("trans")) {
      fail(peek(), "TRAN (or TRANS)");
    }
    comma("TRAN");
    st.value = number("the translational tolerance [mm]", &st.value_loc);
    return st;
  }

  std::vector<Token> tokens_;
  std::size_t pos_ = 0;
  Diagnostics& diags_;
  bool failed_ = false;  ///< panic mode: an error was recorded in the current statement
  Token placeholder_{TokenKind::kEnd, {}, 0.0, {}};
};

}  // namespace

ast::Program parse(std::string_view source, Diagnostics& diags) {
  Parser parser(lex(source, diags), diags);
  return parser.run();
}

}  // namespace cell::rapt
