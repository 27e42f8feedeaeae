#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "cell/rapt/source.hpp"

/// The RAPT abstract syntax tree: one node per statement, exactly as written (names are not
/// resolved yet; that is semantic analysis, sema.hpp). Every node carries positions.
namespace cell::rapt {

/// A name as written, folded to lower case (RAPT is case-insensitive), with its position.
struct Name {
  std::string text;
  SourceLoc loc;
};

/// `<feature> [OF <body>]`. Without OF the feature is looked up in every body (the thesis
/// allows the short form "when there is no ambiguity").
struct FeatureRef {
  Name feature;
  std::optional<Name> body;
  SourceLoc loc;

  /// "e1 of b3" or "wf1" as written (lower case).
  std::string display() const;
};

/// The x/y/z large/small rule: which sign the named body axis component of the feature's
/// direction (face normal, cylinder axis) must have (digest 003 §1.1).
enum class Direction : std::uint8_t { kXLarge, kXSmall, kYLarge, kYSmall, kZLarge, kZSmall };

/// "xlarge", "ysmall", ...
const char* to_string(Direction d) noexcept;

/// The six RAPT feature types (thesis §3.2.1.3).
enum class FeatureType : std::uint8_t { kFace, kShaft, kHole, kEdge, kSphface, kVertex };

/// "face", "shaft", ...
const char* to_string(FeatureType t) noexcept;

/// The input relations of Table 3.1.
enum class RelKeyword : std::uint8_t { kAgainst, kCoplanar, kFits, kAligned, kParax, kParallel };

/// "AGAINST", "COPLANAR", ...
const char* to_string(RelKeyword k) noexcept;

namespace ast {

// Each node's fields are named after the statement form in its comment (a name, the points it
// refers to, numbers in mm or degrees as written); positions are in the Names and Statement.

/// BODY/<name>;
struct BodyBegin {
  Name name;
};
/// TERBOD;
struct BodyEnd {};
/// <name> = POINT/x, y, z;  [mm, in the enclosing body's frame]
struct PointDef {
  Name name;
  std::array<double, 3> xyz{};
};
/// <name> = LINE/<point>, <point>;  (the segment from the first point to the second)
struct LineDef {
  Name name;
  Name from;
  Name to;
};
/// <name> = CIRCLE/CENTER, <point>, RADIUS, r;  (parallel to the body's X-Y plane, v1.1a)
struct CircleDef {
  Name name;
  Name centre;
  double radius = 0.0;
};
/// <name> = FACE/<p1>, <p2>, <p3>, <dir>;  or  <name> = FACE/HORIZ, z, <dir>;
struct FaceDef {
  enum class Form : std::uint8_t { kThreePoints, kHoriz };
  Name name;
  Form form = Form::kThreePoints;
  std::array<Name, 3> points;  ///< kThreePoints
  double height = 0.0;         ///< kHoriz: the plane z = height [mm]
  Direction dir = Direction::kXLarge;
  SourceLoc dir_loc;
};
/// SHAFT / HOLE / EDGE definitions:
///   <name> = SHAFT/AXIS, <line>, RADIUS, r, <dir>;   (also HOLE)
///   <name> = HOLE/<circle>, <dir>;                   (also SHAFT)
///   <name> = EDGE/<line>, <dir>;
struct CylinderDef {
  enum class Form : std::uint8_t { kAxis, kCircle, kLine };
  Name name;
  FeatureType type = FeatureType::kShaft;
  Form form = Form::kAxis;
  Name primitive;  ///< the line (kAxis, kLine) or the circle (kCircle)
  double radius = 0.0;
  Direction dir = Direction::kXLarge;
  SourceLoc dir_loc;
};
/// <name> = SPHFACE/<point>, r;   <name> = VERTEX/<point>;
struct SphereDef {
  Name name;
  FeatureType type = FeatureType::kSphface;
  Name centre;
  double radius = 0.0;
};
/// <relation>/<feature>, <feature>;
struct RelationStmt {
  RelKeyword kind = RelKeyword::kAgainst;
  FeatureRef a;
  FeatureRef b;
};
/// MOVE or TURN.
enum class ActionVerb : std::uint8_t { kMove, kTurn };
/// PERPTO / PARLEL (also spelled PARALLEL) / ABOUT, or none for a general MOVE.
enum class ActionMode : std::uint8_t { kGeneral, kPerpto, kParlel, kAbout };
/// MOVE/<body>;  <MOVE|TURN>/<body>, <mode>, <feature> [, amount];  (TURN amounts in degrees)
struct ActionStmt {
  ActionVerb verb = ActionVerb::kMove;
  Name body;
  ActionMode mode = ActionMode::kGeneral;
  std::optional<FeatureRef> feature;
  std::optional<double> amount;  ///< mm for MOVE, degrees for TURN (converted in sema)
  SourceLoc amount_loc;
};
/// AGENT/<body>;
struct AgentStmt {
  Name body;
};
/// TIED/<b1>, <b2>;  UNTIED/<b1>, <b2>;
struct TieStmt {
  bool tied = true;
  Name a;
  Name b;
};
/// <name> = SUBASS/<PERM|TEMP>;
struct SubassBegin {
  Name name;
  bool permanent = true;
};
/// TERSUB;
struct SubassEnd {};
/// ISSUB/<name>;  NOSUB/<name>; (also NOTSUB)
struct SubassSwitch {
  bool on = true;
  Name name;
};
/// <name> = CAMERA/<physical|POSITION>, <point>, THETA, a, PHI, b, PSI, c, [FOCUS,] F;
/// <name> = CAMERA/<physical>, <body>, [FOCUS,] F;
struct CameraDef {
  Name name;
  bool general = false;          ///< true: the second form (a camera body)
  std::optional<Name> physical;  ///< the physical camera's name, absent for POSITION
  Name place;                    ///< the centre point (immovable) or the body (general)
  double theta_deg = 0.0;        ///< immovable only
  double phi_deg = 0.0;          ///< immovable only
  double psi_deg = 0.0;          ///< immovable only
  double focus = 0.0;            ///< focal length, in image units (mm)
  SourceLoc focus_loc;
};
/// SETCAMERA/<camera>;
struct SetCamera {
  Name camera;
};
/// TOLERANCE/<body>, TRAN, d;  (global)   TOLERANCE/TRAN, d;  (local, inside COMBINE)
struct Tolerance {
  std::optional<Name> body;
  double value = 0.0;  ///< mm
  SourceLoc value_loc;
};
/// COMBINE;
struct Combine {};
/// TERCOM;
struct TerCom {};
/// INVIOLATE/<relation>, <feature>, <feature>;
struct Inviolate {
  RelKeyword kind = RelKeyword::kAgainst;
  SourceLoc kind_loc;
  FeatureRef a;
  FeatureRef b;
};
/// LOOK/<edge of body> [, <camera>];
struct Look {
  FeatureRef edge;
  std::optional<Name> camera;
};
/// TERAPT;
struct TerApt {};

/// Any statement.
using StatementBody = std::variant<BodyBegin,
                                   BodyEnd,
                                   PointDef,
                                   LineDef,
                                   CircleDef,
                                   FaceDef,
                                   CylinderDef,
                                   SphereDef,
                                   RelationStmt,
                                   ActionStmt,
                                   AgentStmt,
                                   TieStmt,
                                   SubassBegin,
                                   SubassEnd,
                                   SubassSwitch,
                                   CameraDef,
                                   SetCamera,
                                   Tolerance,
                                   Combine,
                                   TerCom,
                                   Inviolate,
                                   Look,
                                   TerApt>;

/// One statement and the position of its first token.
struct Statement {
  SourceLoc loc;
  StatementBody body;
};

/// A parsed file: its statements in order (statements with syntax errors are left out).
struct Program {
  std::vector<Statement> statements;
};

}  // namespace ast
}  // namespace cell::rapt
